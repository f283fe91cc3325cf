#include "app/rig_demo.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
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
  rig::SweepOptions options;
  options.session_dir = session;
  options.print_prompts = false;
  options.hooks.on_hold_start = [&](const rig::SweepStepInfo& info) {
    true_sum_hz.resize(info.instance_count, 0.0);
    true_samples.resize(info.instance_count, 0);
    true_sum_hz[info.instance] += sim->state().platform_hz;
    ++true_samples[info.instance];
    return Status::Ok();
  };
  options.hooks.on_hold_end = [&](const rig::SweepStepInfo& info, const rig::HoldSummary&) {
    true_sum_hz[info.instance] += sim->state().platform_hz;
    ++true_samples[info.instance];
    return Status::Ok();
  };
  FACEDYN_ASSIGN_OR_RETURN(const rig::SweepResult result, rig::RunSweep(script, rig, options));

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
  }
  return Status::Ok();
}

}  // namespace facedyn::app
