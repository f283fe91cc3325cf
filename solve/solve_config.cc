#include "solve/solve_config.h"

#include <fmt/format.h>

#include <algorithm>
#include <limits>
#include <map>
#include <set>

namespace facedyn::solve {
namespace {

StatusOr<RegionSpec> ParseRegion(const ConfigNode& node, const std::string& name) {
  RegionSpec region;
  region.name = name;
  FACEDYN_ASSIGN_OR_RETURN(region.rig_regions, node.Get<std::vector<std::string>>("rig_regions"));
  FACEDYN_ASSIGN_OR_RETURN(region.channels, node.Get<std::vector<std::string>>("channels"));
  if (region.rig_regions.empty()) return node.Error("rig_regions", "is empty");
  if (region.channels.empty()) return node.Error("channels", "is empty");
  FACEDYN_ASSIGN_OR_RETURN(const std::string features,
                           node.GetOr<std::string>("features", "distance+direction+delta"));
  StatusOr<FeatureSet> set = FeatureSet::Parse(features);
  if (!set.ok()) return node.Error("features", set.status().message());
  region.features = set.value();
  FACEDYN_ASSIGN_OR_RETURN(region.jaw_conditioned, node.GetOr<bool>("jaw_conditioned", false));
  return region;
}

// Farthest-point subset of `candidates` (deterministic: starts from the first).
std::vector<int> FarthestSubset(const Eigen::Matrix3Xd& points, const std::vector<int>& candidates,
                                int count) {
  if (static_cast<int>(candidates.size()) <= count) return candidates;
  std::vector<int> chosen{candidates.front()};
  std::vector<double> nearest(candidates.size(), std::numeric_limits<double>::infinity());
  while (static_cast<int>(chosen.size()) < count) {
    size_t best = 0;
    double best_distance = -1.0;
    for (size_t i = 0; i < candidates.size(); ++i) {
      nearest[i] =
          std::min(nearest[i], (points.col(candidates[i]) - points.col(chosen.back())).norm());
      if (nearest[i] > best_distance) {
        best_distance = nearest[i];
        best = i;
      }
    }
    chosen.push_back(candidates[best]);
  }
  std::sort(chosen.begin(), chosen.end());
  return chosen;
}

}  // namespace

StatusOr<SolveConfig> ParseSolveConfig(const ConfigNode& root) {
  SolveConfig config;
  FACEDYN_ASSIGN_OR_RETURN(config.rig, root.GetOr<std::string>("rig", ""));
  FACEDYN_ASSIGN_OR_RETURN(config.always_include,
                           root.GetOr<std::vector<std::string>>("always_include", {}));
  if (root.Has("max_markers_per_region")) {
    FACEDYN_ASSIGN_OR_RETURN(const double max_markers,
                             root.GetInRange("max_markers_per_region", 2, 200));
    config.max_markers_per_region = static_cast<int>(max_markers);
  }
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode jaw, root.Child("jaw"));
  FACEDYN_ASSIGN_OR_RETURN(config.jaw, ParseRegion(jaw, "jaw"));
  if (config.jaw.jaw_conditioned)
    return jaw.Error("jaw_conditioned", "the jaw cannot be conditioned on itself");
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode regions, root.Child("regions"));
  if (!regions.IsSequence() || regions.size() == 0)
    return regions.Error("expected a non-empty list");
  for (size_t i = 0; i < regions.size(); ++i) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode node, regions.At(i));
    FACEDYN_ASSIGN_OR_RETURN(const std::string name, node.Get<std::string>("name"));
    FACEDYN_ASSIGN_OR_RETURN(RegionSpec region, ParseRegion(node, name));
    config.regions.push_back(std::move(region));
  }
  if (root.Has("network")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode net, root.Child("network"));
    NetworkSpec& n = config.network;
    FACEDYN_ASSIGN_OR_RETURN(const double hidden, net.GetInRange("hidden_units", 1, 4096));
    FACEDYN_ASSIGN_OR_RETURN(const double blocks, net.GetInRange("residual_blocks", 0, 16));
    FACEDYN_ASSIGN_OR_RETURN(n.dropout, net.GetInRange("dropout", 0.0, 0.9));
    FACEDYN_ASSIGN_OR_RETURN(const double epochs, net.GetInRange("epochs", 1, 100000));
    FACEDYN_ASSIGN_OR_RETURN(const double batch, net.GetInRange("batch_size", 1, 1000000));
    FACEDYN_ASSIGN_OR_RETURN(n.learning_rate, net.GetInRange("learning_rate", 1e-8, 1.0));
    FACEDYN_ASSIGN_OR_RETURN(n.weight_decay, net.GetInRange("weight_decay", 0.0, 1.0));
    n.hidden_units = static_cast<int>(hidden);
    n.residual_blocks = static_cast<int>(blocks);
    n.epochs = static_cast<int>(epochs);
    n.batch_size = static_cast<int>(batch);
  }
  return config;
}

StatusOr<SolveConfig> ReadSolveConfig(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode root, ConfigNode::ReadFile(path));
  return ParseSolveConfig(root);
}

const char* ProceduralSolveConfigYaml() {
  return R"(# FDLS region tables for the procedural face (sim/procedural_face.h): its ten expression
# channels split over the jaw and three regions, after the paper's supplementary section 9
# (upper face, cheek, lower face / lips), with the jaw solved first.
rig: procedural
always_include: [nose_bridge]
max_markers_per_region: 16
jaw:
  rig_regions: [jaw, chin]
  channels: [jaw_open]
  features: direction+delta
regions:
  - name: upper_face
    rig_regions: [forehead, brows, eyes]
    channels: [brow_raise, squeeze]
    features: distance+direction+delta
  - name: cheek
    rig_regions: [cheeks, nose]
    channels: [cheek_puff, sneer]
    features: distance+delta
    jaw_conditioned: true
  - name: mouth
    rig_regions: [lips, mouth_corners, chin]
    channels: [smile, pucker, lip_funnel, mouth_stretch, lips_parted]
    features: distance+direction+delta
    jaw_conditioned: true
network:
  hidden_units: 128
  residual_blocks: 2
  dropout: 0.01
  epochs: 60
  batch_size: 64
  learning_rate: 1.0e-3
  weight_decay: 1.0e-5
)";
}

StatusOr<SolveConfig> ProceduralSolveConfig() {
  FACEDYN_ASSIGN_OR_RETURN(
      const ConfigNode root,
      ConfigNode::Parse(ProceduralSolveConfigYaml(), "<embedded procedural solve config>"));
  return ParseSolveConfig(root);
}

StatusOr<ResolvedConfig> ResolveSolveConfig(const SolveConfig& config, const FaceRig& rig,
                                            const Puppet& puppet) {
  const std::string where = "solve config for rig '" + rig.name + "'";
  // Marker membership by rig region.
  std::map<std::string, std::vector<int>> region_markers;
  for (const auto& [name, vertices] : rig.regions) {
    const std::set<int> in_region(vertices.begin(), vertices.end());
    for (int m = 0; m < puppet.marker_count(); ++m) {
      if (in_region.count(puppet.marker_vertices[m])) region_markers[name].push_back(m);
    }
  }
  std::vector<int> always;
  for (const std::string& name : config.always_include) {
    if (!rig.regions.count(name)) {
      return InvalidArgumentError(fmt::format(
          "{}: always_include names the region '{}', which the rig does not have", where, name));
    }
    const std::vector<int>& markers = region_markers[name];
    if (markers.empty()) continue;
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int m : markers) centroid += puppet.neutral_markers_in_skull.col(m);
    centroid /= static_cast<double>(markers.size());
    int best = markers.front();
    for (int m : markers) {
      if ((puppet.neutral_markers_in_skull.col(m) - centroid).norm() <
          (puppet.neutral_markers_in_skull.col(best) - centroid).norm()) {
        best = m;
      }
    }
    always.push_back(best);
  }

  std::vector<std::string> owner(puppet.channel_count());
  auto resolve = [&](const RegionSpec& spec) -> StatusOr<ResolvedRegion> {
    ResolvedRegion resolved;
    resolved.spec = spec;
    std::set<int> markers;
    for (const std::string& name : spec.rig_regions) {
      if (!rig.regions.count(name)) {
        return InvalidArgumentError(
            fmt::format("{}: region '{}' uses the rig region '{}', which the rig does not have",
                        where, spec.name, name));
      }
      for (int m : region_markers[name]) markers.insert(m);
    }
    std::vector<int> subset = FarthestSubset(puppet.neutral_markers_in_skull,
                                             std::vector<int>(markers.begin(), markers.end()),
                                             config.max_markers_per_region);
    for (int m : always) {
      if (!std::count(subset.begin(), subset.end(), m)) subset.push_back(m);
    }
    std::sort(subset.begin(), subset.end());
    if (subset.size() < 2) {
      return InvalidArgumentError(fmt::format("{}: region '{}' has {} markers, at least 2 needed",
                                              where, spec.name, subset.size()));
    }
    resolved.markers = subset;
    for (const std::string& channel : spec.channels) {
      const int c = puppet.ChannelIndex(channel);
      if (c < 0) {
        return InvalidArgumentError(
            fmt::format("{}: region '{}' names the channel '{}', which the rig does not have",
                        where, spec.name, channel));
      }
      if (!owner[c].empty()) {
        return InvalidArgumentError(
            fmt::format("{}: channel '{}' is in region '{}' and in region '{}'", where, channel,
                        owner[c], spec.name));
      }
      owner[c] = spec.name;
      resolved.channels.push_back(c);
    }
    return resolved;
  };
  ResolvedConfig resolved;
  FACEDYN_ASSIGN_OR_RETURN(resolved.jaw, resolve(config.jaw));
  for (const RegionSpec& spec : config.regions) {
    FACEDYN_ASSIGN_OR_RETURN(ResolvedRegion region, resolve(spec));
    resolved.regions.push_back(std::move(region));
  }
  for (int c = 0; c < puppet.channel_count(); ++c) {
    if (owner[c].empty()) {
      return InvalidArgumentError(fmt::format("{}: the rig's channel '{}' is in no region", where,
                                              puppet.channel_names[c]));
    }
  }
  resolved.network = config.network;
  return resolved;
}

}  // namespace facedyn::solve
