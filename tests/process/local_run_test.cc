// The local scheduler and its workers on small plans of real facedyn commands: a job runs once,
// a second run does nothing, a changed input re-runs exactly what its bytes reach, a failure
// blocks only what needs it, and a status report names each state.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>

#include "process/job_graph.h"
#include "process/local_scheduler.h"
#include "process/status.h"
#include "tests/support/test_support.h"

namespace facedyn::process {
namespace {

using ::facedyn::testing::FacedynExecutable;
using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

// face <- input.txt (an input the command does not read: only its bytes decide re-runs)
// rig  <- face      (a glTF of the face rig)
// bad  (an unknown flag: fails)
// after_bad <- bad
JobGraph SmallPlan(const TempDir& dir) {
  JobGraph graph;
  graph.session_dir = dir.Join("session");
  graph.out_dir = dir.Join("out");
  graph.takes = {"x"};
  auto out = [&](const std::string& name) { return dir.Join("out/" + name); };
  graph.jobs.push_back({"face",
                        "reconstruct",
                        "x",
                        {{"--quiet", "sim", "face", "--out", out("face")}},
                        {dir.Join("input.txt")},
                        {out("face")},
                        {}});
  graph.jobs.push_back(
      {"rig",
       "export",
       "x",
       {{"--quiet", "export", "--rig", out("face"), "--format", "glb", "--out", out("rig")}},
       {out("face")},
       {out("rig")},
       {"face"}});
  graph.jobs.push_back({"bad",
                        "train-solver",
                        "",
                        {{"--quiet", "sim", "face", "--out", out("bad"), "--no-such-flag"}},
                        {},
                        {out("bad")},
                        {}});
  graph.jobs.push_back({"after_bad",
                        "solve",
                        "x",
                        {{"--quiet", "sim", "face", "--out", out("after_bad")}},
                        {out("bad")},
                        {out("after_bad")},
                        {"bad"}});
  return graph;
}

std::map<std::string, std::string> Outcomes(const RunSummary& summary) {
  std::map<std::string, std::string> m;
  for (const JobReport& r : summary.jobs) m[r.id] = r.outcome;
  return m;
}

class LocalRun : public ::testing::Test {
 protected:
  void SetUp() override {
    WriteBytes(dir_.Join("input.txt"), "one");
    graph_ = SmallPlan(dir_);
    ASSERT_TRUE(WritePlan(graph_).ok());
    context_.executable = FacedynExecutable();
    // The workers hash with the version of the binary they are: "facedyn X (rev)".
    std::string version;
    ASSERT_EQ(testing::RunCommand(context_.executable + " --version", &version), 0);
    while (!version.empty() && version.back() == '\n') version.pop_back();
    context_.tool_version = version.substr(version.find(' ') + 1);
  }
  RunSummary Run(int jobs = 2) {
    LocalOptions options;
    options.jobs = jobs;
    const auto summary = RunLocal(
        graph_, context_, {"--quiet", "process", "--out", graph_.out_dir, "--run-job"}, options);
    EXPECT_TRUE(summary.ok()) << summary.status().ToString();
    return summary.ok() ? *summary : RunSummary{};
  }
  TempDir dir_;
  JobGraph graph_;
  RunContext context_;
};

TEST_F(LocalRun, RunsOnceThenNothingThenWhatAChangeReaches) {
  RunSummary first = Run();
  auto o = Outcomes(first);
  EXPECT_EQ(o["face"], "done");
  EXPECT_EQ(o["rig"], "done");
  EXPECT_EQ(o["bad"], "failed");
  EXPECT_EQ(o["after_bad"], "blocked");
  EXPECT_EQ(first.done, 2);
  EXPECT_FALSE(first.ok());
  EXPECT_TRUE(std::filesystem::exists(dir_.Join("out/rig/rig.glb")));
  // The failure names the command, its exit code, its message and the log.
  const JobReport& bad = first.jobs[2];
  EXPECT_THAT(bad.reason, HasSubstr("facedyn sim face exited with"));
  EXPECT_THAT(bad.reason, HasSubstr("no-such-flag"));
  EXPECT_THAT(bad.reason, HasSubstr("process/logs/bad.log"));
  EXPECT_THAT(first.jobs[3].reason, HasSubstr("needs bad (failed)"));

  // Nothing changed: the done jobs are up to date, the failed one is tried again.
  o = Outcomes(Run());
  EXPECT_EQ(o["face"], "up to date");
  EXPECT_EQ(o["rig"], "up to date");
  EXPECT_EQ(o["bad"], "failed");

  // New input bytes: `face` re-runs; its output is byte-identical, so `rig` stays up to date.
  WriteBytes(dir_.Join("input.txt"), "two");
  o = Outcomes(Run());
  EXPECT_EQ(o["face"], "done");
  EXPECT_EQ(o["rig"], "up to date");

  // An output deleted by hand is noticed.
  std::filesystem::remove_all(dir_.Join("out/rig"));
  o = Outcomes(Run(1));
  EXPECT_EQ(o["face"], "up to date");
  EXPECT_EQ(o["rig"], "done");

  // Another facedyn version would re-run everything.
  std::string why;
  EXPECT_TRUE(JobUpToDate(graph_, graph_.jobs[0], context_, &why)) << why;
  RunContext other = context_;
  other.tool_version += " modified";
  EXPECT_FALSE(JobUpToDate(graph_, graph_.jobs[0], other, &why));
  EXPECT_THAT(why, HasSubstr("facedyn version"));
}

TEST_F(LocalRun, StatusNamesEachState) {
  Run();
  WriteBytes(dir_.Join("input.txt"), "changed");
  const auto status = ReadProcessStatus(graph_.out_dir, context_);
  ASSERT_TRUE(status.ok()) << status.status().ToString();
  std::map<std::string, JobStatus> by_id;
  for (const JobStatus& j : status->jobs) by_id[j.id] = j;
  EXPECT_EQ(by_id["face"].state, "stale");
  EXPECT_THAT(by_id["face"].detail, HasSubstr("changed"));
  EXPECT_EQ(by_id["rig"].state, "done");
  EXPECT_EQ(by_id["bad"].state, "failed");
  EXPECT_THAT(by_id["bad"].detail, HasSubstr("no-such-flag"));
  EXPECT_EQ(by_id["after_bad"].state, "not started");
  EXPECT_FALSE(status->slurm);
  EXPECT_THAT(status->ToText(), HasSubstr("1 failed"));
  EXPECT_EQ(status->ToJson()["counts"]["done"].get<int>(), 1);
}

TEST_F(LocalRun, AWorkerRefusesAJobWhoseDependencyIsNotDone) {
  // What a Slurm task does if it ever started early: refuse, naming the dependency.
  const JobResult r = RunJob(graph_, graph_.jobs[1], context_, false);
  EXPECT_EQ(r.outcome, JobOutcome::kFailed);
  EXPECT_THAT(r.reason, HasSubstr("needs face"));
  EXPECT_FALSE(std::filesystem::exists(dir_.Join("out/rig")));
}

}  // namespace
}  // namespace facedyn::process
