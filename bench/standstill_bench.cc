// standstill_bench: how long the simulated platform takes to stand still after each fault the
// supervisor handles (issue 18's reliability table). Each run starts a fresh simulated drive
// (sim-tcp.yaml's physics, real Modbus TCP on a free loopback port), settles the platform at
// --hz under a RigSupervisor, injects the fault 0.5 s into a hold, and times from the injection
// to the drive reporting 0 Hz output (its own state, polled every millisecond beside the
// supervisor). "to_stop_command_s" is the time until the drive's run command was withdrawn
// (the stop reached the drive); for a cut link no command can reach it and the drive's comm
// watchdog stops it. Prints JSON on stdout: the median, min and max over --runs runs.
//
//   standstill_bench [--rig config/rigs/sim-tcp.yaml] [--hz 10] [--runs 5] [--only NAME]
//
// Scenarios: stop_request (the flag SIGINT sets, during a hold), ctrl_c_during_take (a real
// SIGINT while a take runs beside the hold, rig::HoldDuring as `capture --sweep` uses it),
// refused_stop_retried (a stop whose first 15 replies are exception 06 "busy": more than the
// transport's 10 retries, so the supervisor sends the stop again), busy_status_reads (16 busy
// replies from a hold on: a status read fails after the transport's retries, and the live
// drive gets a controlled ramp to stop rather than the lost-link path),
// overspeed (the sensor starts reading 30 % high), sensor_disagreement (10 % high: below the
// overspeed limit, beyond safety.sensor_tolerance_hz), link_cut (requests vanish; the drive's
// comm watchdog, safety.comm_watchdog_s, stops it). Real time: about 8 s per run.

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "bench/bench_flags.h"
#include "core/json_io.h"
#include "core/log.h"
#include "rig/rig_config.h"
#include "rig/stop_signal.h"
#include "rig/supervisor.h"
#include "sim/drive_sim.h"

namespace {

using facedyn::Json;
using facedyn::Status;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

struct Sample {
  double to_standstill_s = -1.0;
  double to_stop_command_s = -1.0;  // < 0: the run command was never withdrawn
  std::string supervisor_said;
  std::string error;  // the run could not be made
};

enum class Fault {
  kStopRequest,
  kCtrlCDuringTake,
  kRefusedStopRetried,
  kBusyStatusReads,
  kOverspeed,
  kSensorDisagreement,
  kLinkCut
};

struct Scenario {
  const char* name;
  Fault fault;
  const char* what_facedyn_does;
};

const Scenario kScenarios[] = {
    {"stop_request", Fault::kStopRequest, "ramps to stop, waits for 0 Hz"},
    {"ctrl_c_during_take", Fault::kCtrlCDuringTake,
     "the supervisor, ticking beside the take, ramps to stop; the take ends interrupted"},
    {"refused_stop_retried", Fault::kRefusedStopRetried,
     "busy replies are retried until the drive reports standstill"},
    {"busy_status_reads", Fault::kBusyStatusReads,
     "a status read still busy after the transport's retries: ramps to a confirmed stop"},
    {"overspeed", Fault::kOverspeed, "stops: measured above absolute_max_hz + margin"},
    {"sensor_disagreement", Fault::kSensorDisagreement,
     "stops: sensor and drive output disagree beyond sensor_tolerance_hz"},
    {"link_cut", Fault::kLinkCut, "link lost; the drive's comm watchdog stops the motor"},
};

Sample RunOnce(const facedyn::rig::RigConfig& base, const facedyn::rig::DriveProfile& profile,
               const facedyn::sim::DriveSimOptions& sim_options, double hz, Fault fault,
               const std::atomic<bool>* signal_flag) {
  Sample sample;
  auto sim = facedyn::sim::DriveSim::Start(profile, sim_options);
  if (!sim.ok()) {
    sample.error = sim.status().message();
    return sample;
  }
  facedyn::rig::RigConfig rig = base;
  rig.transport.host = "127.0.0.1";
  rig.transport.port = (*sim)->port();
  std::atomic<bool> stop_flag{false};
  const std::atomic<bool>* flag = fault == Fault::kCtrlCDuringTake ? signal_flag : &stop_flag;
  facedyn::rig::ClearStopRequest();
  auto supervisor = facedyn::rig::RigSupervisor::Connect(rig, nullptr, flag);
  Status status = supervisor.ok() ? (*supervisor)->Arm() : supervisor.status();
  if (status.ok()) status = (*supervisor)->SetTargetHz(hz);
  if (status.ok()) status = (*supervisor)->WaitSettled(60.0);
  if (!status.ok()) {
    sample.error = status.message();
    return sample;
  }
  facedyn::sim::DriveSim& drive = **sim;
  std::atomic<bool> injected{false};
  Clock::time_point injected_at;  // written before `injected` is set
  auto inject = [&] {
    injected_at = Clock::now();
    switch (fault) {
      case Fault::kStopRequest:
        stop_flag = true;
        break;
      case Fault::kCtrlCDuringTake:
        ::kill(::getpid(), SIGINT);
        break;
      case Fault::kRefusedStopRetried:
        drive.ExceptionNextReplies(15, MODBUS_EXCEPTION_SLAVE_OR_SERVER_BUSY);
        break;
      case Fault::kBusyStatusReads:
        drive.ExceptionNextReplies(16, MODBUS_EXCEPTION_SLAVE_OR_SERVER_BUSY);
        break;
      case Fault::kOverspeed:
        drive.SetSensorGain(1.3);
        break;
      case Fault::kSensorDisagreement:
        drive.SetSensorGain(1.1);
        break;
      case Fault::kLinkCut:
        drive.CutLink(true);
        break;
    }
    injected = true;
  };
  // The watcher: the drive's own state, every millisecond, from the injection on.
  // A refused stop is injected on the supervisor's thread right before it stops, so that the
  // busy replies land on the stop command (busy_status_reads has them land on the status reads
  // of the hold); every other fault from the watcher.
  const bool inject_here = fault == Fault::kRefusedStopRetried;
  std::atomic<bool> watching{true};
  std::thread watcher([&] {
    if (inject_here) {
      while (!injected) std::this_thread::sleep_for(std::chrono::microseconds(200));
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(500));
      inject();
    }
    const auto give_up = injected_at + std::chrono::seconds(20);
    while (watching || Clock::now() < give_up) {
      const facedyn::sim::DriveModelState state = drive.state();
      const auto now = Clock::now();
      if (!state.run_commanded && sample.to_stop_command_s < 0.0)
        sample.to_stop_command_s = Seconds(now - injected_at);
      if (state.output_hz == 0.0) {
        sample.to_standstill_s = Seconds(now - injected_at);
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  });
  if (fault == Fault::kCtrlCDuringTake) {
    const facedyn::rig::SupervisedWork supervised =
        facedyn::rig::HoldDuring(supervisor->get(), 30.0, 60.0, [](const std::atomic<bool>& abort) {
          while (!abort) std::this_thread::sleep_for(std::chrono::milliseconds(8));
          return facedyn::AbortedError("take interrupted");
        });
    sample.supervisor_said = supervised.hold_status.message();
  } else if (inject_here) {
    Status held = (*supervisor)->Hold(0.5).status();
    if (held.ok()) {
      inject();
      held = (*supervisor)->RampToStop("bench: refused stop");
    } else {
      inject();  // releases the watcher
    }
    sample.supervisor_said = held.ok() ? "stopped after busy replies" : held.message();
  } else {
    sample.supervisor_said = (*supervisor)->Hold(30.0).status().message();
  }
  watching = false;
  watcher.join();
  if (fault == Fault::kLinkCut) {
    sample.to_stop_command_s = -1.0;  // nothing reached the drive: its watchdog stopped it
  }
  supervisor->reset();
  facedyn::rig::ClearStopRequest();
  return sample;
}

double Median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  const size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

}  // namespace

int main(int argc, char** argv) {
  facedyn::InitLogging(facedyn::Verbosity::kQuiet);
  std::string rig_path = std::string(FACEDYN_SOURCE_DIR) + "/config/rigs/sim-tcp.yaml";
  double hz = 10.0;
  long long runs = 5;
  std::string only;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--rig" && i + 1 < argc) {
      rig_path = argv[++i];
    } else if (a == "--hz" && i + 1 < argc) {
      hz = facedyn::bench::FlagNumber(argv[0], a, argv[++i]);
    } else if (a == "--runs" && i + 1 < argc) {
      runs = facedyn::bench::FlagInteger(argv[0], a, argv[++i]);
    } else if (a == "--only" && i + 1 < argc) {
      only = argv[++i];
    } else {
      std::fprintf(stderr,
                   "usage: standstill_bench [--rig RIG.yaml] [--hz F] [--runs N] [--only NAME]\n");
      return 2;
    }
  }
  if (runs < 1) {
    std::fprintf(stderr, "%s: --runs must be >= 1\n", argv[0]);
    return 2;
  }
  auto rig = facedyn::rig::LoadRigConfig(rig_path);
  facedyn::rig::DriveProfile profile;
  facedyn::sim::DriveSimOptions sim_options;
  const Status loaded =
      rig.ok() ? facedyn::sim::LoadDriveSimFromRig(rig_path, &profile, &sim_options) : rig.status();
  if (!loaded.ok()) {
    std::fprintf(stderr, "standstill_bench: %s\n", loaded.message().c_str());
    return 1;
  }
  sim_options.host = "127.0.0.1";
  sim_options.port = 0;
  const std::atomic<bool>* signal_flag = facedyn::rig::InstallStopSignalHandlers();

  Json out;
  out["command"] = "standstill_bench --runs " + std::to_string(runs) + " --hz " +
                   facedyn::Json(hz).dump();
  out["rig"] = rig_path;
  out["from_hz"] = hz;
  out["runs"] = runs;
  out["sim_accel_hz_per_s"] = sim_options.model.accel_hz_per_s;
  out["comm_watchdog_s"] = rig->safety.comm_watchdog_s;
  out["control_period_s"] = rig->safety.control_period_s;
  Json scenarios = Json::object();
  bool all_ok = true;
  for (const Scenario& scenario : kScenarios) {
    if (!only.empty() && only != scenario.name) continue;
    std::vector<double> standstill, command;
    Json samples = Json::array();
    std::string said;
    for (long long r = 0; r < runs; ++r) {
      const Sample s = RunOnce(*rig, profile, sim_options, hz, scenario.fault, signal_flag);
      if (!s.error.empty() || s.to_standstill_s < 0.0) {
        all_ok = false;
        samples.push_back(s.error.empty() ? "never reached 0 Hz" : s.error);
        continue;
      }
      standstill.push_back(s.to_standstill_s);
      if (s.to_stop_command_s >= 0.0) command.push_back(s.to_stop_command_s);
      samples.push_back(s.to_standstill_s);
      said = s.supervisor_said;
    }
    Json row;
    row["what_facedyn_does"] = scenario.what_facedyn_does;
    row["samples_s"] = samples;
    if (!standstill.empty()) {
      row["median_to_standstill_s"] = Median(standstill);
      row["min_s"] = *std::min_element(standstill.begin(), standstill.end());
      row["max_s"] = *std::max_element(standstill.begin(), standstill.end());
    }
    if (!command.empty()) row["median_to_stop_command_s"] = Median(command);
    row["supervisor_said"] = said;
    scenarios[scenario.name] = row;
  }
  out["scenarios"] = scenarios;
  std::printf("%s\n", out.dump(2).c_str());
  return all_ok ? 0 : 1;
}
