#include "process/process_config.h"

#include <fnmatch.h>

#include <algorithm>
#include <filesystem>

#include "core/config_node.h"

namespace facedyn::process {
namespace {

const std::vector<std::string> kExportFormats = {"obj", "ply", "pc2", "mdd", "glb"};
const std::vector<std::string> kRemovalTargets = {"moving-average", "platform-synchronous",
                                                  "platform-synchronous-where-known"};

StatusOr<std::vector<std::string>> Patterns(const ConfigNode& node, const std::string& key,
                                            std::vector<std::string> fallback) {
  if (!node.Has(key)) return fallback;
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode child, node.Child(key));
  std::vector<std::string> patterns;
  if (child.IsScalar()) {
    FACEDYN_ASSIGN_OR_RETURN(std::string one, child.As<std::string>());
    patterns.push_back(std::move(one));
  } else {
    FACEDYN_ASSIGN_OR_RETURN(patterns, child.As<std::vector<std::string>>());
  }
  if (patterns.empty()) return node.Error(key, "expected at least one take name or pattern");
  for (const std::string& p : patterns) {
    if (p.empty()) return node.Error(key, "an empty pattern matches no take");
  }
  return patterns;
}

}  // namespace

bool MatchesAnyPattern(const std::string& name, const std::vector<std::string>& patterns) {
  return std::any_of(patterns.begin(), patterns.end(), [&](const std::string& p) {
    return fnmatch(p.c_str(), name.c_str(), 0) == 0;
  });
}

StatusOr<ProcessConfig> LoadProcessConfig(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode root, ConfigNode::ReadFile(path));
  ProcessConfig config;
  config.source_path = path;
  if (root.IsNull()) return config;  // an empty file: every default
  if (!root.IsMap()) return root.Error("expected a map of processing settings");
  FACEDYN_RETURN_IF_ERROR(root.CheckFields({"face", "takes", "reconstruct", "removal", "synthesis",
                                            "solve", "export", "seed", "threads", "slurm"}));
  const std::filesystem::path base = std::filesystem::path(path).parent_path();
  auto resolve = [&](const std::string& p) {
    if (p.empty() || p[0] == '/') return p;
    return (base / p).lexically_normal().string();
  };
  FACEDYN_ASSIGN_OR_RETURN(config.face, root.GetOr<std::string>("face", config.face));
  if (config.face.empty()) return root.Error("face", "expected a FaceRig folder or 'procedural'");
  if (config.face != "procedural") config.face = resolve(config.face);
  FACEDYN_ASSIGN_OR_RETURN(config.takes, Patterns(root, "takes", config.takes));
  FACEDYN_ASSIGN_OR_RETURN(const int64_t seed, root.GetOr<int64_t>("seed", config.seed));
  if (seed < 0 || seed > 0xffffffffLL) return root.Error("seed", "expected 0..4294967295");
  config.seed = static_cast<unsigned>(seed);
  FACEDYN_ASSIGN_OR_RETURN(config.threads, root.GetOr<int>("threads", config.threads));
  if (config.threads < 1 || config.threads > 256) {
    return root.Error("threads", "expected 1..256 LibTorch threads per step");
  }

  if (root.Has("reconstruct")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode node, root.Child("reconstruct"));
    FACEDYN_RETURN_IF_ERROR(
        node.CheckFields({"marker_diameter_px", "bright_markers", "calibration"}));
    auto& r = config.reconstruct;
    if (node.Has("marker_diameter_px")) {
      FACEDYN_ASSIGN_OR_RETURN(r.marker_diameter_px, node.GetInRange("marker_diameter_px", 2, 200));
    }
    FACEDYN_ASSIGN_OR_RETURN(r.bright_markers, node.GetOr<bool>("bright_markers", false));
    FACEDYN_ASSIGN_OR_RETURN(r.calibration, node.GetOr<std::string>("calibration", ""));
    r.calibration = resolve(r.calibration);
  }
  if (root.Has("removal")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode node, root.Child("removal"));
    FACEDYN_RETURN_IF_ERROR(node.CheckFields({"enabled", "train_takes", "targets", "epochs"}));
    auto& r = config.removal;
    FACEDYN_ASSIGN_OR_RETURN(r.enabled, node.GetOr<bool>("enabled", r.enabled));
    FACEDYN_ASSIGN_OR_RETURN(r.train_takes, Patterns(node, "train_takes", r.train_takes));
    FACEDYN_ASSIGN_OR_RETURN(r.targets, node.GetOr<std::string>("targets", r.targets));
    if (std::find(kRemovalTargets.begin(), kRemovalTargets.end(), r.targets) ==
        kRemovalTargets.end()) {
      return node.Error("targets",
                        "expected moving-average, platform-synchronous or "
                        "platform-synchronous-where-known (a capture has no exact quasistatic)");
    }
    FACEDYN_ASSIGN_OR_RETURN(r.epochs, node.GetOr<int>("epochs", r.epochs));
    if (r.epochs < 1 || r.epochs > 100000) return node.Error("epochs", "expected 1..100000");
  }
  if (root.Has("synthesis")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode node, root.Child("synthesis"));
    FACEDYN_RETURN_IF_ERROR(node.CheckFields({"enabled", "epochs"}));
    auto& s = config.synthesis;
    FACEDYN_ASSIGN_OR_RETURN(s.enabled, node.GetOr<bool>("enabled", s.enabled));
    FACEDYN_ASSIGN_OR_RETURN(s.epochs, node.GetOr<int>("epochs", s.epochs));
    if (s.epochs < 1 || s.epochs > 100000) return node.Error("epochs", "expected 1..100000");
  }
  if (root.Has("solve")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode node, root.Child("solve"));
    FACEDYN_RETURN_IF_ERROR(node.CheckFields({"enabled", "model", "epochs"}));
    auto& s = config.solve;
    FACEDYN_ASSIGN_OR_RETURN(s.enabled, node.GetOr<bool>("enabled", s.enabled));
    FACEDYN_ASSIGN_OR_RETURN(s.model, node.GetOr<std::string>("model", ""));
    s.model = resolve(s.model);
    FACEDYN_ASSIGN_OR_RETURN(s.epochs, node.GetOr<int>("epochs", s.epochs));
    if (s.epochs < 0 || s.epochs > 100000) return node.Error("epochs", "expected 0..100000");
  }
  if (root.Has("export")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode node, root.Child("export"));
    FACEDYN_RETURN_IF_ERROR(node.CheckFields({"formats"}));
    FACEDYN_ASSIGN_OR_RETURN(config.exports.formats,
                             node.GetOr<std::vector<std::string>>("formats", {}));
    for (const std::string& f : config.exports.formats) {
      if (std::find(kExportFormats.begin(), kExportFormats.end(), f) == kExportFormats.end()) {
        return node.Error("formats",
                          "unknown format '" + f + "' (expected obj, ply, pc2, mdd, glb)");
      }
    }
  }
  if (root.Has("slurm")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode node, root.Child("slurm"));
    FACEDYN_RETURN_IF_ERROR(node.CheckFields({"partition", "account", "cpus_per_task", "time"}));
    auto& s = config.slurm;
    FACEDYN_ASSIGN_OR_RETURN(s.partition, node.GetOr<std::string>("partition", ""));
    FACEDYN_ASSIGN_OR_RETURN(s.account, node.GetOr<std::string>("account", ""));
    FACEDYN_ASSIGN_OR_RETURN(s.cpus_per_task, node.GetOr<int>("cpus_per_task", 1));
    if (s.cpus_per_task < 1 || s.cpus_per_task > 1024) {
      return node.Error("cpus_per_task", "expected 1..1024");
    }
    FACEDYN_ASSIGN_OR_RETURN(s.time_limit, node.GetOr<std::string>("time", ""));
  }
  if (config.synthesis.enabled && !config.removal.enabled) {
    return root.Error("synthesis", "synthesis is trained on the removal's output: enable removal");
  }
  if (config.solve.enabled && !config.removal.enabled) {
    return root.Error("solve", "the solve runs on the removal's quasistatic take: enable removal");
  }
  return config;
}

}  // namespace facedyn::process
