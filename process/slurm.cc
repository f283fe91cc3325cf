#include "process/slurm.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <map>
#include <set>
#include <sstream>

#include "capture/session.h"
#include "core/file_util.h"

namespace facedyn::process {
namespace {

// Single-quoted for a POSIX shell.
std::string ShellQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += (c == '\'') ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

bool PerTake(const std::string& step) {
  return step == "reconstruct" || step == "remove" || step == "solve" || step == "export";
}

}  // namespace

StatusOr<int> RunProgram(const std::vector<std::string>& argv, std::string* output) {
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0)
    return InternalError(std::string("pipe: ") + std::strerror(errno));
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const pid_t pid = fork();
  if (pid < 0) return InternalError(std::string("fork: ") + std::strerror(errno));
  if (pid == 0) {
    dup2(fds[1], STDOUT_FILENO);
    dup2(fds[1], STDERR_FILENO);
    execvp(args[0], args.data());
    const std::string message = "cannot run " + argv[0] + ": " + std::strerror(errno) + "\n";
    (void)!write(STDERR_FILENO, message.data(), message.size());
    _exit(127);
  }
  close(fds[1]);
  output->clear();
  char buffer[4096];
  while (true) {
    const ssize_t n = read(fds[0], buffer, sizeof(buffer));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    output->append(buffer, static_cast<size_t>(n));
  }
  close(fds[0]);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return InternalError(std::string("waitpid: ") + std::strerror(errno));
  }
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  return 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

Json SlurmSubmission::ToJson() const {
  Json steps_json = Json::array();
  for (const auto& s : steps) {
    steps_json.push_back(
        {{"step", s.step}, {"job_id", s.job_id}, {"tasks", s.tasks}, {"dependency", s.dependency}});
  }
  return {{"format", "facedyn-process-slurm"},
          {"version", 1},
          {"submitted_utc", submitted_utc},
          {"steps", steps_json}};
}

StatusOr<SlurmSubmission> SubmitToSlurm(const JobGraph& graph, const ProcessConfig::Slurm& options,
                                        const RunContext& context) {
  const std::string dir = JoinPath(graph.out_dir, "process/slurm");
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(dir));
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(JoinPath(graph.out_dir, "process/logs")));
  SlurmSubmission submission;
  submission.submitted_utc = capture::UtcNowIso8601();
  std::map<std::string, std::string> job_of_step;
  auto cancel_all = [&]() {
    std::string ignored;
    for (const auto& s : submission.steps) (void)RunProgram({"scancel", s.job_id}, &ignored);
  };
  for (const std::string& step : StepOrder()) {
    const std::vector<const Job*> jobs = graph.JobsOfStep(step);
    if (jobs.empty()) continue;
    // Which earlier steps this one waits for.
    std::set<std::string> dep_steps;
    for (const Job* job : jobs) {
      for (const std::string& dep : job->deps) dep_steps.insert(graph.Find(dep)->step);
    }
    std::string dependency;
    for (const std::string& dep_step : dep_steps) {
      const bool corresponding = PerTake(step) && PerTake(dep_step);
      dependency += (dependency.empty() ? "" : ",") +
                    std::string(corresponding ? "aftercorr:" : "afterok:") +
                    job_of_step.at(dep_step);
    }
    std::string script = "#!/bin/sh\n";
    script +=
        "# facedyn process: step " + step + " of " + graph.session_dir + " (written by facedyn)\n";
    script += "#SBATCH --job-name=facedyn-" + step + "\n";
    script += fmt::format("#SBATCH --array=0-{}\n", jobs.size() - 1);
    script +=
        "#SBATCH --output=" + JoinPath(graph.out_dir, "process/logs/slurm-" + step + "-%a.log") +
        "\n";
    script += fmt::format("#SBATCH --cpus-per-task={}\n", options.cpus_per_task);
    if (!options.partition.empty()) script += "#SBATCH --partition=" + options.partition + "\n";
    if (!options.account.empty()) script += "#SBATCH --account=" + options.account + "\n";
    if (!options.time_limit.empty()) script += "#SBATCH --time=" + options.time_limit + "\n";
    script += "exec " + ShellQuote(context.executable) + " --quiet process --out " +
              ShellQuote(graph.out_dir) + " --run-step " + step +
              " --index \"$SLURM_ARRAY_TASK_ID\"\n";
    const std::string script_path = JoinPath(dir, step + ".sbatch");
    FACEDYN_RETURN_IF_ERROR(WriteFileAtomic(script_path, script));
    std::vector<std::string> argv = {"sbatch", "--parsable"};
    if (!dependency.empty()) {
      argv.push_back("--dependency=" + dependency);
      argv.push_back("--kill-on-invalid-dep=yes");
    }
    argv.push_back(script_path);
    std::string output;
    const auto code = RunProgram(argv, &output);
    std::string job_id;
    if (code.ok() && *code == 0) {
      std::istringstream in(output);
      std::string line;
      while (std::getline(in, line)) {
        const std::string id = line.substr(0, line.find(';'));  // "id" or "id;cluster"
        if (!id.empty() && id.find_first_not_of("0123456789") == std::string::npos) job_id = id;
      }
    }
    if (job_id.empty()) {
      cancel_all();
      while (!output.empty() && (output.back() == '\n' || output.back() == '\r')) output.pop_back();
      return UnavailableError(
          "sbatch refused step " + step + " (" +
          (code.ok() ? "exit " + std::to_string(*code) : code.status().message()) + "): " + output +
          (submission.steps.empty() ? "" : "; the steps already submitted were cancelled"));
    }
    job_of_step[step] = job_id;
    submission.steps.push_back({step, job_id, static_cast<int>(jobs.size()), dependency});
  }
  FACEDYN_RETURN_IF_ERROR(
      WriteJsonFile(JoinPath(graph.out_dir, "process/slurm.json"), submission.ToJson()));
  return submission;
}

StatusOr<SlurmSubmission> ReadSlurmSubmission(const std::string& out_dir) {
  const std::string path = JoinPath(out_dir, "process/slurm.json");
  FACEDYN_ASSIGN_OR_RETURN(const std::string text, ReadFileToString(path));
  try {
    const Json j = Json::parse(text);
    SlurmSubmission s;
    s.submitted_utc = j.at("submitted_utc").get<std::string>();
    for (const auto& step : j.at("steps")) {
      s.steps.push_back({step.at("step").get<std::string>(), step.at("job_id").get<std::string>(),
                         step.at("tasks").get<int>(), step.at("dependency").get<std::string>()});
    }
    return s;
  } catch (const Json::exception& e) {
    return DataLossError(path + ": not a facedyn Slurm submission (" + e.what() + ")");
  }
}

StatusOr<std::map<std::string, std::string>> QuerySlurm(const JobGraph& graph,
                                                        const SlurmSubmission& submission) {
  std::map<std::string, std::string> states;
  if (submission.steps.empty()) return states;
  std::string ids;
  std::map<std::string, std::string> step_of_job;
  for (const auto& s : submission.steps) {
    ids += (ids.empty() ? "" : ",") + s.job_id;
    step_of_job[s.job_id] = s.step;
  }
  std::string output;
  // -r: one line per array task ("123_4"); %i job id, %T state, %r reason.
  FACEDYN_ASSIGN_OR_RETURN(
      const int code, RunProgram({"squeue", "-h", "-r", "-j", ids, "-o", "%i|%T|%r"}, &output));
  if (code != 0) {
    // squeue fails for job ids it has forgotten; that means none is queued any more.
    if (output.find("Invalid job id") != std::string::npos) return states;
    return UnavailableError("squeue failed: " + output);
  }
  std::istringstream in(output);
  std::string line;
  while (std::getline(in, line)) {
    const size_t a = line.find('|');
    const size_t b = line.find('|', a + 1);
    if (a == std::string::npos || b == std::string::npos) continue;
    const std::string id = line.substr(0, a);
    const std::string state = line.substr(a + 1, b - a - 1);
    const std::string reason = line.substr(b + 1);
    const size_t underscore = id.find('_');
    if (underscore == std::string::npos) continue;
    const auto step = step_of_job.find(id.substr(0, underscore));
    if (step == step_of_job.end()) continue;
    const std::string task = id.substr(underscore + 1);
    std::vector<const Job*> jobs = graph.JobsOfStep(step->second);
    auto add = [&](int index) {
      if (index >= 0 && index < static_cast<int>(jobs.size())) {
        states[jobs[index]->id] =
            state + (reason.empty() || reason == "None" ? "" : " (" + reason + ")");
      }
    };
    // A pending array not yet split is listed as "123_[0-5]" (or "123_[2,4-5]").
    if (!task.empty() && task[0] == '[') {
      std::string ranges = task.substr(1, task.find(']') - 1);
      std::istringstream rs(ranges);
      std::string range;
      while (std::getline(rs, range, ',')) {
        const size_t dash = range.find('-');
        try {
          const int lo = std::stoi(range.substr(0, dash));
          const int hi = dash == std::string::npos ? lo : std::stoi(range.substr(dash + 1));
          for (int i = lo; i <= hi; ++i) add(i);
        } catch (const std::exception&) {
        }
      }
    } else {
      try {
        add(std::stoi(task));
      } catch (const std::exception&) {
      }
    }
  }
  return states;
}

}  // namespace facedyn::process
