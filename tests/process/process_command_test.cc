// `facedyn process` end to end on a simulated 6-take session (filmed by the simulated cameras,
// reconstructed from the images): run locally, killed mid-way and rerun (only what was missing
// runs), a second rerun does nothing and says so; then the same session on a private Slurm
// cluster (tests/support/slurm_cluster.h) gives byte-identical outputs. The Slurm case is
// skipped, not passed, where the cluster cannot start (not root, Slurm not installed).

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "core/json_io.h"
#include "tests/support/slurm_cluster.h"
#include "tests/support/test_support.h"

namespace facedyn {
namespace {

namespace fs = std::filesystem;
using ::facedyn::testing::ChildProcess;
using ::facedyn::testing::FacedynExecutable;
using ::facedyn::testing::RunCommand;
using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

// 8 cameras at 640x512 (markers ~4.5 px), no drive. One 0.25 s take trains the removal (its
// windows need 22 held frames); five 0.0625 s takes are only processed.
std::string CaptureYaml(double seconds, int seed, const std::string& expression) {
  return fmt::format(R"(name: process-test
description: 8 simulated cameras for the process test
fps: 128
duration_s: {}
exposure_us: 2000
pixel_format: mono8
trigger: {{kind: virtual, pace: 0}}
recorder: {{queue_frames: 16, backpressure: block, block_timeout_s: 10}}
sync: {{timestamp_tolerance_us: 100}}
cameras:
  backend: sim
  ring: {{count: 8, width_px: 640, height_px: 512, focal_px: 1800, distance_mm: 800,
         span_deg: 150, elevation_deg: 10, target_mm: [0, -5, 60], k1: -0.08, k2: 0.02}}
sim:
  face: procedural
  expression: {}
  motion: platform
  platform_hz: 11
  amplitude_mm: 2
  lead_in_s: 0.5
  seed: {}
)",
                     seconds, expression, seed);
}

constexpr char kProcessYaml[] = R"(reconstruct: {marker_diameter_px: 4.5}
removal: {train_takes: train, epochs: 3}
synthesis: {epochs: 2}
solve: {epochs: 2}
export: {formats: [pc2]}
)";

constexpr int kJobs = 6 * 4 + 3;  // reconstruct, remove, solve, export per take; F, H, solver

Json ParseJsonOutput(const std::string& output) {
  const size_t start = output.find('{');
  if (start == std::string::npos) return Json();
  try {
    return Json::parse(output.substr(start));
  } catch (const Json::exception&) {
    return Json();
  }
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

class ProcessCommand : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    const std::string facedyn = FacedynExecutable();
    struct TakeSpec {
      std::string name;
      double seconds;
      int seed;
      std::string expression;
    };
    const TakeSpec takes[] = {{"train", 0.25, 1, "smile"},   {"p1", 0.0625, 2, "jaw_open"},
                              {"p2", 0.0625, 3, "smile"},    {"p3", 0.0625, 4, "neutral"},
                              {"p4", 0.0625, 5, "jaw_open"}, {"p5", 0.0625, 6, "smile"}};
    for (const TakeSpec& t : takes) {
      const std::string yaml = dir_->Join("capture_" + t.name + ".yaml");
      WriteBytes(yaml, CaptureYaml(t.seconds, t.seed, t.expression));
      std::string out;
      ASSERT_EQ(RunCommand(facedyn + " --quiet capture --config " + yaml + " --session " +
                               dir_->Join("session") + " --take " + t.name,
                           &out),
                0)
          << out;
    }
    WriteBytes(dir_->Join("process.yaml"), kProcessYaml);
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static std::string Args(const std::string& out) {
    return " --session " + dir_->Join("session") + " --config " + dir_->Join("process.yaml") +
           " --out " + out;
  }
  static TempDir* dir_;
};
TempDir* ProcessCommand::dir_ = nullptr;

TEST_F(ProcessCommand, LocalRunKilledMidwayResumesOnlyWhatIsMissing) {
  const std::string out = dir_->Join("local");
  std::vector<std::string> args = {FacedynExecutable(),
                                   "process",
                                   "--session",
                                   dir_->Join("session"),
                                   "--config",
                                   dir_->Join("process.yaml"),
                                   "--out",
                                   out,
                                   "--jobs",
                                   "2"};
  {
    ChildProcess run(args, dir_->Join("killed.log"));
    // Kill it once two takes are reconstructed, while others run.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(400);
    int done = 0;
    while (std::chrono::steady_clock::now() < deadline && run.running()) {
      done = 0;
      for (const char* take : {"train", "p1", "p2", "p3", "p4", "p5"}) {
        const std::string state = ReadAll(out + "/process/state/reconstruct--" + take + ".json");
        done += state.find("\"status\": \"done\"") != std::string::npos;
      }
      if (done >= 2) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
    ASSERT_GE(done, 2) << ReadAll(dir_->Join("killed.log"));
    run.Signal(SIGKILL);
    EXPECT_EQ(run.Wait(30), 128 + SIGKILL);
  }
  // The workers died with it (PR_SET_PDEATHSIG): give them a moment, then the status says what
  // was cut.
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  std::string text;
  ASSERT_EQ(RunCommand(FacedynExecutable() + " process --status " + out + " --json", &text), 0)
      << text;
  Json status = ParseJsonOutput(text);
  ASSERT_TRUE(status.is_object()) << text;
  const int done_before = status["counts"]["done"].get<int>();
  EXPECT_GE(done_before, 2);
  EXPECT_LT(done_before, kJobs);
  EXPECT_EQ(status["counts"]["running"].get<int>(), 0) << text;

  // Rerun: what was done is up to date, everything else runs, nothing fails.
  ASSERT_EQ(
      RunCommand(FacedynExecutable() + " --quiet process" + Args(out) + " --jobs 2 --json", &text),
      0)
      << text;
  Json summary = ParseJsonOutput(text);
  ASSERT_TRUE(summary.is_object()) << text;
  EXPECT_EQ(summary["up_to_date"].get<int>(), done_before);
  EXPECT_EQ(summary["done"].get<int>(), kJobs - done_before);
  EXPECT_EQ(summary["failed"].get<int>(), 0);
  for (const char* take : {"train", "p1", "p2", "p3", "p4", "p5"}) {
    const std::string t = out + "/takes/" + take;
    EXPECT_TRUE(fs::exists(t + "/reconstructed/take.json")) << take;
    EXPECT_TRUE(fs::exists(t + "/quasistatic/take.json")) << take;
    EXPECT_TRUE(fs::exists(t + "/weights.csv")) << take;
    EXPECT_TRUE(fs::exists(t + "/export-pc2")) << take;
  }
  EXPECT_TRUE(fs::exists(out + "/models/F.pt"));
  EXPECT_TRUE(fs::exists(out + "/models/H.pt"));

  // A second run does nothing and says so.
  ASSERT_EQ(RunCommand(FacedynExecutable() + " process" + Args(out), &text), 0) << text;
  EXPECT_THAT(text, HasSubstr("nothing to do"));
  ASSERT_EQ(RunCommand(FacedynExecutable() + " process --status " + out + " --json", &text), 0);
  status = ParseJsonOutput(text);
  EXPECT_EQ(status["counts"]["done"].get<int>(), kJobs) << text;
}

// Every output file of the local run and the Slurm run, byte for byte; the reconstruction
// reports (reconstruction.json) carry wall-clock timings and their own output path, so those
// two fields are left out of their comparison.
void ExpectSameOutputs(const std::string& a, const std::string& b) {
  int files = 0;
  for (const char* top : {"takes", "models"}) {
    for (const auto& entry : fs::recursive_directory_iterator(fs::path(a) / top)) {
      if (!entry.is_regular_file()) continue;
      const std::string rel = fs::relative(entry.path(), a).string();
      ASSERT_TRUE(fs::exists(fs::path(b) / rel)) << rel;
      std::string x = ReadAll(entry.path().string());
      std::string y = ReadAll((fs::path(b) / rel).string());
      if (entry.path().filename() == "reconstruction.json") {
        Json jx = Json::parse(x), jy = Json::parse(y);
        for (Json* j : {&jx, &jy}) {
          j->erase("seconds");
          j->erase("out");
        }
        x = jx.dump();
        y = jy.dump();
      }
      EXPECT_TRUE(x == y) << rel << " differs between the local and the Slurm run";
      ++files;
    }
  }
  EXPECT_GT(files, 6 * 8);
}

TEST_F(ProcessCommand, SlurmRunGivesTheLocalRunsOutputs) {
  const std::string why = testing::SlurmUnavailableReason();
  if (!why.empty()) GTEST_SKIP() << why;
  const std::string local = dir_->Join("local");
  if (!fs::exists(local + "/models/F.pt")) {
    std::string text;
    ASSERT_EQ(
        RunCommand(FacedynExecutable() + " --quiet process" + Args(local) + " --jobs 2", &text), 0)
        << text;
  }
  testing::LocalSlurmCluster cluster;
  const std::string started = cluster.Start(dir_->Join("slurm"));
  ASSERT_EQ(started, "");
  const std::string env = cluster.EnvironmentPrefix();
  const std::string out = dir_->Join("cluster");
  std::string text;
  ASSERT_EQ(
      RunCommand(env + FacedynExecutable() + " process" + Args(out) + " --slurm --json", &text), 0)
      << text;
  const Json submission = ParseJsonOutput(text);
  ASSERT_TRUE(submission.is_object()) << text;
  EXPECT_EQ(submission["steps"].size(), 7u) << text;

  // Follow it with --status until every job is done (or one fails).
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(600);
  Json status;
  bool saw_queued_or_running = false;
  while (std::chrono::steady_clock::now() < deadline) {
    ASSERT_EQ(RunCommand(env + FacedynExecutable() + " process --status " + out + " --json", &text),
              0)
        << text;
    status = ParseJsonOutput(text);
    ASSERT_TRUE(status.is_object()) << text;
    EXPECT_EQ(status["slurm_problem"].get<std::string>(), "");
    saw_queued_or_running = saw_queued_or_running || status["counts"]["queued"].get<int>() > 0 ||
                            status["counts"]["running"].get<int>() > 0;
    if (status["counts"]["done"].get<int>() == kJobs) break;
    if (status["counts"]["failed"].get<int>() > 0) break;
    std::this_thread::sleep_for(std::chrono::seconds(2));
  }
  ASSERT_EQ(status["counts"]["done"].get<int>(), kJobs)
      << status.dump(2) << "\nslurmctld log:\n"
      << ReadAll(cluster.log_dir() + "/slurmctld.log").substr(0, 4000);
  EXPECT_TRUE(saw_queued_or_running);
  // Each task's Slurm log is in the output folder.
  EXPECT_TRUE(fs::exists(out + "/process/logs/slurm-reconstruct-0.log"));
  EXPECT_TRUE(fs::exists(out + "/process/logs/slurm-export-5.log"));
  ExpectSameOutputs(local, out);

  // Nothing left to do: nothing is submitted.
  ASSERT_EQ(RunCommand(env + FacedynExecutable() + " process" + Args(out) + " --slurm", &text), 0)
      << text;
  EXPECT_THAT(text, HasSubstr("nothing to do"));
}

TEST_F(ProcessCommand, BadInputIsNamed) {
  std::string text;
  EXPECT_NE(RunCommand(FacedynExecutable() + " process --session " + dir_->Join("nothing") +
                           " --out " + dir_->Join("o"),
                       &text),
            0);
  EXPECT_THAT(text, HasSubstr("nothing"));
  WriteBytes(dir_->Join("bad.yaml"), "removal: {targets: exact}\n");
  EXPECT_NE(RunCommand(FacedynExecutable() + " process --session " + dir_->Join("session") +
                           " --config " + dir_->Join("bad.yaml") + " --out " + dir_->Join("o"),
                       &text),
            0);
  EXPECT_THAT(text, HasSubstr("removal.targets"));
  EXPECT_NE(RunCommand(FacedynExecutable() + " process --status " + dir_->Join("nowhere"), &text),
            0);
  EXPECT_THAT(text, HasSubstr("plan.json"));
  EXPECT_NE(RunCommand(FacedynExecutable() + " process --out " + dir_->Join("local") +
                           " --run-step remove --index 99",
                       &text),
            0);
}

}  // namespace
}  // namespace facedyn
