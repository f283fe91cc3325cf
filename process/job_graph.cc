#include "process/job_graph.h"

#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <set>

#include "capture/session.h"
#include "core/config_node.h"
#include "core/file_util.h"

namespace facedyn::process {
namespace fs = std::filesystem;

namespace {

std::string Absolute(const std::string& path) {
  std::error_code ec;
  const fs::path abs = fs::absolute(path, ec);
  return (ec ? fs::path(path) : abs).lexically_normal().string();
}

// What reconstruct reads of a take: everything the capture wrote except the simulator's
// ground truth (scoring only; it must not decide whether a method re-runs).
std::vector<std::string> TakeInputs(const std::string& take_dir) {
  std::vector<std::string> inputs;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(take_dir, ec)) {
    if (entry.path().filename() == "ground_truth") continue;
    inputs.push_back(entry.path().string());
  }
  std::sort(inputs.begin(), inputs.end());
  return inputs;
}

}  // namespace

std::vector<const Job*> JobGraph::JobsOfStep(const std::string& step) const {
  std::vector<const Job*> out;
  for (const Job& job : jobs) {
    if (job.step == step) out.push_back(&job);
  }
  return out;
}

const Job* JobGraph::Find(const std::string& id) const {
  for (const Job& job : jobs) {
    if (job.id == id) return &job;
  }
  return nullptr;
}

std::string JobFileStem(const std::string& id) {
  std::string stem;
  for (char c : id) stem += (c == '/') ? std::string("--") : std::string(1, c);
  return stem;
}
std::string PlanPath(const std::string& out_dir) { return JoinPath(out_dir, "process/plan.json"); }
std::string StatePath(const std::string& out_dir, const std::string& job_id) {
  return JoinPath(out_dir, "process/state/" + JobFileStem(job_id) + ".json");
}
std::string LogPath(const std::string& out_dir, const std::string& job_id) {
  return JoinPath(out_dir, "process/logs/" + JobFileStem(job_id) + ".log");
}

StatusOr<JobGraph> BuildJobGraph(const std::string& session_dir, const ProcessConfig& config,
                                 const std::string& out_dir) {
  FACEDYN_ASSIGN_OR_RETURN(const capture::SessionInfo session, capture::ReadSession(session_dir));
  JobGraph graph;
  graph.session_dir = Absolute(session_dir);
  graph.out_dir = Absolute(out_dir);
  graph.config_path = config.source_path;

  // Takes redone by a complete take (a sweep step recorded again) are not processed twice.
  std::map<std::string, std::string> superseded_by;
  for (const capture::SessionTake& take : session.takes) {
    if (take.status != "complete" || !take.manifest.is_object()) continue;
    const auto it = take.manifest.find("supersedes");
    if (it == take.manifest.end() || !it->is_array()) continue;
    for (const auto& name : *it) {
      if (name.is_string()) superseded_by[name.get<std::string>()] = take.name;
    }
  }
  for (const capture::SessionTake& take : session.takes) {
    if (!MatchesAnyPattern(take.name, config.takes)) continue;
    if (take.status != "complete") {
      graph.skipped.push_back(
          {take.name, "capture is '" + take.status + "'" +
                          (take.reason.empty() ? std::string() : (": " + take.reason))});
    } else if (superseded_by.count(take.name) > 0) {
      graph.skipped.push_back({take.name, "superseded by " + superseded_by[take.name]});
    } else {
      graph.takes.push_back(take.name);
    }
  }
  if (graph.takes.empty()) {
    std::string patterns;
    for (const auto& p : config.takes) patterns += (patterns.empty() ? "" : ", ") + p;
    return FailedPreconditionError(
        "session " + graph.session_dir + " has no complete take matching " + patterns +
        (graph.skipped.empty()
             ? ""
             : " (" + std::to_string(graph.skipped.size()) + " matched but incomplete)"));
  }

  const std::string face = config.face;
  const std::vector<std::string> face_inputs =
      face == "procedural" ? std::vector<std::string>{} : std::vector<std::string>{face};
  const std::string threads = std::to_string(config.threads);
  const std::string seed = std::to_string(config.seed);
  const std::string models = JoinPath(graph.out_dir, "models");
  auto take_out = [&](const std::string& take, const std::string& name) {
    return JoinPath(graph.out_dir, "takes/" + take + "/" + name);
  };
  auto append = [](std::vector<std::string> a, const std::vector<std::string>& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
  };

  // reconstruct, per take
  for (const std::string& take : graph.takes) {
    const std::string take_dir = JoinPath(graph.session_dir, "takes/" + take);
    Job job;
    job.id = "reconstruct/" + take;
    job.step = "reconstruct";
    job.take = take;
    std::vector<std::string> args = {"--quiet",
                                     "reconstruct",
                                     "--session",
                                     graph.session_dir,
                                     "--take",
                                     take,
                                     "--out",
                                     take_out(take, "reconstructed"),
                                     "--face",
                                     face,
                                     "--marker-diameter-px",
                                     fmt::format("{}", config.reconstruct.marker_diameter_px)};
    if (config.reconstruct.bright_markers) args.push_back("--bright-markers");
    std::string calibration = config.reconstruct.calibration;
    if (calibration.empty()) calibration = session.calibration_path;
    if (!config.reconstruct.calibration.empty()) {
      args.push_back("--calibration");
      args.push_back(calibration);
    }
    job.commands.push_back(args);
    job.inputs = append(TakeInputs(take_dir), face_inputs);
    if (!calibration.empty()) job.inputs.push_back(calibration);
    job.outputs = {take_out(take, "reconstructed")};
    graph.jobs.push_back(std::move(job));
  }

  // Session-wide training
  std::vector<std::string> train_takes;
  for (const std::string& take : graph.takes) {
    if (MatchesAnyPattern(take, config.removal.train_takes)) train_takes.push_back(take);
  }
  const std::string f_model = JoinPath(models, "F.pt");
  if (config.removal.enabled) {
    if (train_takes.empty()) {
      return FailedPreconditionError(config.source_path +
                                     ": removal.train_takes matches none of the processed takes");
    }
    Job job;
    job.id = job.step = "train-removal";
    std::vector<std::string> args = {"--quiet", "dynamics", "train-removal", "--takes"};
    for (const std::string& take : train_takes) {
      args.push_back(take_out(take, "reconstructed"));
      job.inputs.push_back(take_out(take, "reconstructed"));
      job.deps.push_back("reconstruct/" + take);
    }
    args = append(
        args, {"--face", face, "--out", f_model, "--targets", config.removal.targets, "--epochs",
               std::to_string(config.removal.epochs), "--seed", seed, "--threads", threads});
    job.commands.push_back(args);
    job.inputs = append(job.inputs, face_inputs);
    job.outputs = {f_model};
    graph.jobs.push_back(std::move(job));
  }
  if (config.synthesis.enabled) {
    Job job;
    job.id = job.step = "train-synthesis";
    const std::string h_model = JoinPath(models, "H.pt");
    std::vector<std::string> args = {"--quiet", "dynamics", "train-synthesis", "--takes"};
    for (const std::string& take : train_takes) {
      args.push_back(take_out(take, "reconstructed"));
      job.inputs.push_back(take_out(take, "reconstructed"));
      job.deps.push_back("reconstruct/" + take);
    }
    args = append(args,
                  {"--removal-model", f_model, "--face", face, "--out", h_model, "--epochs",
                   std::to_string(config.synthesis.epochs), "--seed", seed, "--threads", threads});
    job.commands.push_back(args);
    job.inputs.push_back(f_model);
    job.inputs = append(job.inputs, face_inputs);
    job.deps.push_back("train-removal");
    job.outputs = {h_model};
    graph.jobs.push_back(std::move(job));
  }
  std::string solver = config.solve.model;
  if (config.solve.enabled && solver.empty()) {
    solver = JoinPath(models, "solver");
    Job job;
    job.id = job.step = "train-solver";
    std::vector<std::string> args = {"--quiet", "solve",  "train", "--rig",     face,   "--out",
                                     solver,    "--seed", seed,    "--threads", threads};
    if (config.solve.epochs > 0)
      args = append(args, {"--epochs", std::to_string(config.solve.epochs)});
    job.commands.push_back(args);
    job.inputs = face_inputs;
    job.outputs = {solver};
    graph.jobs.push_back(std::move(job));
  }

  // Per take after training
  if (config.removal.enabled) {
    for (const std::string& take : graph.takes) {
      Job job;
      job.id = "remove/" + take;
      job.step = "remove";
      job.take = take;
      job.commands.push_back({"--quiet", "dynamics", "remove", "--take",
                              take_out(take, "reconstructed"), "--model", f_model, "--face", face,
                              "--out", take_out(take, "quasistatic")});
      job.inputs = append({take_out(take, "reconstructed"), f_model}, face_inputs);
      job.outputs = {take_out(take, "quasistatic")};
      job.deps = {"reconstruct/" + take, "train-removal"};
      graph.jobs.push_back(std::move(job));
    }
  }
  // What solve and export read: the quasistatic take when removal runs, else the reconstruction.
  const std::string final_take = config.removal.enabled ? "quasistatic" : "reconstructed";
  const std::string final_step = config.removal.enabled ? "remove/" : "reconstruct/";
  if (config.solve.enabled) {
    for (const std::string& take : graph.takes) {
      Job job;
      job.id = "solve/" + take;
      job.step = "solve";
      job.take = take;
      job.commands.push_back({"--quiet", "solve", "run", "--take", take_out(take, final_take),
                              "--rig", face, "--model", solver, "--out",
                              take_out(take, "weights.csv")});
      job.inputs = append({take_out(take, final_take), solver}, face_inputs);
      job.outputs = {take_out(take, "weights.csv")};
      job.deps = {final_step + take};
      if (config.solve.model.empty()) job.deps.push_back("train-solver");
      graph.jobs.push_back(std::move(job));
    }
  }
  if (!config.exports.formats.empty()) {
    for (const std::string& take : graph.takes) {
      Job job;
      job.id = "export/" + take;
      job.step = "export";
      job.take = take;
      for (const std::string& format : config.exports.formats) {
        const std::string out = take_out(take, "export-" + format);
        job.commands.push_back({"--quiet", "export", "--take", take_out(take, final_take),
                                "--format", format, "--out", out});
        job.outputs.push_back(out);
      }
      job.inputs = {take_out(take, final_take)};
      job.deps = {final_step + take};
      graph.jobs.push_back(std::move(job));
    }
  }
  return graph;
}

Json JobGraphToJson(const JobGraph& graph) {
  Json jobs = Json::array();
  for (const Job& job : graph.jobs) {
    jobs.push_back({{"id", job.id},
                    {"step", job.step},
                    {"take", job.take},
                    {"commands", job.commands},
                    {"inputs", job.inputs},
                    {"outputs", job.outputs},
                    {"deps", job.deps}});
  }
  Json skipped = Json::array();
  for (const SkippedTake& s : graph.skipped)
    skipped.push_back({{"take", s.take}, {"reason", s.reason}});
  return {{"format", "facedyn-process-plan"},
          {"version", 1},
          {"session", graph.session_dir},
          {"out", graph.out_dir},
          {"config", graph.config_path},
          {"takes", graph.takes},
          {"skipped", skipped},
          {"jobs", jobs}};
}

StatusOr<JobGraph> JobGraphFromJson(const Json& json, const std::string& source) {
  auto bad = [&](const std::string& what) {
    return DataLossError(source + ": not a facedyn process plan (" + what + ")");
  };
  try {
    if (!json.is_object() || json.value("format", "") != "facedyn-process-plan") {
      return bad("format is not facedyn-process-plan");
    }
    if (json.value("version", 0) != 1) return bad("unsupported version");
    JobGraph graph;
    graph.session_dir = json.at("session").get<std::string>();
    graph.out_dir = json.at("out").get<std::string>();
    graph.config_path = json.at("config").get<std::string>();
    graph.takes = json.at("takes").get<std::vector<std::string>>();
    for (const auto& s : json.at("skipped")) {
      graph.skipped.push_back({s.at("take").get<std::string>(), s.at("reason").get<std::string>()});
    }
    std::set<std::string> ids;
    for (const auto& j : json.at("jobs")) {
      Job job;
      job.id = j.at("id").get<std::string>();
      job.step = j.at("step").get<std::string>();
      job.take = j.at("take").get<std::string>();
      job.commands = j.at("commands").get<std::vector<std::vector<std::string>>>();
      job.inputs = j.at("inputs").get<std::vector<std::string>>();
      job.outputs = j.at("outputs").get<std::vector<std::string>>();
      job.deps = j.at("deps").get<std::vector<std::string>>();
      if (job.id.empty() || job.commands.empty()) return bad("a job without id or command");
      for (const std::string& dep : job.deps) {
        if (ids.count(dep) == 0)
          return bad("job " + job.id + " depends on unknown or later " + dep);
      }
      if (!ids.insert(job.id).second) return bad("job " + job.id + " twice");
      graph.jobs.push_back(std::move(job));
    }
    return graph;
  } catch (const Json::exception& e) {
    return bad(e.what());
  }
}

Status WritePlan(const JobGraph& graph) {
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(JoinPath(graph.out_dir, "process/state")));
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(JoinPath(graph.out_dir, "process/logs")));
  return WriteJsonFile(PlanPath(graph.out_dir), JobGraphToJson(graph));
}

StatusOr<JobGraph> ReadPlan(const std::string& out_dir) {
  const std::string path = PlanPath(out_dir);
  FACEDYN_ASSIGN_OR_RETURN(const std::string text, ReadFileToString(path));
  Json json;
  try {
    json = Json::parse(text);
  } catch (const Json::exception& e) {
    return DataLossError(path + ": " + e.what());
  }
  return JobGraphFromJson(json, path);
}

}  // namespace facedyn::process
