// `facedyn sweep` and `facedyn rig ... --config` as a user runs them: a separate facedyn
// process against the simulated drive hosted by this test, killed with SIGINT and SIGKILL.
#include <fcntl.h>
#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "core/config_node.h"
#include "rig/rig_config.h"
#include "rig/session_log.h"
#include "sim/drive_sim.h"
#include "tests/rig/rig_test_util.h"

namespace facedyn {
namespace {

using ::testing::HasSubstr;
using Clock = std::chrono::steady_clock;

using Child = testing::ChildProcess;

struct Stage {
  testing::TempDir dir;
  std::unique_ptr<sim::DriveSim> sim;
  std::string rig_path;
  std::string session;
  std::string log_path;
};

// The simulated drive with sim-tcp.yaml's sim: physics on a free port, and a copy of
// sim-tcp.yaml pointing at it.
std::unique_ptr<Stage> StartStage() {
  auto stage = std::make_unique<Stage>();
  const std::string source = testing::RigConfigPath("sim-tcp");
  auto rig = rig::LoadRigConfig(source);
  EXPECT_TRUE(rig.ok()) << rig.status().ToString();
  auto root = ConfigNode::ReadFile(source);
  EXPECT_TRUE(root.ok());
  if (!rig.ok() || !root.ok()) return nullptr;
  sim::DriveSimOptions options;
  auto section = root->Child("sim");
  EXPECT_TRUE(section.ok());
  EXPECT_TRUE(sim::ParseDriveModelOptions(*section, &options.model).ok());
  auto sim = sim::DriveSim::Start(rig->profile, options);
  EXPECT_TRUE(sim.ok()) << sim.status().ToString();
  if (!sim.ok()) return nullptr;
  stage->sim = std::move(sim).value();
  std::string text = testing::ReadBytes(source);
  text.replace(text.find("port: 5020"), 10, fmt::format("port: {}", stage->sim->port()));
  text.replace(text.find("../drives/sim.yaml"), 18, testing::DriveProfilePath("sim"));
  stage->rig_path = stage->dir.Join("rig.yaml");
  testing::WriteBytes(stage->rig_path, text);
  stage->session = stage->dir.Join("session");
  stage->log_path = stage->dir.Join("session/rig_log.jsonl");
  return stage;
}

std::string WriteSweep(const Stage& stage, const std::string& steps) {
  const std::string path = stage.dir.Join("sweep.yaml");
  testing::WriteBytes(
      path, fmt::format("name: cli-test\nrig: {}\ndefaults: {{settle_timeout_s: 20}}\nsteps:\n{}",
                        stage.rig_path, steps));
  return path;
}

int CountEvents(const std::string& log_path, const std::string& event) {
  auto records = rig::ReadSessionLog(log_path);
  if (!records.ok()) return 0;
  int count = 0;
  for (const Json& r : *records) count += r["event"] == event;
  return count;
}

bool WaitForEvents(const std::string& log_path, const std::string& event, int count,
                   double timeout_s) {
  const auto deadline = Clock::now() + std::chrono::duration<double>(timeout_s);
  while (Clock::now() < deadline) {
    if (CountEvents(log_path, event) >= count) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return false;
}

int RunFacedyn(const std::string& args, std::string* output) {
  return testing::RunCommand(testing::FacedynExecutable() + " " + args, output);
}

TEST(SweepCommand, KillDashNineThenResumeCompletesWithNothingRepeatedOrLost) {
  auto stage = StartStage();
  ASSERT_NE(stage, nullptr);
  const std::string sweep = WriteSweep(*stage,
                                       "  - {hz: 7, hold_s: 0.6}\n  - {hz: 8, hold_s: 0.6}\n  - "
                                       "{hz: 7.5, hold_s: 0.6}\n  - {hz: 8.5, hold_s: 0.6}\n");
  {
    Child child(
        {testing::FacedynExecutable(), "sweep", "--config", sweep, "--session", stage->session},
        stage->dir.Join("first.out"));
    ASSERT_TRUE(WaitForEvents(stage->log_path, "step_done", 2, 40.0))
        << testing::ReadBytes(stage->dir.Join("first.out"));
    child.Signal(SIGKILL);
    EXPECT_EQ(child.Wait(5.0), 128 + SIGKILL);
  }
  // Nobody stopped the drive: its own comm watchdog (armed by the sweep, 1 s) does.
  EXPECT_TRUE(stage->sim->state().run_commanded || stage->sim->state().watchdog_fired);
  const auto killed = Clock::now();
  while (!stage->sim->state().watchdog_fired && Clock::now() - killed < std::chrono::seconds(3)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(stage->sim->state().watchdog_fired);
  EXPECT_EQ(stage->sim->state().fault_code, 10);
  EXPECT_EQ(stage->sim->state().output_hz, 0.0);

  // The trip must be acknowledged explicitly before the sweep may move the platform again.
  std::string output;
  const std::string resume =
      fmt::format("sweep --config {} --session {} --resume", sweep, stage->session);
  EXPECT_EQ(RunFacedyn(resume, &output), 1) << output;
  EXPECT_THAT(output, HasSubstr("comm watchdog expired"));
  EXPECT_THAT(output, HasSubstr("facedyn rig reset"));
  ASSERT_EQ(RunFacedyn("rig reset --config " + stage->rig_path, &output), 0) << output;
  ASSERT_EQ(RunFacedyn(resume + " --json", &output), 0) << output;
  const auto json = nlohmann::json::parse(output.substr(output.find('{')));
  EXPECT_EQ(json["skipped_on_resume"], 2);
  ASSERT_EQ(json["steps"].size(), 4u);

  std::map<int, int> done;
  auto records = rig::ReadSessionLog(stage->log_path);
  ASSERT_TRUE(records.ok()) << records.status().ToString();
  for (const Json& r : *records) {
    if (r["event"] == "step_done") ++done[r["instance"].get<int>()];
  }
  EXPECT_EQ(done, (std::map<int, int>{{0, 1}, {1, 1}, {2, 1}, {3, 1}}));
  EXPECT_EQ(CountEvents(stage->log_path, "sweep_start"), 1);
  EXPECT_EQ(CountEvents(stage->log_path, "sweep_done"), 1);
  EXPECT_EQ(stage->sim->state().output_hz, 0.0);
  auto summary = ConfigNode::ReadFile(stage->dir.Join("session/sweep_summary.json"));
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  EXPECT_EQ(summary->ToJson()["steps"].size(), 4u);
}

TEST(SweepCommand, SigintDuringAHoldRampsToStop) {
  auto stage = StartStage();
  ASSERT_NE(stage, nullptr);
  const std::string sweep =
      WriteSweep(*stage, "  - {hz: 9, hold_s: 30}\n  - {hz: 10, hold_s: 30}\n");
  Child child(
      {testing::FacedynExecutable(), "sweep", "--config", sweep, "--session", stage->session},
      stage->dir.Join("out"));
  ASSERT_TRUE(WaitForEvents(stage->log_path, "settled", 1, 30.0))
      << testing::ReadBytes(stage->dir.Join("out"));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ASSERT_GT(stage->sim->state().output_hz, 8.0);
  child.Signal(SIGINT);
  const int code = child.Wait(15.0);
  const std::string output = testing::ReadBytes(stage->dir.Join("out"));
  EXPECT_EQ(code, 1) << output;
  EXPECT_THAT(output, HasSubstr("stop requested"));
  // Stopped by ramping, not left to the watchdog: the run command was withdrawn and the
  // output reached 0 before facedyn exited.
  EXPECT_FALSE(stage->sim->state().run_commanded);
  EXPECT_FALSE(stage->sim->state().watchdog_fired);
  EXPECT_EQ(stage->sim->state().output_hz, 0.0);
  auto records = rig::ReadSessionLog(stage->log_path);
  ASSERT_TRUE(records.ok());
  bool stop_logged = false;
  double last_output_hz = -1.0;
  for (const Json& r : *records) {
    if (r["event"] == "command" && r["command"] == "stop") {
      stop_logged = r["reason"].get<std::string>().find("stop requested") != std::string::npos;
    }
    if (stop_logged && r["event"] == "reply" && r.contains("output_hz")) {
      if (last_output_hz >= 0.0) {
        EXPECT_LE(r["output_hz"].get<double>(), last_output_hz + 1e-9);
      }
      last_output_hz = r["output_hz"].get<double>();
    }
  }
  EXPECT_TRUE(stop_logged);
  EXPECT_EQ(last_output_hz, 0.0);
  EXPECT_EQ(CountEvents(stage->log_path, "step_done"), 0);
  EXPECT_EQ(CountEvents(stage->log_path, "sweep_aborted"), 1);
}

TEST(RigCommand, SetStatusStopWithConfig) {
  auto stage = StartStage();
  ASSERT_NE(stage, nullptr);
  std::string output;
  EXPECT_EQ(RunFacedyn("rig set --config " + stage->rig_path + " --hz 12", &output), 1);
  EXPECT_THAT(output, HasSubstr("hz: 12 Hz is above limits.absolute_max_hz 11.6 Hz"));
  EXPECT_EQ(stage->sim->state().run_commanded, false);
  ASSERT_EQ(
      RunFacedyn("rig set --config " + stage->rig_path + " --hz 8.5 --seconds 0.5 --json", &output),
      0)
      << output;
  const auto json = nlohmann::json::parse(output.substr(output.find('{')));
  EXPECT_NEAR(json["measured_hz"].get<double>(), 8.5, 0.05);
  EXPECT_NEAR(json["hold"]["mean_measured_hz"].get<double>(), 8.5, 0.05);
  EXPECT_EQ(json["state"], "stopped");
  EXPECT_GT(json["exposure"]["vibrating_s"].get<double>(), 0.5);
  ASSERT_EQ(RunFacedyn("rig status --config " + stage->rig_path + " --json", &output), 0) << output;
  EXPECT_THAT(output, HasSubstr("\"running\": false"));
  // Both connection styles at once is a usage error (exit 2).
  EXPECT_EQ(RunFacedyn("rig status --config " + stage->rig_path + " --profile x.yaml", &output), 2);
  // A bad config names the field.
  std::string text = testing::ReadBytes(stage->rig_path);
  text.replace(text.find("max_ramp_hz_per_s: 2.0"), 22, "max_ramp_hz_per_s: -1");
  testing::WriteBytes(stage->dir.Join("bad.yaml"), text);
  EXPECT_EQ(RunFacedyn("rig status --config " + stage->dir.Join("bad.yaml"), &output), 1);
  EXPECT_THAT(output, HasSubstr("limits.max_ramp_hz_per_s"));
}

TEST(RigServeSim, ServesTheRigConfigOnAFreePortUntilSigint) {
  testing::TempDir dir;
  Child server({testing::FacedynExecutable(), "rig", "serve-sim", "--config",
                testing::RigConfigPath("sim-tcp"), "--tcp", "127.0.0.1:0", "--seconds", "30"},
               dir.Join("serve.out"));
  int port = 0;
  const auto deadline = Clock::now() + std::chrono::seconds(10);
  while (port == 0 && Clock::now() < deadline) {
    const std::string out = testing::ReadBytes(dir.Join("serve.out"));
    const size_t at = out.find("listening 127.0.0.1:");
    if (at != std::string::npos) port = std::atoi(out.c_str() + at + 20);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_GT(port, 0) << testing::ReadBytes(dir.Join("serve.out"));
  std::string output;
  ASSERT_EQ(RunFacedyn(fmt::format("rig status --profile {} --tcp 127.0.0.1:{} --json",
                                   testing::DriveProfilePath("sim"), port),
                       &output),
            0)
      << output;
  EXPECT_THAT(output, HasSubstr("\"running\": false"));
  server.Signal(SIGINT);
  EXPECT_EQ(server.Wait(5.0), 0);
}

}  // namespace
}  // namespace facedyn
