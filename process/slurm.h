// The plan on a Slurm cluster: one job array per step (task i = the step's i-th job, in take
// order), chained with dependencies — afterok on a session-wide step, aftercorr between per-take
// steps (task i waits only for task i of the earlier array, so one failed take stops only its own
// chain) — and --kill-on-invalid-dep so a job whose dependency failed is cancelled, not left
// pending for ever. Every task runs `facedyn process --run-step STEP --index I`, which does what a
// local worker does (process/job_runner.h) and writes the same state files. Logs go to
// OUT/process/logs/. Nothing is copied: the session, OUT and the facedyn binary must be at the
// same paths on every node (a shared file system).
#pragma once

#include <string>
#include <vector>

#include "core/json_io.h"
#include "core/status.h"
#include "process/job_graph.h"
#include "process/job_runner.h"
#include "process/process_config.h"

namespace facedyn::process {

struct SlurmStepSubmission {
  std::string step;
  std::string job_id;  // the array's job id
  int tasks = 0;
  std::string dependency;  // as passed to sbatch ("" for none)
};

struct SlurmSubmission {
  std::string submitted_utc;
  std::vector<SlurmStepSubmission> steps;
  Json ToJson() const;
};

// Writes OUT/process/slurm/<step>.sbatch and submits them in step order with `sbatch --parsable`
// (found on PATH). OUT/process/slurm.json records the job ids for --status. On a failed sbatch,
// the arrays already submitted are cancelled (scancel) and the error names the step and sbatch's
// message.
StatusOr<SlurmSubmission> SubmitToSlurm(const JobGraph& graph, const ProcessConfig::Slurm& options,
                                        const RunContext& context);

StatusOr<SlurmSubmission> ReadSlurmSubmission(const std::string& out_dir);

// The state Slurm gives each task of the submission that is still queued or running, keyed by
// job id ("reconstruct/a" -> "PENDING (Dependency)"), from `squeue`. Tasks Slurm no longer lists
// are absent. An error when squeue cannot be run.
StatusOr<std::map<std::string, std::string>> QuerySlurm(const JobGraph& graph,
                                                        const SlurmSubmission& submission);

// Runs a program (PATH lookup) with arguments; stdout and stderr together in *output.
StatusOr<int> RunProgram(const std::vector<std::string>& argv, std::string* output);

}  // namespace facedyn::process
