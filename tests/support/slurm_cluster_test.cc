// LocalSlurmCluster against the real Slurm 22.05 and munge daemons: jobs, a dependency and an
// array run; Stop() and a failed Start() leave no daemon behind. Skipped (not passed) where
// Slurm is not installed or the test is not root.
#include "tests/support/slurm_cluster.h"

#include <gtest/gtest.h>
#include <signal.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/test_support.h"

namespace facedyn::testing {
namespace {

#define SKIP_WITHOUT_SLURM() \
  if (const std::string reason = SlurmUnavailableReason(); !reason.empty()) GTEST_SKIP() << reason

std::string Trim(const std::string& s) {
  const size_t begin = s.find_first_not_of(" \t\n");
  if (begin == std::string::npos) return "";
  return s.substr(begin, s.find_last_not_of(" \t\n") - begin + 1);
}

std::string ShellQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// Runs a Slurm client of `cluster` through the shell; EXPECTs exit code 0.
std::string Client(const LocalSlurmCluster& cluster, const std::string& command) {
  std::string output;
  EXPECT_EQ(RunCommand(cluster.EnvironmentPrefix() + command, &output), 0) << command << "\n"
                                                                           << output;
  return Trim(output);
}

// The JobState of every record of job `id` (one per array task) from `scontrol -o show job`.
std::vector<std::string> JobStates(const LocalSlurmCluster& cluster, const std::string& id) {
  std::string output;
  RunCommand(cluster.EnvironmentPrefix() + "scontrol -o show job " + id, &output);
  std::vector<std::string> states;
  std::istringstream lines(output);
  std::string line;
  while (std::getline(lines, line)) {
    const size_t at = line.find(" JobState=");
    if (at == std::string::npos) continue;
    const size_t begin = at + 10;
    states.push_back(line.substr(begin, line.find(' ', begin) - begin));
  }
  return states;
}

// Waits (at most timeout_s) until every record of every job in `ids` is in a final state;
// returns "<id>: STATE STATE ..." lines, the last seen.
std::string WaitForJobs(const LocalSlurmCluster& cluster, const std::vector<std::string>& ids,
                        double timeout_s) {
  static const std::set<std::string> kFinal = {"COMPLETED", "FAILED",    "CANCELLED",
                                               "TIMEOUT",   "NODE_FAIL", "OUT_OF_MEMORY",
                                               "BOOT_FAIL", "DEADLINE",  "PREEMPTED"};
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (;;) {
    std::string summary;
    bool done = true;
    for (const std::string& id : ids) {
      const std::vector<std::string> states = JobStates(cluster, id);
      summary += id + ":";
      if (states.empty()) done = false;
      for (const std::string& state : states) {
        summary += " " + state;
        if (!kFinal.count(state)) done = false;
      }
      summary += "\n";
    }
    if (done || std::chrono::steady_clock::now() > deadline) return summary;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
}

int ReadPid(const std::string& path) {
  std::ifstream in(path);
  int pid = -1;
  in >> pid;
  return pid;
}

bool Alive(int pid) { return pid > 0 && ::kill(pid, 0) == 0; }

// Processes whose command line names `dir` (the daemons all carry their folder in argv).
std::string ProcessesMentioning(const std::string& dir) {
  std::string output;
  // exec: the shell becomes pgrep, which leaves itself out.
  RunCommand("exec pgrep -a -f " + ShellQuote(dir), &output);
  return output;
}

TEST(LocalSlurmCluster, RunsJobsWithDependencyAndArrayThenStopsEverything) {
  SKIP_WITHOUT_SLURM();
  TempDir tmp;
  const std::string dir = tmp.Join("slurm");
  const char* conf_before = std::getenv("SLURM_CONF");
  const std::string conf_before_value = conf_before ? conf_before : "(unset)";

  LocalSlurmCluster cluster;
  EXPECT_FALSE(cluster.running());
  ASSERT_EQ(cluster.Start(dir), "");
  ASSERT_TRUE(cluster.running());
  const char* conf_after = std::getenv("SLURM_CONF");
  EXPECT_EQ(conf_after ? conf_after : "(unset)", conf_before_value);
  const auto environment = cluster.Environment();
  ASSERT_EQ(environment.size(), 1u);
  EXPECT_EQ(environment[0].first, "SLURM_CONF");
  EXPECT_EQ(environment[0].second, dir + "/slurm.conf");
  EXPECT_TRUE(std::filesystem::exists(cluster.log_dir() + "/slurmctld.log"));

  const std::vector<int> pids = {ReadPid(dir + "/munge/munged.pid"),
                                 ReadPid(dir + "/slurmctld.pid"), ReadPid(dir + "/slurmd.pid")};
  for (int pid : pids) EXPECT_TRUE(Alive(pid)) << pid;

  // One idle node with the machine's CPUs in the default partition.
  EXPECT_EQ(Client(cluster, "sinfo -h -o '%P %t %c'"),
            cluster.partition() + "* idle " + std::to_string(std::thread::hardware_concurrency()));

  const std::string common = "sbatch --parsable --chdir=" + ShellQuote(tmp.path()) +
                             " --output=" + ShellQuote(tmp.Join("slurm-%j.out")) + " ";
  const std::string first = Client(cluster, common + "--wrap 'echo hello > first.txt'");
  ASSERT_FALSE(first.empty());
  // Reads what the first job wrote: runs only after it, as the dependency says.
  const std::string second = Client(
      cluster, common + "--dependency=afterok:" + first + " --wrap 'cat first.txt > second.txt'");
  const std::string array =
      Client(cluster, "sbatch --parsable --array=0-2 --chdir=" + ShellQuote(tmp.path()) +
                          " --output=" + ShellQuote(tmp.Join("array-%A_%a.out")) +
                          " --wrap 'echo $SLURM_ARRAY_TASK_ID > task_$SLURM_ARRAY_TASK_ID.txt'");
  ASSERT_FALSE(second.empty());
  ASSERT_FALSE(array.empty());

  EXPECT_EQ(WaitForJobs(cluster, {first, second, array}, 20.0),
            first + ": COMPLETED\n" + second + ": COMPLETED\n" + array +
                ": COMPLETED COMPLETED COMPLETED\n");
  EXPECT_EQ(ReadBytes(tmp.Join("first.txt")), "hello\n");
  EXPECT_EQ(ReadBytes(tmp.Join("second.txt")), "hello\n");
  for (int task = 0; task < 3; ++task) {
    EXPECT_EQ(ReadBytes(tmp.Join("task_" + std::to_string(task) + ".txt")),
              std::to_string(task) + "\n");
  }

  cluster.Stop();
  EXPECT_FALSE(cluster.running());
  EXPECT_TRUE(cluster.Environment().empty());
  for (int pid : pids) {
    EXPECT_FALSE(Alive(pid)) << pid;
    EXPECT_EQ(errno, ESRCH);
  }
  EXPECT_EQ(ProcessesMentioning(dir), "");
  cluster.Stop();  // Idempotent.
  EXPECT_FALSE(cluster.running());
}

TEST(LocalSlurmCluster, StopCancelsARunningJob) {
  SKIP_WITHOUT_SLURM();
  TempDir tmp;
  const std::string dir = tmp.Join("slurm");
  int job_pid = -1;
  {
    LocalSlurmCluster cluster;
    ASSERT_EQ(cluster.Start(dir), "");
    Client(cluster, "sbatch --parsable --chdir=" + ShellQuote(tmp.path()) +
                        " --output=/dev/null --wrap 'echo $$ > job.pid; exec sleep 300'");
    for (int i = 0; i < 100 && job_pid <= 0; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      job_pid = ReadPid(tmp.Join("job.pid"));
    }
    ASSERT_TRUE(Alive(job_pid));
    // The destructor stops the cluster.
  }
  EXPECT_FALSE(Alive(job_pid)) << "the job's sleep outlived the cluster";
  EXPECT_EQ(ProcessesMentioning(dir), "");
}

TEST(LocalSlurmCluster, TwoClustersSideBySide) {
  SKIP_WITHOUT_SLURM();
  TempDir tmp;
  LocalSlurmCluster a;
  LocalSlurmCluster b;
  ASSERT_EQ(a.Start(tmp.Join("a")), "");
  ASSERT_EQ(b.Start(tmp.Join("b")), "");
  const std::string job = Client(b, "sbatch --parsable --hold --output=/dev/null --wrap true");
  // Each cluster sees its own jobs only.
  EXPECT_EQ(Client(b, "squeue -h -o %i"), job);
  EXPECT_EQ(Client(a, "squeue -h -o %i"), "");
  a.Stop();
  EXPECT_TRUE(b.running());
  EXPECT_EQ(Client(b, "squeue -h -o %i"), job);
}

TEST(LocalSlurmCluster, FailedStartNamesTheDaemonAndLeavesNothingRunning) {
  SKIP_WITHOUT_SLURM();
  TempDir tmp;
  // A slurmctld that refuses to start, found first on PATH.
  const std::string bin = tmp.Join("bin");
  std::filesystem::create_directory(bin);
  WriteBytes(bin + "/slurmctld",
             "#!/bin/sh\necho 'fake slurmctld: refusing to start' >&2\nexit 3\n");
  std::filesystem::permissions(bin + "/slurmctld", std::filesystem::perms::owner_all);
  const char* path = std::getenv("PATH");
  const std::string old_path = path ? path : "/usr/bin:/bin";
  ::setenv("PATH", (bin + ":" + old_path).c_str(), 1);

  const std::string dir = tmp.Join("slurm");
  LocalSlurmCluster cluster;
  const std::string error = cluster.Start(dir);
  ::setenv("PATH", old_path.c_str(), 1);

  EXPECT_NE(error.find("slurmctld exited (exit code 3)"), std::string::npos) << error;
  EXPECT_NE(error.find("fake slurmctld: refusing to start"), std::string::npos) << error;
  EXPECT_FALSE(cluster.running());
  EXPECT_TRUE(cluster.Environment().empty());
  // munged had started (its log says so) and was stopped (it removes its pid file then).
  const std::string munged_log = ReadBytes(dir + "/log/munged.log");
  EXPECT_NE(munged_log.find("Created socket"), std::string::npos) << munged_log;
  EXPECT_NE(munged_log.find("Exiting on signal 15"), std::string::npos) << munged_log;
  EXPECT_FALSE(std::filesystem::exists(dir + "/munge/munged.pid"));
  EXPECT_EQ(ProcessesMentioning(dir), "");
}

TEST(LocalSlurmCluster, RefusesFoldersSlurmCannotUse) {
  SKIP_WITHOUT_SLURM();
  TempDir tmp;
  LocalSlurmCluster cluster;
  const std::string too_long = tmp.Join(std::string(100, 'x'));
  EXPECT_NE(cluster.Start(too_long).find("too long for the Unix sockets"), std::string::npos);
  EXPECT_NE(cluster.Start(tmp.Join("a b")).find("a character slurm.conf cannot carry"),
            std::string::npos);
  EXPECT_FALSE(cluster.running());
  EXPECT_FALSE(std::filesystem::exists(too_long));
}

}  // namespace
}  // namespace facedyn::testing
