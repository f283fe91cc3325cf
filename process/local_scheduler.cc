#include "process/local_scheduler.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <map>

namespace facedyn::process {
namespace {

enum class Phase { kPending, kRunning, kFinished };

// The worker's own messages (not its command's: those are in the job's log) go to
// `output_path`, so that a worker that cannot even start its command leaves a trace.
StatusOr<pid_t> SpawnWorker(const std::string& executable, const std::vector<std::string>& args,
                            const std::string& output_path) {
  std::vector<char*> argv;
  argv.push_back(const_cast<char*>(executable.c_str()));
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid < 0) return InternalError(std::string("fork: ") + std::strerror(errno));
  if (pid == 0) {
    // A worker (and through it the step's command) dies with the scheduler: killing
    // `facedyn process` stops everything it started, and the next run redoes what was cut.
    prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (getppid() != parent) _exit(125);
    const int fd = open(output_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd >= 0) {
      dup2(fd, STDOUT_FILENO);
      dup2(fd, STDERR_FILENO);
    }
    execv(executable.c_str(), argv.data());
    _exit(127);
  }
  return pid;
}

}  // namespace

Json RunSummary::ToJson() const {
  Json jobs_json = Json::array();
  for (const JobReport& j : jobs) {
    jobs_json.push_back(
        {{"id", j.id}, {"outcome", j.outcome}, {"reason", j.reason}, {"elapsed_s", j.elapsed_s}});
  }
  return {{"up_to_date", up_to_date}, {"done", done},     {"failed", failed},
          {"blocked", blocked},       {"wall_s", wall_s}, {"jobs", jobs_json}};
}

std::string RunSummary::ToText() const {
  std::string text;
  if (done == 0 && failed == 0 && blocked == 0) {
    return fmt::format("nothing to do: all {} jobs are up to date\n", up_to_date);
  }
  text += fmt::format("{} done, {} up to date, {} failed, {} blocked in {:.1f} s\n", done,
                      up_to_date, failed, blocked, wall_s);
  for (const JobReport& j : jobs) {
    if (j.outcome == "failed" || j.outcome == "blocked") {
      text += fmt::format("  {:<8} {}: {}\n", j.outcome, j.id, j.reason);
    }
  }
  return text;
}

StatusOr<RunSummary> RunLocal(const JobGraph& graph, const RunContext& context,
                              const std::vector<std::string>& worker_args,
                              const LocalOptions& options) {
  if (options.jobs < 1) return InvalidArgumentError("--jobs must be at least 1");
  const auto start = std::chrono::steady_clock::now();
  const int total = static_cast<int>(graph.jobs.size());
  std::vector<Phase> phase(total, Phase::kPending);
  std::vector<JobReport> reports(total);
  std::map<std::string, int> index;
  for (int i = 0; i < total; ++i) {
    index[graph.jobs[i].id] = i;
    reports[i].id = graph.jobs[i].id;
  }
  std::map<pid_t, int> running;
  std::map<int, std::chrono::steady_clock::time_point> started;
  int finished = 0;
  auto finish = [&](int i, const std::string& outcome, const std::string& reason, double s) {
    phase[i] = Phase::kFinished;
    reports[i].outcome = outcome;
    reports[i].reason = reason;
    reports[i].elapsed_s = s;
    ++finished;
    if (options.on_job) options.on_job(reports[i], finished, total);
  };
  auto succeeded = [&](int i) {
    return phase[i] == Phase::kFinished &&
           (reports[i].outcome == "done" || reports[i].outcome == "up to date");
  };

  while (finished < total) {
    bool progressed = false;
    for (int i = 0; i < total; ++i) {
      if (phase[i] != Phase::kPending) continue;
      const Job& job = graph.jobs[i];
      bool ready = true;
      std::string blocker;
      for (const std::string& dep : job.deps) {
        const auto it = index.find(dep);
        if (it == index.end()) {
          blocker = dep + " (not in the plan)";
          break;
        }
        const int d = it->second;
        if (phase[d] != Phase::kFinished) {
          ready = false;
        } else if (!succeeded(d)) {
          blocker = dep + " (" + reports[d].outcome + ")";
          break;
        }
      }
      if (!blocker.empty()) {
        finish(i, "blocked", "needs " + blocker, 0.0);
        progressed = true;
        continue;
      }
      if (!ready) continue;
      if (!options.force && JobUpToDate(graph, job, context, nullptr)) {
        finish(i, "up to date", "", 0.0);
        progressed = true;
        continue;
      }
      if (static_cast<int>(running.size()) >= options.jobs) continue;
      std::vector<std::string> args = worker_args;
      args.push_back(job.id);
      if (options.force) args.push_back("--force");
      FACEDYN_ASSIGN_OR_RETURN(
          const pid_t pid,
          SpawnWorker(context.executable, args, LogPath(graph.out_dir, job.id) + ".worker"));
      running[pid] = i;
      started[i] = std::chrono::steady_clock::now();
      phase[i] = Phase::kRunning;
      progressed = true;
    }
    if (finished >= total) break;
    if (progressed && static_cast<int>(running.size()) < options.jobs) continue;
    if (running.empty()) {
      return InternalError("process: no job can start and none is running (a cycle in the plan?)");
    }
    int status = 0;
    const pid_t pid = waitpid(-1, &status, 0);
    if (pid < 0) {
      if (errno == EINTR) continue;
      return InternalError(std::string("waitpid: ") + std::strerror(errno));
    }
    const auto it = running.find(pid);
    if (it == running.end()) continue;
    const int i = it->second;
    running.erase(it);
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started[i]).count();
    const JobState state = ReadJobState(graph.out_dir, graph.jobs[i].id);
    const bool exited_ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    if (exited_ok && state.status == "done") {
      finish(i, "done", "", elapsed);
    } else {
      std::string reason = state.status == "failed" ? state.reason : std::string();
      if (reason.empty()) {
        reason = (WIFSIGNALED(status)
                      ? fmt::format("the worker was killed by signal {}", WTERMSIG(status))
                      : fmt::format("the worker exited with {}", WEXITSTATUS(status))) +
                 " (see " + LogPath(graph.out_dir, graph.jobs[i].id) + ".worker)";
      }
      finish(i, "failed", reason, elapsed);
    }
  }
  RunSummary summary;
  summary.jobs = reports;
  for (const JobReport& r : reports) {
    if (r.outcome == "up to date") ++summary.up_to_date;
    if (r.outcome == "done") ++summary.done;
    if (r.outcome == "failed") ++summary.failed;
    if (r.outcome == "blocked") ++summary.blocked;
  }
  summary.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace facedyn::process
