// `facedyn process`: a capture session's reprocessing as a job graph (process/), locally with N
// workers or as Slurm job arrays; `--status` reports a run. The graph, the up-to-date checks and
// the Slurm submission are process/'s; this file reads flags and prints.

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdio>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "app/command.h"
#include "core/json_io.h"
#include "facedyn_version.h"
#include "process/job_graph.h"
#include "process/job_runner.h"
#include "process/local_scheduler.h"
#include "process/process_config.h"
#include "process/slurm.h"
#include "process/status.h"

namespace facedyn::app {
namespace {

struct ProcessOptions {
  std::string session;
  std::string config;
  std::string out;
  std::string status_dir;
  int jobs = 0;
  bool force = false;
  bool dry_run = false;
  bool slurm = false;
  std::string partition;
  std::string account;
  bool json = false;
  // Worker modes (a local worker; a Slurm array task).
  std::string run_job;
  std::string run_step;
  int index = -1;
};

StatusOr<process::RunContext> Context() {
  process::RunContext context;
  char path[4096] = {};
  const ssize_t n = readlink("/proc/self/exe", path, sizeof(path) - 1);
  if (n <= 0) return InternalError("cannot find the facedyn executable (/proc/self/exe)");
  context.executable.assign(path, static_cast<size_t>(n));
  context.tool_version = std::string(FACEDYN_VERSION) + " (" + FACEDYN_GIT_REVISION + ")";
  return context;
}

Status RunWorker(const ProcessOptions& o, const process::RunContext& context) {
  FACEDYN_ASSIGN_OR_RETURN(const process::JobGraph graph, process::ReadPlan(o.out));
  const process::Job* job = nullptr;
  if (!o.run_job.empty()) {
    job = graph.Find(o.run_job);
    if (!job) return NotFoundError("the plan in " + o.out + " has no job " + o.run_job);
  } else {
    const auto jobs = graph.JobsOfStep(o.run_step);
    if (o.index < 0 || o.index >= static_cast<int>(jobs.size())) {
      return NotFoundError(fmt::format("the plan in {} has no task {} of step {} ({} tasks)", o.out,
                                       o.index, o.run_step, jobs.size()));
    }
    job = jobs[o.index];
  }
  const process::JobResult result = process::RunJob(graph, *job, context, o.force);
  switch (result.outcome) {
    case process::JobOutcome::kUpToDate:
      spdlog::info("{}: up to date", job->id);
      return Status::Ok();
    case process::JobOutcome::kDone:
      spdlog::info("{}: done in {:.1f} s", job->id, result.elapsed_s);
      return Status::Ok();
    case process::JobOutcome::kFailed:
      break;
  }
  return AbortedError(job->id + " failed: " + result.reason);
}

Status PrintStatus(const ProcessOptions& o, const process::RunContext& context) {
  FACEDYN_ASSIGN_OR_RETURN(const process::ProcessStatus status,
                           process::ReadProcessStatus(o.status_dir, context));
  if (o.json) {
    std::printf("%s\n", status.ToJson().dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
  } else {
    std::printf("%s", status.ToText().c_str());
  }
  return Status::Ok();
}

Status RunProcess(const ProcessOptions& o) {
  FACEDYN_ASSIGN_OR_RETURN(const process::RunContext context, Context());
  if (!o.status_dir.empty()) return PrintStatus(o, context);
  if (o.out.empty()) return InvalidArgumentError("process: --out is required");
  if (!o.run_job.empty() || !o.run_step.empty()) return RunWorker(o, context);
  if (o.session.empty()) return InvalidArgumentError("process: --session is required");

  process::ProcessConfig config;
  if (!o.config.empty()) {
    FACEDYN_ASSIGN_OR_RETURN(config, process::LoadProcessConfig(o.config));
  }
  if (!o.partition.empty()) config.slurm.partition = o.partition;
  if (!o.account.empty()) config.slurm.account = o.account;
  FACEDYN_ASSIGN_OR_RETURN(const process::JobGraph graph,
                           process::BuildJobGraph(o.session, config, o.out));
  for (const auto& s : graph.skipped) spdlog::warn("take {} skipped: {}", s.take, s.reason);

  // Never re-plan under the feet of an earlier Slurm submission that is still working.
  if (const auto earlier = process::ReadSlurmSubmission(graph.out_dir); earlier.ok()) {
    if (const auto old_plan = process::ReadPlan(graph.out_dir); old_plan.ok()) {
      const auto queued = process::QuerySlurm(*old_plan, *earlier);
      if (queued.ok() && !queued->empty()) {
        return FailedPreconditionError(fmt::format(
            "{} jobs of the Slurm submission of {} into {} are still queued or running; wait for "
            "them (facedyn process --status {}) or cancel them (scancel)",
            queued->size(), earlier->submitted_utc, graph.out_dir, graph.out_dir));
      }
    }
  }

  // Up to date in plan order: a job is when its dependencies are and its own inputs match.
  std::map<std::string, bool> up_to_date;
  std::vector<std::pair<std::string, std::string>> to_run;  // id, why
  for (const process::Job& job : graph.jobs) {
    bool deps_ok = true;
    for (const auto& d : job.deps) deps_ok = deps_ok && up_to_date[d];
    std::string why;
    const bool ok = !o.force && deps_ok && process::JobUpToDate(graph, job, context, &why);
    up_to_date[job.id] = ok;
    if (!ok)
      to_run.emplace_back(job.id,
                          o.force ? "--force" : (deps_ok ? why : "an input is redone first"));
  }
  if (o.dry_run) {
    for (const process::Job& job : graph.jobs) {
      std::string line = up_to_date[job.id] ? "up to date" : "would run";
      for (const auto& [id, why] : to_run) {
        if (id == job.id) line += " (" + why + ")";
      }
      std::printf("%-36s %s\n", job.id.c_str(), line.c_str());
    }
    return Status::Ok();
  }
  if (to_run.empty()) {
    spdlog::info("nothing to do: all {} jobs of {} are up to date", graph.jobs.size(),
                 graph.out_dir);
    if (o.json) {
      std::printf("%s\n", Json{{"up_to_date", graph.jobs.size()},
                               {"done", 0},
                               {"failed", 0},
                               {"blocked", 0},
                               {"submitted", false}}
                              .dump(2)
                              .c_str());
    }
    return Status::Ok();
  }
  FACEDYN_RETURN_IF_ERROR(process::WritePlan(graph));

  if (o.slurm) {
    // Whole arrays are submitted; their up-to-date tasks finish at once.
    FACEDYN_ASSIGN_OR_RETURN(const process::SlurmSubmission submission,
                             process::SubmitToSlurm(graph, config.slurm, context));
    for (const auto& s : submission.steps) {
      spdlog::info("submitted {} as Slurm job {} ({} tasks{}{})", s.step, s.job_id, s.tasks,
                   s.dependency.empty() ? "" : ", after ", s.dependency);
    }
    spdlog::info("{} of {} jobs to run; follow with: facedyn process --status {}", to_run.size(),
                 graph.jobs.size(), graph.out_dir);
    if (o.json) std::printf("%s\n", submission.ToJson().dump(2).c_str());
    return Status::Ok();
  }

  process::LocalOptions local;
  local.jobs = o.jobs > 0 ? o.jobs : std::max(1u, std::thread::hardware_concurrency());
  local.force = o.force;
  local.on_job = [](const process::JobReport& r, int finished, int total) {
    if (r.outcome == "failed" || r.outcome == "blocked") {
      spdlog::warn("[{}/{}] {}: {} — {}", finished, total, r.id, r.outcome, r.reason);
    } else if (r.outcome == "done") {
      spdlog::info("[{}/{}] {}: done in {:.1f} s", finished, total, r.id, r.elapsed_s);
    } else {
      spdlog::info("[{}/{}] {}: {}", finished, total, r.id, r.outcome);
    }
  };
  spdlog::info("{} of {} jobs to run with {} workers; logs in {}/process/logs", to_run.size(),
               graph.jobs.size(), local.jobs, graph.out_dir);
  FACEDYN_ASSIGN_OR_RETURN(
      const process::RunSummary summary,
      process::RunLocal(graph, context, {"--quiet", "process", "--out", graph.out_dir, "--run-job"},
                        local));
  if (o.json) {
    std::printf("%s\n", summary.ToJson().dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
  } else {
    std::fprintf(stderr, "%s", summary.ToText().c_str());
  }
  if (!summary.ok()) {
    return AbortedError(fmt::format("{} job(s) failed and {} could not run for want of them",
                                    summary.failed, summary.blocked));
  }
  return Status::Ok();
}

}  // namespace

void AddProcessCommand(CLI::App& app, CommandRunner* selected) {
  auto o = std::make_shared<ProcessOptions>();
  auto* cmd = app.add_subcommand(
      "process",
      "Reprocess a capture session as a job graph: per take reconstruct, then train the removal "
      "(F) and synthesis (H) networks and a rig solver, then per take remove, solve and export. "
      "Up-to-date steps are skipped; runs locally with N workers or on Slurm");
  cmd->add_option("--session", o->session, "Capture session folder");
  cmd->add_option("--config", o->config, "PROCESS.yaml (config/process/); default: every default");
  cmd->add_option("--out", o->out, "Output folder (on a cluster: a shared file system path)");
  cmd->add_option("--jobs,-j", o->jobs, "Local workers at once (default: the machine's cores)")
      ->check(CLI::Range(1, 1024));
  cmd->add_flag("--force", o->force, "Run every job, even those up to date");
  cmd->add_flag("--dry-run", o->dry_run, "Print which jobs would run and why; run nothing");
  cmd->add_flag("--slurm", o->slurm,
                "Submit to Slurm (one job array per step) instead of running here");
  cmd->add_option("--partition", o->partition, "With --slurm: the partition (else the config's)");
  cmd->add_option("--account", o->account, "With --slurm: the account (else the config's)");
  cmd->add_option("--status", o->status_dir,
                  "Report a run's output folder: done, running, queued, failed and why");
  cmd->add_flag("--json", o->json, "Print the run's summary (or the status) as JSON");
  // The workers' entry points; not for people.
  cmd->add_option("--run-job", o->run_job, "")->group("");
  cmd->add_option("--run-step", o->run_step, "")->group("");
  cmd->add_option("--index", o->index, "")->group("");
  cmd->callback([o, selected]() { *selected = [o]() { return RunProcess(*o); }; });
}

}  // namespace facedyn::app
