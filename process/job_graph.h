// A session's reprocessing as a graph of jobs, each one run of a facedyn command.
//
// Every job names its inputs (files or folders whose bytes its outputs depend on), its outputs
// (written only by this job), the jobs it waits for, and the facedyn arguments that do the work.
// The plan is written to OUT/process/plan.json when a run starts, so that workers — local child
// processes or Slurm array tasks on other machines — run exactly the planned jobs.
//
// Layout of the output folder (all paths in the plan are absolute; on a cluster OUT must be on a
// shared file system):
//   OUT/process/plan.json          the graph
//   OUT/process/state/<job>.json   each job's state: done (with its input hash) or failed (why)
//   OUT/process/logs/<job>.log     each job's command output
//   OUT/takes/<take>/reconstructed the reconstructed take
//   OUT/takes/<take>/quasistatic   its secondary dynamics removed (channel dynamic_offset)
//   OUT/takes/<take>/weights.csv   the rig controls solved from the quasistatic markers
//   OUT/takes/<take>/export-<fmt>  the quasistatic take exported
//   OUT/models/F.pt, H.pt, solver/ the session's trained removal, synthesis and solver
#pragma once

#include <string>
#include <vector>

#include "core/json_io.h"
#include "core/status.h"
#include "process/process_config.h"

namespace facedyn::process {

// The steps in the order Slurm arrays are submitted (each depends only on earlier ones).
inline const std::vector<std::string>& StepOrder() {
  static const std::vector<std::string> order = {"reconstruct",  "train-removal", "train-synthesis",
                                                 "train-solver", "remove",        "solve",
                                                 "export"};
  return order;
}

struct Job {
  std::string id;    // "reconstruct/smile_8hz", "train-removal", "export/smile_8hz/pc2", ...
  std::string step;  // one of StepOrder()
  std::string take;  // "" for session-wide jobs
  // facedyn argument lists (without the executable), run in order; most jobs have one, an
  // export job one per format.
  std::vector<std::vector<std::string>> commands;
  std::vector<std::string> inputs;   // files or folders (absolute)
  std::vector<std::string> outputs;  // files or folders (absolute), removed before a run
  std::vector<std::string> deps;     // ids of jobs that must be done first
};

struct SkippedTake {
  std::string take;
  std::string reason;
};

struct JobGraph {
  std::string session_dir;           // absolute
  std::string out_dir;               // absolute
  std::string config_path;           // as given
  std::vector<std::string> takes;    // processed, in session order
  std::vector<SkippedTake> skipped;  // takes matched by the config but not processable
  std::vector<Job> jobs;             // topological order
  // Jobs of `step`, in take order (the Slurm array index is the position in this list).
  std::vector<const Job*> JobsOfStep(const std::string& step) const;
  const Job* Find(const std::string& id) const;
};

// The graph for `session_dir` under `config`. A take is processed when its name matches
// config.takes and its capture says "complete"; other matched takes are listed in `skipped`
// with the reason. An error when no take is left, when removal training would have no take,
// or the session cannot be read.
StatusOr<JobGraph> BuildJobGraph(const std::string& session_dir, const ProcessConfig& config,
                                 const std::string& out_dir);

// File name for a job id inside state/ and logs/ ("reconstruct/a" -> "reconstruct--a").
std::string JobFileStem(const std::string& id);
std::string PlanPath(const std::string& out_dir);
std::string StatePath(const std::string& out_dir, const std::string& job_id);
std::string LogPath(const std::string& out_dir, const std::string& job_id);

Json JobGraphToJson(const JobGraph& graph);
StatusOr<JobGraph> JobGraphFromJson(const Json& json, const std::string& source);
Status WritePlan(const JobGraph& graph);
StatusOr<JobGraph> ReadPlan(const std::string& out_dir);

}  // namespace facedyn::process
