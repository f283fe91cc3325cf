#include "process/job_runner.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "capture/session.h"
#include "core/config_node.h"
#include "core/file_util.h"
#include "process/content_hash.h"

namespace facedyn::process {
namespace fs = std::filesystem;
namespace {

std::string HostName() {
  char name[256] = {};
  if (gethostname(name, sizeof(name) - 1) != 0) return "unknown";
  return name;
}

std::vector<std::string> HashExtras(const Job& job, const RunContext& context) {
  std::vector<std::string> extra = {"facedyn " + context.tool_version};
  for (const auto& command : job.commands) {
    std::string line;
    for (const std::string& a : command) line += a + '\0';
    extra.push_back(line);
  }
  return extra;
}

Json StateToJson(const Job& job, const JobState& s) {
  Json j = {{"job", job.id},
            {"status", s.status},
            {"input_hash", s.input_hash},
            {"reason", s.reason},
            {"host", s.host},
            {"pid", s.pid},
            {"started_utc", s.started_utc},
            {"finished_utc", s.finished_utc},
            {"elapsed_s", s.elapsed_s},
            {"slurm_job", s.slurm_job},
            {"files", s.files}};
  return j;
}

Status WriteState(const JobGraph& graph, const Job& job, const JobState& state) {
  const std::string path = StatePath(graph.out_dir, job.id);
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(fs::path(path).parent_path().string()));
  return WriteJsonFile(path, StateToJson(job, state));
}

// The last two non-empty lines of a log, for a failure's one-line reason (one line is often
// only "Run with --help for more information.").
std::string LastLogLines(const std::string& path) {
  std::ifstream in(path);
  std::string line, previous, last;
  while (std::getline(in, line)) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    previous = last;
    last = line;
  }
  std::string text = previous.empty() ? last : previous + " / " + last;
  if (text.size() > 400) text = text.substr(0, 400) + "...";
  return text;
}

std::string SlurmJobName() {
  const char* array_job = getenv("SLURM_ARRAY_JOB_ID");
  const char* task = getenv("SLURM_ARRAY_TASK_ID");
  if (array_job && task) return std::string(array_job) + "_" + task;
  const char* job = getenv("SLURM_JOB_ID");
  return job ? job : "";
}

// Runs `executable args...` with stdout and stderr appended to `log_fd`; the child dies with this
// process (PR_SET_PDEATHSIG), so killing a worker never leaves a step running unseen.
StatusOr<int> RunCommand(const std::string& executable, const std::vector<std::string>& args,
                         int log_fd) {
  std::vector<char*> argv;
  argv.push_back(const_cast<char*>(executable.c_str()));
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid < 0) return InternalError(std::string("fork: ") + std::strerror(errno));
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (getppid() != parent) _exit(125);
    dup2(log_fd, STDOUT_FILENO);
    dup2(log_fd, STDERR_FILENO);
    const int null_fd = open("/dev/null", O_RDONLY);
    if (null_fd >= 0) dup2(null_fd, STDIN_FILENO);
    execv(executable.c_str(), argv.data());
    const std::string message = std::string("facedyn process: cannot run ") + executable + ": " +
                                std::strerror(errno) + "\n";
    (void)!write(STDERR_FILENO, message.data(), message.size());
    _exit(127);
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return InternalError(std::string("waitpid: ") + std::strerror(errno));
  }
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return -1;
}

// "dynamics train-removal" from "--quiet dynamics train-removal --takes ...".
std::string CommandName(const std::vector<std::string>& command) {
  std::string name;
  size_t i = 0;
  while (i < command.size() && command[i].rfind("-", 0) == 0) ++i;
  for (; i < command.size() && command[i].rfind("-", 0) != 0; ++i)
    name += (name.empty() ? "" : " ") + command[i];
  return name;
}

}  // namespace

JobState ReadJobState(const std::string& out_dir, const std::string& job_id) {
  JobState s;
  const auto text = ReadFileToString(StatePath(out_dir, job_id));
  if (!text.ok()) return s;
  try {
    const Json j = Json::parse(*text);
    s.status = j.value("status", "");
    s.input_hash = j.value("input_hash", "");
    s.reason = j.value("reason", "");
    s.host = j.value("host", "");
    s.pid = j.value("pid", int64_t{0});
    s.started_utc = j.value("started_utc", "");
    s.finished_utc = j.value("finished_utc", "");
    s.elapsed_s = j.value("elapsed_s", 0.0);
    s.slurm_job = j.value("slurm_job", "");
    s.files = j.value("files", Json::array());
  } catch (const Json::exception& e) {
    s = JobState{};
    s.status = "";
    s.reason = StatePath(out_dir, job_id) + " unreadable: " + e.what();
  }
  return s;
}

bool JobUpToDate(const JobGraph& graph, const Job& job, const RunContext& context,
                 std::string* why) {
  auto say = [&](const std::string& reason) {
    if (why) *why = reason;
    return false;
  };
  const JobState state = ReadJobState(graph.out_dir, job.id);
  if (state.status.empty()) return say("never run");
  if (state.status == "failed") return say("failed last time: " + state.reason);
  if (state.status == "running") return say("interrupted or still running on " + state.host);
  if (state.status != "done") return say("unknown state '" + state.status + "'");
  for (const std::string& out : job.outputs) {
    if (!fs::exists(out)) return say("output " + out + " is missing");
  }
  FileHashCache cache = FileHashCache::FromJson(state.files);
  const auto hash = HashInputs(job.inputs, HashExtras(job, context), &cache);
  if (!hash.ok()) return say(hash.status().message());
  if (*hash != state.input_hash) return say("inputs, options or facedyn version changed");
  if (why) why->clear();
  return true;
}

JobResult RunJob(const JobGraph& graph, const Job& job, const RunContext& context, bool force) {
  JobResult result;
  const auto start = std::chrono::steady_clock::now();
  for (const std::string& dep : job.deps) {
    const JobState dep_state = ReadJobState(graph.out_dir, dep);
    if (dep_state.status != "done") {
      result.reason = "needs " + dep + ", which is " +
                      (dep_state.status.empty() ? std::string("not run") : dep_state.status);
      JobState failed;
      failed.status = "failed";
      failed.reason = result.reason;
      failed.host = HostName();
      failed.finished_utc = capture::UtcNowIso8601();
      failed.slurm_job = SlurmJobName();
      (void)WriteState(graph, job, failed);
      return result;
    }
  }
  if (!force && JobUpToDate(graph, job, context, nullptr)) {
    result.outcome = JobOutcome::kUpToDate;
    return result;
  }

  JobState state;
  state.status = "running";
  state.host = HostName();
  state.pid = getpid();
  state.started_utc = capture::UtcNowIso8601();
  state.slurm_job = SlurmJobName();
  auto fail = [&](const std::string& reason) {
    state.status = "failed";
    state.reason = reason;
    state.finished_utc = capture::UtcNowIso8601();
    state.elapsed_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    (void)WriteState(graph, job, state);
    result.outcome = JobOutcome::kFailed;
    result.reason = reason;
    result.elapsed_s = state.elapsed_s;
    return result;
  };
  if (Status s = WriteState(graph, job, state); !s.ok()) return fail(s.message());

  // Hash the inputs before running: what the outputs are recorded against is what was read.
  FileHashCache cache = FileHashCache::FromJson(ReadJobState(graph.out_dir, job.id).files);
  const auto hash = HashInputs(job.inputs, HashExtras(job, context), &cache);
  if (!hash.ok()) return fail(hash.status().message());
  state.input_hash = *hash;
  state.files = cache.ToJson();

  for (const std::string& out : job.outputs) {
    std::error_code ec;
    fs::remove_all(out, ec);
    if (ec) return fail("cannot remove the old output " + out + ": " + ec.message());
    if (Status s = MakeDirectories(fs::path(out).parent_path().string()); !s.ok()) {
      return fail(s.message());
    }
  }
  const std::string log_path = LogPath(graph.out_dir, job.id);
  if (Status s = MakeDirectories(fs::path(log_path).parent_path().string()); !s.ok()) {
    return fail(s.message());
  }
  const int log_fd = open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (log_fd < 0) return fail("cannot write the log " + log_path + ": " + std::strerror(errno));
  for (const auto& command : job.commands) {
    std::string line = "$ facedyn";
    for (const std::string& a : command) line += " " + a;
    line += "\n";
    (void)!write(log_fd, line.data(), line.size());
    const auto code = RunCommand(context.executable, command, log_fd);
    if (!code.ok()) {
      close(log_fd);
      return fail(code.status().message());
    }
    if (*code != 0) {
      close(log_fd);
      const std::string last = LastLogLines(log_path);
      return fail("facedyn " + CommandName(command) + " exited with " + std::to_string(*code) +
                  (last.empty() ? "" : ": " + last) + " (log: " + log_path + ")");
    }
  }
  close(log_fd);
  for (const std::string& out : job.outputs) {
    if (!fs::exists(out)) return fail("the command succeeded but did not write " + out);
  }
  state.status = "done";
  state.finished_utc = capture::UtcNowIso8601();
  state.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (Status s = WriteState(graph, job, state); !s.ok()) return fail(s.message());
  result.outcome = JobOutcome::kDone;
  result.elapsed_s = state.elapsed_s;
  return result;
}

}  // namespace facedyn::process
