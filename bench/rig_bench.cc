// rig_bench: steady-state frequency error of the simulated platform across 6-11 Hz, closed loop
// (the RigSupervisor's trim on the oscillation sensor) against open loop (nominal slip only).
// The simulated drive runs in process behind its real Modbus TCP server on a free loopback
// port; the error is taken from the simulator's true platform frequency (ground truth the
// controller never sees), sampled at 50 Hz over each hold. Prints JSON on stdout.
//
//   rig_bench [--rig config/rigs/sim-tcp.yaml] [--from 6] [--to 11] [--step 1] [--hold-s 3]
//             [--no-open-loop]
//
// Real time: about (settle + hold) x frequencies x 2 runs, ~1.5 min with the defaults.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "core/json_io.h"
#include "core/log.h"
#include "rig/rig_config.h"
#include "rig/supervisor.h"
#include "sim/drive_sim.h"

namespace {

using facedyn::Json;
using facedyn::Status;
using Clock = std::chrono::steady_clock;

struct Args {
  std::string rig = std::string(FACEDYN_SOURCE_DIR) + "/config/rigs/sim-tcp.yaml";
  double from_hz = 6.0;
  double to_hz = 11.0;
  double step_hz = 1.0;
  double hold_s = 3.0;
  bool open_loop = true;
};

bool ParseArgs(int argc, char** argv, Args* args) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&](double* value) {
      if (i + 1 >= argc) return false;
      char* end = nullptr;
      *value = std::strtod(argv[++i], &end);
      return *end == '\0';
    };
    if (a == "--rig" && i + 1 < argc) {
      args->rig = argv[++i];
    } else if (a == "--from") {
      if (!next(&args->from_hz)) return false;
    } else if (a == "--to") {
      if (!next(&args->to_hz)) return false;
    } else if (a == "--step") {
      if (!next(&args->step_hz) || !(args->step_hz > 0.0)) return false;
    } else if (a == "--hold-s") {
      if (!next(&args->hold_s) || !(args->hold_s > 0.0)) return false;
    } else if (a == "--no-open-loop") {
      args->open_loop = false;
    } else {
      return false;
    }
  }
  return true;
}

struct Row {
  double target_hz = 0.0;
  double settle_s = 0.0;
  double true_mean_hz = 0.0;
  double true_max_abs_error_hz = 0.0;
  double measured_mean_hz = 0.0;
  double correction_hz = 0.0;
  std::string error;

  Json ToJson() const {
    Json json;
    json["target_hz"] = target_hz;
    if (!error.empty()) {
      json["error"] = error;
      return json;
    }
    json["steady_state_error_hz"] = true_mean_hz - target_hz;
    json["max_abs_error_hz"] = true_max_abs_error_hz;
    json["true_mean_hz"] = true_mean_hz;
    json["measured_mean_hz"] = measured_mean_hz;
    json["settle_s"] = settle_s;
    json["trim_hz"] = correction_hz;
    return json;
  }
};

// One pass over the frequencies with one supervisor (as a sweep does: no stop in between).
std::vector<Row> RunPass(const facedyn::rig::RigConfig& rig, facedyn::sim::DriveSim& sim,
                         const std::vector<double>& frequencies, double hold_s) {
  std::vector<Row> rows;
  auto supervisor = facedyn::rig::RigSupervisor::Connect(rig, nullptr, nullptr);
  if (!supervisor.ok() || !(*supervisor)->Arm().ok()) {
    Row row;
    row.error = supervisor.ok() ? "arm failed" : supervisor.status().message();
    rows.push_back(row);
    return rows;
  }
  for (const double hz : frequencies) {
    Row row;
    row.target_hz = hz;
    const auto start = Clock::now();
    Status status = (*supervisor)->SetTargetHz(hz);
    if (status.ok()) status = (*supervisor)->WaitSettled(60.0);
    row.settle_s = std::chrono::duration<double>(Clock::now() - start).count();
    if (!status.ok()) {
      row.error = status.message();
      rows.push_back(row);
      break;
    }
    std::atomic<bool> holding{true};
    double sum_hz = 0.0;
    int samples = 0;
    std::thread sampler([&] {
      while (holding) {
        const double true_hz = sim.state().platform_hz;
        sum_hz += true_hz;
        ++samples;
        row.true_max_abs_error_hz = std::max(row.true_max_abs_error_hz, std::abs(true_hz - hz));
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
    });
    auto hold = (*supervisor)->Hold(hold_s);
    holding = false;
    sampler.join();
    if (!hold.ok()) {
      row.error = hold.status().message();
      rows.push_back(row);
      break;
    }
    row.true_mean_hz = samples > 0 ? sum_hz / samples : 0.0;
    row.measured_mean_hz = hold->mean_measured_hz;
    row.correction_hz = (*supervisor)->last().correction_hz;
    rows.push_back(row);
  }
  return rows;
}

}  // namespace

int main(int argc, char** argv) {
  facedyn::InitLogging(facedyn::Verbosity::kQuiet);
  Args args;
  if (!ParseArgs(argc, argv, &args)) {
    std::fprintf(stderr,
                 "usage: rig_bench [--rig RIG.yaml] [--from HZ] [--to HZ] [--step HZ] [--hold-s S] "
                 "[--no-open-loop]\n");
    return 2;
  }
  facedyn::rig::DriveProfile profile;
  facedyn::sim::DriveSimOptions sim_options;
  Status loaded = facedyn::sim::LoadDriveSimFromRig(args.rig, &profile, &sim_options);
  auto rig = facedyn::rig::LoadRigConfig(args.rig);
  if (!loaded.ok() || !rig.ok()) {
    std::fprintf(stderr, "rig_bench: %s\n",
                 (loaded.ok() ? rig.status() : loaded).message().c_str());
    return 1;
  }
  if (rig->transport.kind != facedyn::rig::TransportOptions::Kind::kTcp) {
    std::fprintf(stderr, "rig_bench: %s is not a TCP rig\n", args.rig.c_str());
    return 1;
  }
  sim_options.port = 0;
  auto sim = facedyn::sim::DriveSim::Start(profile, sim_options);
  if (!sim.ok()) {
    std::fprintf(stderr, "rig_bench: %s\n", sim.status().message().c_str());
    return 1;
  }
  rig->transport.port = (*sim)->port();
  std::vector<double> frequencies;
  for (double hz = args.from_hz; hz <= args.to_hz + 1e-9; hz += args.step_hz)
    frequencies.push_back(hz);

  Json out;
  out["rig"] = rig->name;
  out["controller"] = {{"nominal_slip", rig->platform.slip},
                       {"ratio", rig->platform.ratio},
                       {"trim_gain_per_s", rig->trim.gain_per_s},
                       {"settle_tolerance_hz", rig->settle.tolerance_hz},
                       {"settle_time_s", rig->settle.time_s}};
  out["simulated_platform"] = {{"slip_base", sim_options.model.slip_base},
                               {"slip_load", sim_options.model.slip_load},
                               {"slip_reference_hz", sim_options.model.slip_reference_hz},
                               {"sensor_window_s", sim_options.model.sensor_window_s},
                               {"sensor_noise_hz", sim_options.model.sensor_noise_hz}};
  out["hold_s"] = args.hold_s;
  const std::vector<Row> closed = RunPass(*rig, **sim, frequencies, args.hold_s);
  std::vector<Row> open;
  if (args.open_loop) {
    facedyn::rig::RigConfig open_rig = *rig;
    open_rig.trim.enabled = false;
    open_rig.settle.tolerance_hz = 1.0;  // open loop "settles" wherever the slip leaves it
    open = RunPass(open_rig, **sim, frequencies, args.hold_s);
  }
  Json table = Json::array();
  double worst_closed = 0.0, worst_open = 0.0;
  bool all_ok = closed.size() == frequencies.size();
  for (size_t i = 0; i < closed.size(); ++i) {
    Json row;
    row["target_hz"] = closed[i].target_hz;
    row["closed_loop"] = closed[i].ToJson();
    if (closed[i].error.empty()) {
      worst_closed = std::max(worst_closed, std::abs(closed[i].true_mean_hz - closed[i].target_hz));
    } else {
      all_ok = false;
    }
    if (i < open.size()) {
      row["open_loop"] = open[i].ToJson();
      if (open[i].error.empty())
        worst_open = std::max(worst_open, std::abs(open[i].true_mean_hz - open[i].target_hz));
    }
    table.push_back(row);
  }
  out["rows"] = table;
  out["worst_steady_state_error_hz"] = {{"closed_loop", worst_closed}, {"open_loop", worst_open}};
  out["requirement_hz"] = 0.05;
  out["meets_requirement"] = all_ok && worst_closed <= 0.05;
  std::printf("%s\n", out.dump(2).c_str());
  return all_ok ? 0 : 1;
}
