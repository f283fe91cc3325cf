// Running one job of a plan: skip it when up to date, else run its commands with their output
// in the job's log, and record the outcome in the job's state file.
//
// A job is up to date when its state says "done" with the hash of its current inputs, command
// lines and facedyn version, and its outputs exist. Before a run its old outputs are removed and
// its state says "running" (host, pid), so a run killed mid-way is never mistaken for done: the
// next run of the graph redoes it. States are written atomically (temporary file + rename).
#pragma once

#include <string>

#include "core/json_io.h"
#include "core/status.h"
#include "process/job_graph.h"

namespace facedyn::process {

struct RunContext {
  std::string executable;    // the facedyn binary the commands run with
  std::string tool_version;  // hashed: a new facedyn build re-runs every step
};

enum class JobOutcome { kUpToDate, kDone, kFailed };

struct JobResult {
  JobOutcome outcome = JobOutcome::kFailed;
  std::string reason;  // why it failed (names the command, exit code and the log's last line)
  double elapsed_s = 0.0;
};

// The state file as read ("" status when there is none or it cannot be read).
struct JobState {
  std::string status;  // "running", "done", "failed", or ""
  std::string input_hash;
  std::string reason;
  std::string host;
  int64_t pid = 0;
  std::string started_utc, finished_utc;
  double elapsed_s = 0.0;
  std::string slurm_job;  // "<array job id>_<task>" when run by Slurm
  Json files;             // the input file digests (content_hash.h FileHashCache)
};
JobState ReadJobState(const std::string& out_dir, const std::string& job_id);

// Whether `job` is up to date; `*why` (may be null) says why not ("never run", "inputs changed",
// "an output is missing", "failed last time", ...). Hash errors count as not up to date.
bool JobUpToDate(const JobGraph& graph, const Job& job, const RunContext& context,
                 std::string* why);

// Runs `job` unless up to date (or `force`). Its dependencies must be done: a job whose
// dependency is not is refused (failed, naming it) without running anything.
JobResult RunJob(const JobGraph& graph, const Job& job, const RunContext& context, bool force);

}  // namespace facedyn::process
