// `facedyn process --status DIR`: what of a plan is done, running, failed (and why), waiting.
#pragma once

#include <string>
#include <vector>

#include "core/json_io.h"
#include "core/status.h"
#include "process/job_graph.h"
#include "process/job_runner.h"

namespace facedyn::process {

struct JobStatus {
  std::string id;
  // "done", "stale" (done, but its inputs changed since), "running", "queued" (Slurm),
  // "failed", "interrupted" (a run that stopped without finishing), "not started"
  std::string state;
  std::string detail;  // failed: why; running: where; queued: Slurm's state and reason
  std::string log;     // the job's log file when it has one
};

struct ProcessStatus {
  std::string out_dir;
  std::vector<JobStatus> jobs;
  std::vector<SkippedTake> skipped;
  bool slurm = false;
  std::string slurm_problem;  // squeue could not be asked
  int Count(const std::string& state) const;
  bool AllDone() const { return Count("done") == static_cast<int>(jobs.size()); }
  Json ToJson() const;
  std::string ToText() const;
};

// Reads OUT/process/ (plan, states, Slurm submission) and asks squeue about queued tasks.
StatusOr<ProcessStatus> ReadProcessStatus(const std::string& out_dir, const RunContext& context);

}  // namespace facedyn::process
