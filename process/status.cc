#include "process/status.h"

#include <fmt/format.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <filesystem>
#include <fstream>

#include "process/slurm.h"

namespace facedyn::process {

namespace {

// A process that exists and is not a zombie (a worker whose scheduler was killed is re-parented;
// where nothing reaps it, it lingers as a zombie but runs nothing).
bool ProcessAlive(int64_t pid) {
  if (pid <= 0) return false;
  if (kill(static_cast<pid_t>(pid), 0) != 0 && errno != EPERM) return false;
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string text;
  std::getline(stat, text);
  const size_t paren = text.rfind(')');
  if (paren == std::string::npos || paren + 2 >= text.size()) return true;
  return text[paren + 2] != 'Z';
}

}  // namespace

int ProcessStatus::Count(const std::string& state) const {
  int n = 0;
  for (const JobStatus& j : jobs) n += j.state == state;
  return n;
}

Json ProcessStatus::ToJson() const {
  Json jobs_json = Json::array();
  for (const JobStatus& j : jobs) {
    jobs_json.push_back({{"id", j.id}, {"state", j.state}, {"detail", j.detail}, {"log", j.log}});
  }
  Json counts = Json::object();
  for (const char* s :
       {"done", "stale", "running", "queued", "failed", "interrupted", "not started"}) {
    counts[s] = Count(s);
  }
  Json skipped_json = Json::array();
  for (const auto& s : skipped) skipped_json.push_back({{"take", s.take}, {"reason", s.reason}});
  return {{"out", out_dir},   {"slurm", slurm},    {"slurm_problem", slurm_problem},
          {"counts", counts}, {"jobs", jobs_json}, {"skipped_takes", skipped_json}};
}

std::string ProcessStatus::ToText() const {
  std::string text = fmt::format("{}: {} jobs — {} done", out_dir, jobs.size(), Count("done"));
  for (const char* s : {"stale", "running", "queued", "failed", "interrupted", "not started"}) {
    if (Count(s) > 0) text += fmt::format(", {} {}", Count(s), s);
  }
  text += "\n";
  for (const JobStatus& j : jobs) {
    if (j.state == "done") continue;
    text += fmt::format("  {:<12} {}", j.state, j.id);
    if (!j.detail.empty()) text += ": " + j.detail;
    text += "\n";
  }
  for (const auto& s : skipped) text += fmt::format("  skipped take {}: {}\n", s.take, s.reason);
  if (!slurm_problem.empty()) text += "  (Slurm not asked: " + slurm_problem + ")\n";
  return text;
}

StatusOr<ProcessStatus> ReadProcessStatus(const std::string& out_dir, const RunContext& context) {
  FACEDYN_ASSIGN_OR_RETURN(const JobGraph graph, ReadPlan(out_dir));
  ProcessStatus status;
  status.out_dir = graph.out_dir;
  status.skipped = graph.skipped;
  std::map<std::string, std::string> queued;
  if (const auto submission = ReadSlurmSubmission(out_dir); submission.ok()) {
    status.slurm = true;
    const auto states = QuerySlurm(graph, *submission);
    if (states.ok()) {
      queued = *states;
    } else {
      status.slurm_problem = states.status().message();
    }
  }
  char host[256] = {};
  gethostname(host, sizeof(host) - 1);
  for (const Job& job : graph.jobs) {
    JobStatus js;
    js.id = job.id;
    const JobState state = ReadJobState(out_dir, job.id);
    const std::string log = LogPath(out_dir, job.id);
    if (std::filesystem::exists(log)) js.log = log;
    const auto q = queued.find(job.id);
    if (state.status == "done") {
      std::string why;
      if (JobUpToDate(graph, job, context, &why)) {
        js.state = "done";
      } else {
        js.state = "stale";
        js.detail = why;
      }
    } else if (state.status == "failed") {
      js.state = "failed";
      js.detail = state.reason;
    } else if (state.status == "running") {
      // Alive when Slurm still lists it, or when it ran here and its pid is alive.
      const bool local_alive =
          state.slurm_job.empty() && state.host == host && ProcessAlive(state.pid);
      if (q != queued.end() || local_alive) {
        js.state = "running";
        js.detail = "on " + state.host +
                    (state.slurm_job.empty() ? "" : " as Slurm job " + state.slurm_job) +
                    " since " + state.started_utc;
      } else {
        js.state = "interrupted";
        js.detail = "started " + state.started_utc + " on " + state.host + ", never finished";
      }
    } else if (q != queued.end()) {
      js.state = "queued";
      js.detail = q->second;
    } else {
      js.state = "not started";
    }
    status.jobs.push_back(std::move(js));
  }
  return status;
}

}  // namespace facedyn::process
