// Runs a plan on this machine with N workers: each ready job (its dependencies done or up to
// date) is checked, and when out of date run by a child `facedyn process --run-job` (so a local
// run and a Slurm task run a job the same way). A failed job blocks the jobs that need it and
// nothing else: the other takes go on.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/json_io.h"
#include "process/job_graph.h"
#include "process/job_runner.h"

namespace facedyn::process {

struct JobReport {
  std::string id;
  std::string outcome;  // "up to date", "done", "failed", "blocked"
  std::string reason;   // failed: why; blocked: by which job
  double elapsed_s = 0.0;
};

struct RunSummary {
  std::vector<JobReport> jobs;  // plan order
  int up_to_date = 0, done = 0, failed = 0, blocked = 0;
  double wall_s = 0.0;
  bool ok() const { return failed == 0 && blocked == 0; }
  Json ToJson() const;
  std::string ToText() const;
};

struct LocalOptions {
  int jobs = 1;        // workers at once
  bool force = false;  // run every job even when up to date
  // Called as each job finishes (for progress lines); may be empty.
  std::function<void(const JobReport&, int finished, int total)> on_job;
};

// `worker_args`: the arguments after the executable that make it run one job and exit 0 when
// it is done or up to date (e.g. {"--quiet", "process", "--out", OUT, "--run-job"}; the job id
// is appended).
StatusOr<RunSummary> RunLocal(const JobGraph& graph, const RunContext& context,
                              const std::vector<std::string>& worker_args,
                              const LocalOptions& options);

}  // namespace facedyn::process
