// Sweep scripts (parsing, validation against the rig) and the runner against the in-process
// simulated drive, including resume after a failure mid-sweep.
#include "rig/sweep.h"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <map>
#include <string>
#include <thread>

#include "rig/session_log.h"
#include "sim/drive_sim.h"
#include "tests/rig/rig_test_util.h"

namespace facedyn::rig {
namespace {

using ::testing::HasSubstr;
using Clock = std::chrono::steady_clock;

StatusOr<SweepScript> ParseText(const std::string& text) {
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode root, ConfigNode::Parse(text, "sweep.yaml"));
  return ParseSweepScript(root, "/base", 42);
}

RigConfig SimRig() {
  auto rig = LoadRigConfig(testing::RigConfigPath("sim-tcp"));
  EXPECT_TRUE(rig.ok()) << rig.status().ToString();
  return rig.ok() ? *rig : RigConfig();
}

TEST(LoadSweepScript, ShippedSweepsLoadAndFitTheSimRig) {
  const RigConfig rig = SimRig();
  auto paper = LoadSweepScript(testing::SweepConfigPath("paper-protocol"));
  ASSERT_TRUE(paper.ok()) << paper.status().ToString();
  EXPECT_EQ(paper->InstanceCount(), 66);  // 11 expressions x 6 frequencies
  std::map<double, int> per_hz;
  for (const SweepStep& s : paper->steps) ++per_hz[s.hz];
  EXPECT_EQ(per_hz,
            (std::map<double, int>{{6, 11}, {7, 11}, {8, 11}, {9, 11}, {10, 11}, {11, 11}}));
  EXPECT_EQ(paper->steps[0].prompt, "neutral");
  EXPECT_EQ(paper->steps[6].prompt, "smile");  // prompt_major: all frequencies per expression
  EXPECT_TRUE(paper->CheckAgainst(rig).ok());
  EXPECT_THAT(paper->rig_path, ::testing::EndsWith("config/sweeps/../rigs/sim-tcp.yaml"));
  auto demo = LoadSweepScript(testing::SweepConfigPath("demo"));
  ASSERT_TRUE(demo.ok()) << demo.status().ToString();
  EXPECT_TRUE(demo->CheckAgainst(rig).ok());
}

TEST(ParseSweepScript, DefaultsRepeatsAndGridOrder) {
  auto script = ParseText(
      "name: t\ndefaults: {hold_s: 3, settle_s: 1}\n"
      "steps:\n  - {hz: 7, prompt: a, repeats: 2}\n  - {hz: 8, hold_s: 5}\n"
      "grid: {frequencies_hz: [9, 10], prompts: [x, y], order: frequency_major}\n");
  ASSERT_TRUE(script.ok()) << script.status().ToString();
  ASSERT_EQ(script->steps.size(), 6u);
  EXPECT_EQ(script->InstanceCount(), 7);
  EXPECT_EQ(script->steps[0].hold_s, 3.0);
  EXPECT_EQ(script->steps[1].hold_s, 5.0);
  EXPECT_EQ(script->steps[1].settle_s, 1.0);
  EXPECT_EQ(script->steps[2].hz, 9.0);
  EXPECT_EQ(script->steps[2].prompt, "x");
  EXPECT_EQ(script->steps[3].prompt, "y");
  EXPECT_EQ(script->steps[4].hz, 10.0);
  EXPECT_NEAR(script->MinimumDurationS(), 2 * 4 + 6 + 4 * 4, 1e-12);
}

TEST(ParseSweepScript, MalformedScriptsAreRefusedNamingTheField) {
  struct Case {
    const char* text;
    const char* expected;
  };
  const Case cases[] = {
      {"name: t\nsteps:\n  - {hz: fast}\n", "steps[0].hz"},
      {"name: t\nsteps:\n  - {prompt: smile}\n", "steps[0].hz': required field is missing"},
      {"name: t\nsteps:\n  - {hz: 8, hold_s: 0}\n", "steps[0].hold_s"},
      {"name: t\nsteps:\n  - {hz: 8, repeats: 0}\n", "steps[0].repeats"},
      {"name: t\nsteps:\n  - {hz: 8, hold: 3}\n", "steps[0].hold': unknown field"},
      {"name: t\nsteps: []\n", "non-empty list"},
      {"name: t\n", "needs 'steps'"},
      {"steps:\n  - {hz: 8}\n", "'name': required field is missing"},
      {"name: t\ngrid: {frequencies_hz: [6, x]}\n", "grid.frequencies_hz"},
      {"name: t\ngrid: {frequencies_hz: [6], order: random}\n", "grid.order"},
      {"name: t\nsteps:\n  - {hz: -3}\n", "steps[0].hz"},
      {"name: t\nspeed: 3\nsteps:\n  - {hz: 8}\n", "'speed': unknown field"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.text);
    auto script = ParseText(c.text);
    ASSERT_FALSE(script.ok());
    EXPECT_THAT(script.status().message(), HasSubstr(c.expected));
    EXPECT_THAT(script.status().message(), HasSubstr("sweep.yaml:"));
  }
}

// "frequencies_hz: [8, 8, ...]" with `count` entries and "prompts: [p0, p1, ...]" likewise.
std::string GridScript(int frequencies, int prompts, int repeats) {
  std::string text =
      "name: big\ngrid:\n  repeats: " + std::to_string(repeats) + "\n  frequencies_hz: [";
  for (int i = 0; i < frequencies; ++i) text += i ? ", 8" : "8";
  text += "]\n  prompts: [";
  for (int i = 0; i < prompts; ++i) text += (i ? ", p" : "p") + std::to_string(i);
  return text + "]\n";
}

// A 10^4 x 10^4 grid is refused from its list sizes, before a single step is built. Before,
// the 10^8 steps were expanded first (gigabytes: run under `ulimit -v 4000000` it dies of
// bad_alloc) and only then counted.
TEST(ParseSweepScript, HugeGridIsRefusedBeforeExpansion) {
  auto script = ParseText(GridScript(10000, 10000, 1));
  ASSERT_FALSE(script.ok());
  EXPECT_THAT(script.status().message(),
              HasSubstr("sweep.yaml:3: field 'grid': 10000 frequencies_hz x 10000 prompts x 1 "
                        "repeats is more than 100000 step instances; a sweep may have at most "
                        "100000"));
}

// 3000 x 1000 cells x 1000 repeats is 3e9 instances: summed in int it wrapped to -1294967296,
// which is below the cap, so `sweep --check` printed a negative step count and passed.
TEST(ParseSweepScript, InstanceCountBeyondIntIsRefusedNamingTheGrid) {
  auto script = ParseText(GridScript(3000, 1000, 1000));
  ASSERT_FALSE(script.ok()) << "parsed with " << script->InstanceCount() << " instances";
  EXPECT_THAT(script.status().message(),
              HasSubstr("field 'grid': 3000 frequencies_hz x 1000 prompts x 1000 repeats"));
}

// Repeats alone can exceed the cap: the message names the repeats that crossed it.
TEST(ParseSweepScript, RepeatsBeyondTheCapAreRefusedNamingTheField) {
  // 100 cells x 1000 repeats = 100000 (the cap, allowed) ...
  auto at_cap = ParseText(GridScript(10, 10, 1000));
  ASSERT_TRUE(at_cap.ok()) << at_cap.status().ToString();
  EXPECT_EQ(at_cap->InstanceCount(), 100000);
  // ... one more step of 1 repeat in front of it is not.
  std::string one_more = GridScript(10, 10, 1000);
  one_more.insert(one_more.find("grid:"), "steps:\n  - {hz: 8}\n");
  auto over = ParseText(one_more);
  ASSERT_FALSE(over.ok());
  EXPECT_THAT(over.status().message(),
              HasSubstr("field 'grid': 10 frequencies_hz x 10 prompts x 1000 repeats is 100000 "
                        "step instances after the 1 of 'steps'"));
  // Explicit steps: the step whose repeats cross the cap is named.
  std::string steps = "name: t\nsteps:\n";
  for (int i = 0; i < 101; ++i) steps += "  - {hz: 8, repeats: 1000}\n";
  auto many = ParseText(steps);
  ASSERT_FALSE(many.ok());
  EXPECT_THAT(many.status().message(),
              HasSubstr("sweep.yaml:103: field 'steps[100].repeats': 1000 repeats bring the sweep "
                        "to 101000 step instances, more than the 100000"));
  // A repeats value beyond int is out of range, not "not an integer".
  auto wide = ParseText("name: t\nsteps:\n  - {hz: 8, repeats: 3000000000}\n");
  ASSERT_FALSE(wide.ok());
  EXPECT_THAT(wide.status().message(),
              HasSubstr("field 'steps[0].repeats': 3000000000 is outside 1..1000"));
}

// CheckAgainst applies the cap too, so a script assembled in code cannot bypass it.
TEST(SweepScript, CheckAgainstRefusesTooManyInstances) {
  auto script = ParseText("name: t\nsteps:\n  - {hz: 8, repeats: 1000}\n");
  ASSERT_TRUE(script.ok());
  script->steps.resize(101, script->steps[0]);
  const Status check = script->CheckAgainst(SimRig());
  ASSERT_FALSE(check.ok());
  EXPECT_THAT(check.message(), HasSubstr("101000 step instances is more than the 100000"));
}

TEST(SweepScript, OutOfRangeFrequencyIsRefusedBeforeAnythingMoves) {
  auto script = ParseText("name: t\nsteps:\n  - {hz: 8}\n  - {hz: 11.5}\n");
  ASSERT_TRUE(script.ok());
  const Status check = script->CheckAgainst(SimRig());
  ASSERT_FALSE(check.ok());
  EXPECT_THAT(check.message(), HasSubstr("sweep.yaml:4: field 'steps[1].hz': 11.5 Hz is outside"));
  // RunSweep refuses it too, without connecting (no drive is listening on this port).
  RigConfig rig = SimRig();
  rig.transport.port = 1;
  testing::TempDir dir;
  SweepOptions options;
  options.session_dir = dir.Join("session");
  auto result = RunSweep(*script, rig, options);
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result.status().message(), HasSubstr("steps[1].hz"));
}

struct SimRigBench {
  RigConfig rig;
  std::unique_ptr<sim::DriveSim> sim;
};

SimRigBench StartSim() {
  SimRigBench bench;
  bench.rig = SimRig();
  auto sim = sim::DriveSim::Start(bench.rig.profile, sim::DriveSimOptions());
  EXPECT_TRUE(sim.ok()) << sim.status().ToString();
  if (sim.ok()) {
    bench.sim = std::move(sim).value();
    bench.rig.transport.port = bench.sim->port();
  }
  return bench;
}

std::map<int, int> StepDoneCounts(const std::string& log_path) {
  std::map<int, int> counts;
  auto records = ReadSessionLog(log_path);
  EXPECT_TRUE(records.ok()) << records.status().ToString();
  if (!records.ok()) return counts;
  for (const Json& r : *records) {
    if (r["event"] == "step_done") ++counts[r["instance"].get<int>()];
  }
  return counts;
}

TEST(RunSweep, RunsEveryStepCallsHooksAndResumesAfterAFailure) {
  SimRigBench bench = StartSim();
  ASSERT_NE(bench.sim, nullptr);
  auto script = ParseText(
      "name: t\ndefaults: {hold_s: 0.4, settle_timeout_s: 15}\n"
      "steps:\n  - {hz: 7, prompt: neutral}\n  - {hz: 7.5, prompt: smile, repeats: 2}\n  - {hz: 8, "
      "prompt: pucker}\n");
  ASSERT_TRUE(script.ok());
  testing::TempDir dir;
  SweepOptions options;
  options.session_dir = dir.Join("session");
  std::vector<int> started;
  options.hooks.on_hold_start = [&](const SweepStepInfo& info) {
    started.push_back(info.instance);
    EXPECT_EQ(info.instance_count, 4);
    // The hook runs with the platform settled at the step's frequency (ground truth).
    EXPECT_NEAR(bench.sim->state().platform_hz, info.spec.hz, 0.06);
    if (info.instance == 2) return UnavailableError("camera 3 did not answer");
    return Status::Ok();
  };
  auto first = RunSweep(*script, bench.rig, options);
  ASSERT_FALSE(first.ok());
  EXPECT_THAT(first.status().message(), HasSubstr("camera 3 did not answer"));
  EXPECT_EQ(started, (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(bench.sim->state().output_hz, 0.0);  // a failed hook ramps the platform to a stop
  EXPECT_EQ(StepDoneCounts(dir.Join("session/rig_log.jsonl")),
            (std::map<int, int>{{0, 1}, {1, 1}}));

  // Starting again without --resume would overwrite the journal: refused.
  auto again = RunSweep(*script, bench.rig, options);
  ASSERT_FALSE(again.ok());
  EXPECT_THAT(again.status().message(), HasSubstr("--resume"));

  options.resume = true;
  started.clear();
  options.hooks.on_hold_start = [&](const SweepStepInfo& info) {
    started.push_back(info.instance);
    return Status::Ok();
  };
  auto resumed = RunSweep(*script, bench.rig, options);
  ASSERT_TRUE(resumed.ok()) << resumed.status().ToString();
  EXPECT_EQ(started, (std::vector<int>{2, 3}));
  EXPECT_EQ(resumed->skipped, 2);
  ASSERT_EQ(resumed->steps.size(), 4u);
  for (const SweepStepResult& step : resumed->steps) {
    EXPECT_NEAR(step.hold.mean_measured_hz, step.target_hz, 0.05) << "instance " << step.instance;
  }
  EXPECT_EQ(StepDoneCounts(dir.Join("session/rig_log.jsonl")),
            (std::map<int, int>{{0, 1}, {1, 1}, {2, 1}, {3, 1}}));
  EXPECT_TRUE(resumed->exposure["vibrating_s"].get<double>() > 4 * 0.4);

  // A finished session resumes to nothing.
  started.clear();
  auto done = RunSweep(*script, bench.rig, options);
  ASSERT_TRUE(done.ok()) << done.status().ToString();
  EXPECT_TRUE(started.empty());
  EXPECT_EQ(done->skipped, 4);

  // A different script cannot resume this session.
  auto other = ParseText("name: t\nsteps:\n  - {hz: 9}\n");
  ASSERT_TRUE(other.ok());
  other->text_hash = 43;
  auto mismatch = RunSweep(*other, bench.rig, options);
  ASSERT_FALSE(mismatch.ok());
  EXPECT_THAT(mismatch.status().message(), HasSubstr("different sweep script"));
}

// Issue 18, item 4: a take recorded during a sweep step (during_hold) stands in for capture's:
// it "records" for take_s unless told to abort, calling `inject` once, `inject_after_s` in.
struct FakeTake {
  double take_s = 6.0;
  double inject_after_s = 0.5;
  std::function<void()> inject;
  // Filled in by the take.
  int frames = 0;
  bool aborted = false;
  double ran_s = 0.0;
  Clock::time_point injected_at{};

  std::function<Status(const SweepStepInfo&, const HoldWork&)> Hook() {
    return [this](const SweepStepInfo&, const HoldWork& work) {
      const auto start = Clock::now();
      bool injected = false;
      while (std::chrono::duration<double>(Clock::now() - start).count() < take_s) {
        if (work.abort->load()) {
          aborted = true;
          break;
        }
        if (!injected && inject &&
            std::chrono::duration<double>(Clock::now() - start).count() >= inject_after_s) {
          injected = true;
          injected_at = Clock::now();
          inject();
        }
        ++frames;  // one frame per 1/128 s
        std::this_thread::sleep_for(std::chrono::microseconds(7812));
      }
      ran_s = std::chrono::duration<double>(Clock::now() - start).count();
      return aborted ? AbortedError("take interrupted") : Status::Ok();
    };
  }
};

StatusOr<SweepScript> OneStep(double hz) {
  return ParseText(fmt::format(
      "name: t\ndefaults: {{hold_s: 0.2, settle_timeout_s: 15}}\nsteps:\n  - {{hz: {}}}\n", hz));
}

// The simulated drive trips 0.5 s into a 6 s take: the supervisor, still ticking, sees the trip,
// stops the platform and interrupts the take (before, it ran unsupervised to its end).
TEST(RunSweep, TripDuringATakeStopsThePlatformMidTake) {
  SimRigBench bench = StartSim();
  ASSERT_NE(bench.sim, nullptr);
  auto script = OneStep(8.0);
  ASSERT_TRUE(script.ok());
  testing::TempDir dir;
  SweepOptions options;
  options.session_dir = dir.Join("session");
  FakeTake take;
  take.inject = [&] { bench.sim->ForceFault(2); };
  options.hooks.during_hold = take.Hook();
  auto result = RunSweep(*script, bench.rig, options);
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result.status().message(), HasSubstr("tripped"));
  EXPECT_TRUE(take.aborted);
  EXPECT_LT(take.ran_s, 2.0);  // stopped mid-take, far from its 6 s
  EXPECT_GT(take.frames, 0);
  EXPECT_FALSE(bench.sim->state().run_commanded);
  EXPECT_TRUE(StepDoneCounts(dir.Join("session/rig_log.jsonl")).empty());
}

// The sensor starts reading 30 % high mid-take (10 Hz reads 13 Hz, above absolute_max_hz +
// overspeed_margin_hz): the overspeed check runs during the take and stops the platform.
TEST(RunSweep, OverspeedReadingDuringATakeStopsThePlatformMidTake) {
  SimRigBench bench = StartSim();
  ASSERT_NE(bench.sim, nullptr);
  auto script = OneStep(10.0);
  ASSERT_TRUE(script.ok());
  testing::TempDir dir;
  SweepOptions options;
  options.session_dir = dir.Join("session");
  FakeTake take;
  take.inject = [&] { bench.sim->SetSensorGain(1.3); };
  options.hooks.during_hold = take.Hook();
  auto result = RunSweep(*script, bench.rig, options);
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result.status().message(), HasSubstr("overspeed"));
  EXPECT_TRUE(take.aborted);
  EXPECT_LT(take.ran_s, 2.0);
  EXPECT_EQ(bench.sim->state().output_hz, 0.0);  // ramped to a confirmed standstill
  EXPECT_FALSE(bench.sim->state().run_commanded);
}

// A stop request (what SIGINT sets) 0.5 s into a take reaches the drive — its run command
// dropped, as the simulated drive's own state shows — within the 0.5 s the issue requires.
TEST(RunSweep, StopRequestDuringATakeReachesTheDriveWithinHalfASecond) {
  SimRigBench bench = StartSim();
  ASSERT_NE(bench.sim, nullptr);
  auto script = OneStep(8.0);
  ASSERT_TRUE(script.ok());
  testing::TempDir dir;
  std::atomic<bool> stop{false};
  SweepOptions options;
  options.session_dir = dir.Join("session");
  options.stop_requested = &stop;
  FakeTake take;
  take.inject = [&] { stop = true; };
  options.hooks.during_hold = take.Hook();
  std::atomic<bool> watching{true};
  std::atomic<bool> was_running{false};
  Clock::time_point stopped_at{};
  std::thread watcher([&] {
    while (watching) {
      const bool running = bench.sim->state().run_commanded;
      if (running) was_running = true;
      if (was_running && !running && stopped_at == Clock::time_point{}) stopped_at = Clock::now();
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  });
  auto result = RunSweep(*script, bench.rig, options);
  watching = false;
  watcher.join();
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kAborted);
  EXPECT_THAT(result.status().message(), HasSubstr("stop requested"));
  EXPECT_TRUE(take.aborted);
  EXPECT_GT(take.frames, 0);  // what the take recorded is its own to keep
  ASSERT_NE(take.injected_at, Clock::time_point{});
  ASSERT_NE(stopped_at, Clock::time_point{}) << "the stop never reached the drive";
  EXPECT_LT(std::chrono::duration<double>(stopped_at - take.injected_at).count(), 0.5);
  EXPECT_EQ(bench.sim->state().output_hz, 0.0);
}

// The person's exposure counts all of a 3 s take (before, one tick after the take added at
// most 1 s). Truth: the time the simulated drive's output is above 0 Hz, sampled beside.
TEST(RunSweep, ExposureOverATakeIsItsWallTime) {
  SimRigBench bench = StartSim();
  ASSERT_NE(bench.sim, nullptr);
  auto script = OneStep(8.0);
  ASSERT_TRUE(script.ok());
  testing::TempDir dir;
  SweepOptions options;
  options.session_dir = dir.Join("session");
  FakeTake take;
  take.take_s = 3.0;
  options.hooks.during_hold = take.Hook();
  std::atomic<bool> watching{true};
  double vibrating_s = 0.0;
  std::thread watcher([&] {
    auto last = Clock::now();
    while (watching) {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
      const auto now = Clock::now();
      if (bench.sim->state().output_hz > 0.0)
        vibrating_s += std::chrono::duration<double>(now - last).count();
      last = now;
    }
  });
  auto result = RunSweep(*script, bench.rig, options);
  watching = false;
  watcher.join();
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  EXPECT_FALSE(take.aborted);
  EXPECT_GE(take.ran_s, 3.0);
  EXPECT_GT(vibrating_s, 3.0);
  // Both clocks see the same run; they differ by a control period or two at either end.
  EXPECT_NEAR(result->exposure["vibrating_s"].get<double>(), vibrating_s, 0.4);
}
}  // namespace
}  // namespace facedyn::rig
