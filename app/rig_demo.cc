#include "app/rig_demo.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <thread>
#include <vector>

#include "core/file_util.h"
#include "rig/rig_config.h"
#include "rig/sweep.h"
#include "sim/drive_sim.h"

namespace facedyn::app {
namespace {

bool IsFile(const std::string& path) {
  struct stat info {};
  return ::stat(path.c_str(), &info) == 0 && S_ISREG(info.st_mode);
}

// Samples the simulated drive's state on its own thread while the sweep runs: the drive's
// setpoint, the oscillation sensor's reading (what the controller reads over Modbus) and the
// simulator's true platform frequency (which nothing on the control side sees), against wall
// time since Start(). A thread rather than the sweep's hooks because the hooks only fire at the
// edges of each hold, and the ramps in between are what the plot is for.
class DriveSampler {
 public:
  DriveSampler(const sim::DriveSim* sim, double interval_s) : sim_(sim), interval_s_(interval_s) {}
  ~DriveSampler() { Stop(); }

  void Start() {
    start_ = std::chrono::steady_clock::now();
    thread_ = std::thread([this] {
      std::unique_lock<std::mutex> lock(mutex_);
      while (!stop_) {
        const sim::DriveModelState state = sim_->state();
        t_s_.push_back(NowS());
        setpoint_hz_.push_back(state.run_commanded ? state.setpoint_hz : 0.0);
        measured_hz_.push_back(state.sensor_hz);
        true_hz_.push_back(state.platform_hz);
        wake_.wait_for(lock, std::chrono::duration<double>(interval_s_), [this] { return stop_; });
      }
    });
  }
  void Stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
  }
  // Seconds since Start().
  double NowS() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  // Call after Stop().
  Json ToJson() const {
    auto rounded = [](const std::vector<double>& values, double step) {
      Json array = Json::array();
      for (double v : values) array.push_back(std::round(v / step) * step);
      return array;
    };
    return {{"sample_interval_s", interval_s_},
            {"t_s", rounded(t_s_, 1e-3)},
            {"setpoint_hz", rounded(setpoint_hz_, 1e-4)},
            {"measured_hz", rounded(measured_hz_, 1e-4)},
            {"true_hz", rounded(true_hz_, 1e-4)}};
  }

 private:
  const sim::DriveSim* sim_;
  double interval_s_;
  std::chrono::steady_clock::time_point start_;
  std::thread thread_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
  std::vector<double> t_s_, setpoint_hz_, measured_hz_, true_hz_;
};

}  // namespace

StatusOr<std::string> FindConfigDir() {
  std::vector<std::string> candidates;
  if (const char* env = std::getenv("FACEDYN_CONFIG_DIR")) candidates.push_back(env);
  char exe[4096];
  const ssize_t n = ::readlink("/proc/self/exe", exe, sizeof(exe) - 1);
  if (n > 0) {
    exe[n] = '\0';
    std::string dir(exe);
    dir = dir.substr(0, dir.rfind('/'));
    candidates.push_back(dir + "/../../config");  // build/app/facedyn
    candidates.push_back(dir + "/../config");
    candidates.push_back(dir + "/../share/facedyn/config");
  }
  candidates.push_back("config");
  for (const std::string& dir : candidates) {
    if (IsFile(dir + "/rigs/sim-tcp.yaml") && IsFile(dir + "/sweeps/demo.yaml")) return dir;
  }
  return NotFoundError(
      fmt::format("no facedyn config folder with rigs/sim-tcp.yaml and sweeps/demo.yaml "
                  "(looked in {}); set FACEDYN_CONFIG_DIR",
                  fmt::join(candidates, ", ")));
}

Status RunRigDemoStage(const std::string& out_dir, bool quick, Json* metrics) {
  FACEDYN_ASSIGN_OR_RETURN(const std::string config_dir, FindConfigDir());
  const std::string rig_path = config_dir + "/rigs/sim-tcp.yaml";
  rig::DriveProfile profile;
  sim::DriveSimOptions sim_options;
  FACEDYN_RETURN_IF_ERROR(sim::LoadDriveSimFromRig(rig_path, &profile, &sim_options));
  FACEDYN_ASSIGN_OR_RETURN(rig::RigConfig rig, rig::LoadRigConfig(rig_path));
  FACEDYN_ASSIGN_OR_RETURN(rig::SweepScript script,
                           rig::LoadSweepScript(config_dir + "/sweeps/demo.yaml"));
  if (quick) {
    for (rig::SweepStep& step : script.steps) step.hold_s = std::min(step.hold_s, 0.5);
  }
  sim_options.host = "127.0.0.1";
  sim_options.port = 0;  // a free port: the demo never collides with a running serve-sim
  FACEDYN_ASSIGN_OR_RETURN(auto sim, sim::DriveSim::Start(profile, sim_options));
  rig.transport.host = "127.0.0.1";
  rig.transport.port = sim->port();
  spdlog::info("rig demo: simulated drive ({}) on {}, sweep {} ({} steps)", profile.name,
               sim->Describe(), script.name, script.InstanceCount());

  const std::string session = JoinPath(out_dir, "rig-session");
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(session));
  for (const char* owned : {"rig_log.jsonl", "sweep_summary.json"}) {
    const std::string path = JoinPath(session, owned);
    if (IsFile(path) && ::unlink(path.c_str()) != 0) {
      return UnavailableError(fmt::format("rig demo: cannot replace {}", path));
    }
  }
  // The simulator's true platform frequency over each hold, which the controller never sees.
  std::vector<double> true_sum_hz;
  std::vector<int> true_samples;
  // Hold edges on the sampler's clock, so the plot can mark each step's ramp and hold.
  std::vector<double> hold_start_s, hold_end_s;
  DriveSampler sampler(sim.get(), 0.05);
  rig::SweepOptions options;
  options.session_dir = session;
  options.print_prompts = false;
  options.hooks.on_hold_start = [&](const rig::SweepStepInfo& info) {
    true_sum_hz.resize(info.instance_count, 0.0);
    true_samples.resize(info.instance_count, 0);
    hold_start_s.resize(info.instance_count, std::nan(""));
    hold_end_s.resize(info.instance_count, std::nan(""));
    hold_start_s[info.instance] = sampler.NowS();
    true_sum_hz[info.instance] += sim->state().platform_hz;
    ++true_samples[info.instance];
    return Status::Ok();
  };
  options.hooks.on_hold_end = [&](const rig::SweepStepInfo& info, const rig::HoldSummary&) {
    hold_end_s[info.instance] = sampler.NowS();
    true_sum_hz[info.instance] += sim->state().platform_hz;
    ++true_samples[info.instance];
    return Status::Ok();
  };
  sampler.Start();
  StatusOr<rig::SweepResult> swept = rig::RunSweep(script, rig, options);
  sampler.Stop();
  FACEDYN_RETURN_IF_ERROR(swept.status());
  const rig::SweepResult& result = *swept;

  std::printf("\nRig: simulated drive over Modbus TCP (%s), sweep %s\n", sim->Describe().c_str(),
              script.name.c_str());
  std::printf("  %-9s %-10s %-12s %-12s %-10s %s\n", "step", "target", "measured", "true",
              "max err", "prompt");
  Json steps = Json::array();
  double worst_max = 0.0, worst_steady = 0.0;
  for (const rig::SweepStepResult& step : result.steps) {
    const int i = step.instance;
    const double true_hz = i < static_cast<int>(true_samples.size()) && true_samples[i] > 0
                               ? true_sum_hz[i] / true_samples[i]
                               : std::nan("");
    std::printf("  %-9d %-10.2f %-12.3f %-12.3f %-10.3f %s\n", i + 1, step.target_hz,
                step.hold.mean_measured_hz, true_hz, step.hold.max_abs_error_hz,
                step.prompt.c_str());
    worst_max = std::max(worst_max, step.hold.max_abs_error_hz);
    worst_steady = std::max(worst_steady, std::abs(step.hold.mean_measured_hz - step.target_hz));
    Json s;
    s["target_hz"] = step.target_hz;
    s["measured_mean_hz"] = step.hold.mean_measured_hz;
    s["true_platform_hz"] = true_hz;
    s["max_abs_error_hz"] = step.hold.max_abs_error_hz;
    s["hold_s"] = step.hold.seconds;
    s["prompt"] = step.prompt;
    // The step runs from the previous hold's end (the sweep's start for the first) through
    // its ramp and settling to the end of its own hold.
    const auto edge = [](const std::vector<double>& times, int k) -> Json {
      return k >= 0 && k < static_cast<int>(times.size()) && std::isfinite(times[k])
                 ? Json(std::round(times[k] * 1e3) / 1e3)
                 : Json(nullptr);
    };
    s["start_s"] = i == 0 ? Json(0.0) : edge(hold_end_s, i - 1);
    s["hold_start_s"] = edge(hold_start_s, i);
    s["hold_end_s"] = edge(hold_end_s, i);
    steps.push_back(s);
  }
  std::printf("  exposure: %.1f s of vibration, A(8) %.3f m/s^2 (unweighted); journal %s\n",
              result.exposure.value("vibrating_s", 0.0),
              result.exposure.value("a8_unweighted_m_s2", 0.0), result.log_path.c_str());
  if (metrics != nullptr) {
    (*metrics)["steps"] = steps;
    (*metrics)["max_abs_error_hz"] = worst_max;
    (*metrics)["worst_steady_state_error_hz"] = worst_steady;
    (*metrics)["exposure"] = result.exposure;
    (*metrics)["log"] = result.log_path;
    (*metrics)["time_series"] = sampler.ToJson();
  }
  return Status::Ok();
}

}  // namespace facedyn::app
