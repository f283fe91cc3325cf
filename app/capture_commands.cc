// `facedyn capture` and `facedyn session check`: multi-view capture sessions.
//
//   facedyn capture --config CAPTURE.yaml --session DIR --take NAME [--json]
//       sets the platform (when the config names a rig; a simulated rig's drive can be served
//       in-process), waits for it to settle, records one take from every camera on one
//       trigger, stops the platform.
//   facedyn capture --config CAPTURE.yaml --session DIR --sweep SWEEP.yaml [--resume] [--json]
//       the capture step of a frequency sweep: the rig's sweep runner (rig/sweep.h) moves the
//       platform step by step and one take is recorded per step, once the step has settled.
//   facedyn session check DIR [--json]
//       what is complete in a session and what is not (exit 1 when anything is incomplete).

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <string>
#include <thread>

#include "app/capture_demo.h"
#include "app/command.h"
#include "capture/aravis_camera.h"
#include "capture/capture_config.h"
#include "capture/opencv_camera.h"
#include "capture/session.h"
#include "capture/session_runner.h"
#include "capture/trigger.h"
#include "core/config_node.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "rig/drive_client.h"
#include "rig/modbus_transport.h"
#include "rig/rig_config.h"
#include "rig/session_log.h"
#include "rig/stop_signal.h"
#include "rig/supervisor.h"
#include "rig/sweep.h"
#include "sim/calibration_target.h"
#include "sim/drive_sim.h"
#include "sim/expressions.h"
#include "sim/sim_capture.h"

namespace facedyn::app {

namespace {

std::vector<capture::SessionCameraInfo> CameraInfos(const capture::CaptureConfig& config) {
  std::vector<capture::SessionCameraInfo> infos;
  const int count = config.backend == "sim"      ? static_cast<int>(config.cameras.size())
                    : config.backend == "opencv" ? static_cast<int>(config.sources.size())
                                                 : static_cast<int>(config.devices.size());
  for (int k = 0; k < count; ++k) {
    capture::SessionCameraInfo info;
    info.name = k < static_cast<int>(config.cameras.size()) ? config.cameras[k].name
                                                            : "cam" + std::to_string(k);
    info.backend = config.backend;
    const capture::CameraSettings settings = config.SettingsFor(k);
    info.width_px = settings.width_px;
    info.height_px = settings.height_px;
    info.pixel_format = capture::PixelFormatName(config.pixel_format);
    infos.push_back(info);
  }
  return infos;
}

// The platform for the duration of a command: an optional in-process simulated drive, the
// rig's supervisor, and its journal in the session folder.
struct Platform {
  std::unique_ptr<sim::DriveSim> drive_sim;
  rig::RigConfig rig;
  std::unique_ptr<rig::SessionLog> log;
  std::unique_ptr<rig::RigSupervisor> supervisor;
};

Status StartPlatform(const capture::CaptureConfig& config, const std::string& rig_path,
                     Platform* platform) {
  FACEDYN_ASSIGN_OR_RETURN(platform->rig, rig::LoadRigConfig(rig_path));
  if (config.platform.start_simulated_drive) {
    rig::DriveProfile profile;
    sim::DriveSimOptions sim_options;
    FACEDYN_RETURN_IF_ERROR(sim::LoadDriveSimFromRig(rig_path, &profile, &sim_options));
    if (platform->rig.transport.kind != rig::TransportOptions::Kind::kTcp) {
      return InvalidArgumentError(
          rig_path +
          ": start_simulated_drive needs a Modbus TCP rig (e.g. config/rigs/sim-tcp.yaml)");
    }
    sim_options.host = "127.0.0.1";
    sim_options.port = 0;  // a free loopback port: never collides with a running serve-sim
    FACEDYN_ASSIGN_OR_RETURN(platform->drive_sim, sim::DriveSim::Start(profile, sim_options));
    platform->rig.transport.host = "127.0.0.1";
    platform->rig.transport.port = platform->drive_sim->port();
    spdlog::info("capture: simulated drive ({}) on {}", profile.name,
                 platform->drive_sim->Describe());
  }
  return Status::Ok();
}

Status ConnectSupervisor(const std::string& session_dir, Platform* platform,
                         const std::atomic<bool>* stop) {
  FACEDYN_ASSIGN_OR_RETURN(platform->log,
                           rig::SessionLog::Open(JoinPath(session_dir, "rig_log.jsonl")));
  FACEDYN_ASSIGN_OR_RETURN(platform->supervisor,
                           rig::RigSupervisor::Connect(platform->rig, platform->log.get(), stop));
  return platform->supervisor->Arm();
}

// A take's telemetry row from the supervisor's last control period. The supervisor's thread
// is the only one on the drive link (rig/supervisor.h); the take reads its snapshot.
capture::TelemetrySample SampleFromSnapshot(const rig::PlatformSnapshot& snapshot) {
  capture::TelemetrySample sample;
  sample.running = snapshot.reading.running;
  sample.faulted = snapshot.reading.faulted;
  sample.output_hz = snapshot.reading.output_hz;
  sample.measured_hz = snapshot.reading.measured_hz;
  sample.target_hz = snapshot.reading.target_hz;
  sample.state = rig::RigStateName(snapshot.state);
  return sample;
}

// How long the platform may be held for one take before it is stopped whatever the take is
// doing: the take's own length, plus preparation (a simulated take renders slower than real
// time), with a wide margin. A camera that hangs must not keep a person vibrating.
double MaxTakeHoldS(const capture::CaptureConfig& config) {
  return 120.0 + 20.0 * static_cast<double>(config.TriggerCount()) / config.fps;
}

struct TakeInputs {
  std::string name;
  double platform_hz = 0.0;  // true platform frequency for the simulated face (0: config's)
  std::string expression;    // "" = the config's
  std::function<StatusOr<capture::TelemetrySample>()> telemetry;  // from the trigger thread
  Json extra = Json::object();
};

struct TakeOutput {
  capture::TakeReport report;
  double render_fps = 0.0;
  double simulate_s = 0.0;
};

StatusOr<TakeOutput> CaptureTake(const capture::CaptureConfig& config,
                                 capture::SessionWriter* session, const TakeInputs& inputs,
                                 const std::atomic<bool>* stop) {
  TakeOutput output;
  std::vector<std::unique_ptr<capture::Camera>> owned;
  std::unique_ptr<sim::SimulatedStage> stage;
  sim::SimCaptureOptions sim_options;
  const int64_t triggers = config.TriggerCount();
  if (config.backend == "sim") {
    FACEDYN_ASSIGN_OR_RETURN(
        sim_options,
        sim::ParseSimCaptureOptions(
            *config.sim, std::filesystem::path(config.source_path).parent_path().string()));
    if (!inputs.expression.empty()) sim_options.performance.expression = inputs.expression;
    spdlog::info(
        "capture: simulating {} s of '{}' on the platform at {:.3f} Hz", triggers / config.fps,
        sim_options.performance.expression,
        inputs.platform_hz > 0 ? inputs.platform_hz : sim_options.performance.motion.platform_hz);
    FACEDYN_ASSIGN_OR_RETURN(
        sim::SimulatedStage prepared,
        sim::PrepareSimulatedStage(sim_options, config.cameras, config.fps, triggers,
                                   inputs.platform_hz, config.mount));
    stage = std::make_unique<sim::SimulatedStage>(std::move(prepared));
    output.simulate_s = stage->simulate_s;
  } else if (config.backend == "opencv") {
    for (size_t k = 0; k < config.sources.size(); ++k) {
      owned.push_back(std::make_unique<capture::OpenCvCamera>(
          static_cast<int>(k), CameraInfos(config)[k].name, config.sources[k]));
    }
  } else {
    for (size_t k = 0; k < config.devices.size(); ++k) {
      owned.push_back(std::make_unique<capture::AravisCamera>(
          static_cast<int>(k), CameraInfos(config)[k].name, config.devices[k]));
    }
  }
  std::vector<capture::Camera*> cameras;
  if (stage) {
    for (auto& camera : stage->cameras) cameras.push_back(camera.get());
  } else {
    for (auto& camera : owned) cameras.push_back(camera.get());
  }
  for (size_t k = 0; k < cameras.size(); ++k) {
    capture::CameraSettings settings = config.SettingsFor(static_cast<int>(k));
    if (settings.width_px == 0)
      return InvalidArgumentError(config.source_path + ": camera " + std::to_string(k) +
                                  " has no size (give cameras.calibration)");
    FACEDYN_RETURN_IF_ERROR(cameras[k]->Configure(settings));
  }
  capture::TakeOptions options;
  options.name = inputs.name;
  options.triggers = triggers;
  options.recorder = config.recorder;
  options.timestamp_tolerance_ns = config.timestamp_tolerance_ns;
  if (inputs.telemetry) options.telemetry = inputs.telemetry;
  options.telemetry_period_s = config.platform.telemetry_period_s;
  options.stop_requested = stop;
  options.extra = inputs.extra;
  options.extra["config"] = config.source_path;
  options.extra["backend"] = config.backend;
  options.extra["camera_mount"] = capture::CameraMountName(config.mount);
  options.extra["exposure_us"] = config.exposure_us;
  options.extra["backpressure"] = capture::BackpressurePolicyName(config.recorder.policy);
  if (stage) {
    options.extra["ground_truth"] = "ground_truth";
    options.extra["platform_hz_true"] = stage->platform_hz;
    if (stage->hold_start_s) {
      // When the prompted expression is held (from trigger 0): the session's prompt script for
      // the simulated actor (sim/sim_capture.h), which reconstruction carries into take.json.
      options.extra["hold_start_s"] = *stage->hold_start_s;
    }
    options.before_first_trigger = [&](const std::string& take_dir) {
      return sim::WriteGroundTruth(*stage, sim_options, config.cameras, take_dir);
    };
  }
  capture::VirtualTrigger trigger({config.fps, config.trigger_pace});
  FACEDYN_ASSIGN_OR_RETURN(output.report, capture::RecordTake(session, cameras, &trigger, options));
  if (stage && output.report.record_wall_s > 0) {
    // Rendering is the bottleneck of a simulated take: frames/s over all cameras and cores.
    int64_t frames = 0;
    for (const auto& camera : output.report.result.cameras) frames += camera.record.frames_written;
    output.render_fps = frames / output.report.record_wall_s;
  }
  return output;
}

Json TakeJson(const TakeOutput& output) {
  Json json = capture::TakeResultToJson("", output.report.result);
  json.erase("name");
  json["take_dir"] = output.report.take_dir;
  json["wall_s"] = output.report.wall_s;
  json["record_wall_s"] = output.report.record_wall_s;
  json["megabytes_written"] = output.report.bytes_written / 1e6;
  json["megabytes_per_s"] = output.report.MegabytesPerSecond();
  if (output.render_fps > 0) json["frames_per_s"] = output.render_fps;
  if (output.simulate_s > 0) json["simulate_s"] = output.simulate_s;
  return json;
}

void PrintTake(const std::string& name, const TakeOutput& output) {
  const capture::TakeResult& r = output.report.result;
  std::printf(
      "take %s: %s, %lld of %lld triggers at %.0f fps, %.1f MB recorded in %.1f s (%.1f MB/s)\n",
      name.c_str(), r.status.c_str(), static_cast<long long>(r.triggers_emitted),
      static_cast<long long>(r.triggers_requested), r.fps, output.report.bytes_written / 1e6,
      output.report.record_wall_s, output.report.MegabytesPerSecond());
  for (const capture::TakeCameraResult& camera : r.cameras) {
    std::printf(
        "  %-6s %5lld frames  missing %lld  duplicated %lld  out-of-order %lld  ts-mismatch %lld "
        "(max %.1f us)  dropped %lld\n",
        camera.name.c_str(), static_cast<long long>(camera.record.frames_written),
        static_cast<long long>(camera.sync.missing), static_cast<long long>(camera.sync.duplicated),
        static_cast<long long>(camera.sync.out_of_order),
        static_cast<long long>(camera.sync.timestamp_mismatch),
        camera.sync.max_timestamp_error_ns / 1e3,
        static_cast<long long>(camera.record.dropped_queue_full));
  }
  if (!r.reason.empty()) std::printf("  reason: %s\n", r.reason.c_str());
  if (output.render_fps > 0)
    std::printf("  simulated cameras: %.1f frames/s rendered and recorded (all cameras)\n",
                output.render_fps);
}

struct CaptureCommandOptions {
  std::string config;
  std::string session;
  std::string take;
  std::string sweep;
  bool resume = false;
  bool json = false;
};

StatusOr<std::unique_ptr<capture::SessionWriter>> OpenSession(const capture::CaptureConfig& config,
                                                              const std::string& dir) {
  Json rig{{"capture_config", config.source_path},
           {"name", config.name},
           {"backend", config.backend},
           {"fps", config.fps},
           {"trigger", {{"kind", "virtual"}, {"pace", config.trigger_pace}}}};
  if (!config.platform.rig_path.empty()) rig["rig"] = config.platform.rig_path;
  FACEDYN_ASSIGN_OR_RETURN(auto session,
                           capture::SessionWriter::Open(dir, "virtual", CameraInfos(config), rig));
  if (!config.cameras.empty()) {
    FACEDYN_RETURN_IF_ERROR(
        capture::WriteCameraModels(JoinPath(dir, "calibration.yaml"), config.cameras));
    FACEDYN_RETURN_IF_ERROR(session->SetCalibration("calibration.yaml"));
  }
  return session;
}

Status RunCaptureCommand(const CaptureCommandOptions& options) {
  FACEDYN_ASSIGN_OR_RETURN(const capture::CaptureConfig config,
                           capture::LoadCaptureConfig(options.config));
  if (options.take.empty() == options.sweep.empty())
    return InvalidArgumentError("give exactly one of --take NAME and --sweep SWEEP.yaml");
  if (!options.take.empty() && !capture::IsValidTakeName(options.take)) {
    return InvalidArgumentError("--take '" + options.take +
                                "': use letters, digits, '_', '-', '.' (not first)");
  }
  const std::atomic<bool>* stop = rig::InstallStopSignalHandlers();
  FACEDYN_ASSIGN_OR_RETURN(auto session, OpenSession(config, options.session));

  if (!options.take.empty()) {
    TakeInputs inputs;
    inputs.name = options.take;
    Platform platform;
    if (!config.platform.rig_path.empty()) {
      FACEDYN_RETURN_IF_ERROR(StartPlatform(config, config.platform.rig_path, &platform));
      FACEDYN_RETURN_IF_ERROR(ConnectSupervisor(options.session, &platform, stop));
      FACEDYN_RETURN_IF_ERROR(platform.supervisor->SetTargetHz(config.platform.hz));
      (void)session->events().Append({{"event", "rig_set"}, {"hz", config.platform.hz}});
      spdlog::info("capture: platform to {:.2f} Hz, waiting for it to settle", config.platform.hz);
      FACEDYN_RETURN_IF_ERROR(platform.supervisor->WaitSettled(config.platform.settle_timeout_s));
      const rig::PlatformReading settled = platform.supervisor->last();
      (void)session->events().Append({{"event", "rig_settled"},
                                      {"measured_hz", settled.measured_hz},
                                      {"target_hz", config.platform.hz}});
      inputs.platform_hz =
          platform.drive_sim ? platform.drive_sim->state().platform_hz : settled.measured_hz;
      inputs.extra["platform"] = {{"target_hz", config.platform.hz},
                                  {"measured_hz_at_start", settled.measured_hz},
                                  {"rig", config.platform.rig_path}};
      rig::RigSupervisor* supervisor = platform.supervisor.get();
      inputs.telemetry = [supervisor]() -> StatusOr<capture::TelemetrySample> {
        return SampleFromSnapshot(supervisor->Snapshot());
      };
    }
    StatusOr<TakeOutput> output = InternalError("the take was not recorded");
    Status platform_status;  // what the supervisor saw during the take, then the stop
    if (platform.supervisor) {
      // The take records on a thread of its own while this thread keeps supervising the
      // platform; a trip, overspeed or stop signal stops the platform and interrupts the take.
      const rig::SupervisedWork supervised =
          rig::HoldDuring(platform.supervisor.get(), 0.0, MaxTakeHoldS(config),
                          [&](const std::atomic<bool>& abort) {
                            output = CaptureTake(config, session.get(), inputs, &abort);
                            return output.status();
                          });
      platform_status = supervised.hold_status;
      Status stopped = platform_status.ok()
                           ? platform.supervisor->RampToStop("take " + options.take + " done")
                           : Status::Ok();  // a failed hold has stopped already (or lost the link)
      (void)session->events().Append(
          {{"event", "rig_stop"}, {"ok", stopped.ok() && platform_status.ok()}});
      // Close() disarms the drive's watchdog only after a confirmed standstill; its error says
      // when it had to leave it armed, and that must reach the user.
      const Status closed = platform.supervisor->Close();
      if (platform_status.ok()) platform_status = stopped;
      if (platform_status.ok()) platform_status = closed;
    } else {
      output = CaptureTake(config, session.get(), inputs, stop);
    }
    if (!output.ok()) return platform_status.ok() ? output.status() : platform_status;
    if (!platform_status.ok()) {
      if (!options.json) PrintTake(options.take, *output);
      return platform_status;
    }
    if (options.json) {
      std::printf("%s\n", TakeJson(*output).dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
    } else {
      PrintTake(options.take, *output);
    }
    if (output->report.result.status != "complete") {
      return AbortedError("take " + options.take +
                          " is incomplete: " + output->report.result.reason);
    }
    return Status::Ok();
  }

  // One take per sweep step.
  FACEDYN_ASSIGN_OR_RETURN(const rig::SweepScript script, rig::LoadSweepScript(options.sweep));
  const std::string rig_path =
      !config.platform.rig_path.empty() ? config.platform.rig_path : script.rig_path;
  if (rig_path.empty())
    return InvalidArgumentError(
        "--sweep: neither the capture config's platform.rig nor the sweep names a rig");
  Platform platform;
  FACEDYN_RETURN_IF_ERROR(StartPlatform(config, rig_path, &platform));
  Json takes = Json::array();
  rig::SweepOptions sweep_options;
  sweep_options.session_dir = options.session;
  sweep_options.resume = options.resume;
  sweep_options.stop_requested = stop;
  sweep_options.print_prompts = !options.json;
  bool all_complete = true;
  // The takes earlier runs made for a step (a kill or a stop interrupts one, and the step is
  // recorded again as <base>_retryN), oldest first, and the name for a new one.
  struct StepTakes {
    std::vector<std::string> earlier;
    std::string next;
  };
  auto step_takes = [&](const rig::SweepStepInfo& info) {
    std::string prompt;
    for (char c : info.spec.prompt) prompt += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
    const std::string base = fmt::format("step{:02d}_{:.2f}hz{}{}", info.instance + 1, info.spec.hz,
                                         prompt.empty() ? "" : "_", prompt);
    StepTakes found;
    found.next = base;
    for (int retry = 2; std::filesystem::exists(session->TakeDir(found.next)); ++retry) {
      found.earlier.push_back(found.next);
      found.next = fmt::format("{}_retry{}", base, retry);
    }
    return found;
  };
  // A kill between a take's end and the rig log's step_done leaves the step's take complete on
  // disk: --resume counts it instead of recording (and vibrating) the step again.
  sweep_options.hooks.already_done = [&](const rig::SweepStepInfo& info) {
    for (const std::string& name : step_takes(info).earlier) {
      auto manifest = ConfigNode::ReadFile(JoinPath(session->TakeDir(name), "capture.json"));
      if (manifest.ok() && manifest->GetOr<std::string>("status", "").ok() &&
          *manifest->GetOr<std::string>("status", "") == "complete") {
        spdlog::info("capture: take {} of step {} is complete from an earlier run", name,
                     info.instance + 1);
        return true;
      }
    }
    return false;
  };
  sweep_options.hooks.max_hold_s = MaxTakeHoldS(config);
  // Runs on a thread of its own while the sweep's thread supervises the platform (HoldDuring).
  sweep_options.hooks.during_hold = [&](const rig::SweepStepInfo& info,
                                        const rig::HoldWork& work) -> Status {
    const StepTakes earlier = step_takes(info);
    const std::string name = earlier.next;
    TakeInputs inputs;
    inputs.name = name;
    // `session check` then counts the earlier, interrupted attempts as redone by this take.
    if (!earlier.earlier.empty()) inputs.extra["supersedes"] = earlier.earlier;
    inputs.platform_hz =
        platform.drive_sim ? platform.drive_sim->state().platform_hz : info.spec.hz;
    const std::vector<std::string> expressions = sim::ExpressionNames();
    if (std::find(expressions.begin(), expressions.end(), info.spec.prompt) != expressions.end()) {
      inputs.expression = info.spec.prompt;  // the prompt names an expression: the face holds it
    }
    inputs.extra["sweep"] = {{"script", script.name},
                             {"instance", info.instance},
                             {"target_hz", info.spec.hz},
                             {"prompt", info.spec.prompt}};
    inputs.telemetry = [&work]() -> StatusOr<capture::TelemetrySample> {
      return SampleFromSnapshot(work.platform());
    };
    FACEDYN_ASSIGN_OR_RETURN(const TakeOutput output,
                             CaptureTake(config, session.get(), inputs, work.abort));
    if (!options.json) PrintTake(name, output);
    Json entry = TakeJson(output);
    entry["name"] = name;
    takes.push_back(entry);
    if (output.report.result.status != "complete") {
      all_complete = false;
      return AbortedError("take " + name + " is incomplete: " + output.report.result.reason);
    }
    return Status::Ok();
  };
  auto result = rig::RunSweep(script, platform.rig, sweep_options);
  if (options.json)
    std::printf("%s\n", Json{{"takes", takes}, {"complete", result.ok() && all_complete}}
                            .dump(2, ' ', false, kJsonReplaceInvalidUtf8)
                            .c_str());
  if (!result.ok()) return result.status();
  return Status::Ok();
}

Status RunSessionCheck(const std::string& dir, bool json) {
  FACEDYN_ASSIGN_OR_RETURN(const capture::SessionCheck check, capture::CheckSession(dir));
  if (json) {
    std::printf("%s\n", check.ToJson().dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
  } else {
    std::printf("%s", check.ToText().c_str());
  }
  if (!check.Complete()) {
    int incomplete = 0;
    for (const auto& take : check.takes) incomplete += !take.complete;
    return FailedPreconditionError(fmt::format(
        "session {}: {} of {} take(s) incomplete{}", dir, incomplete, check.takes.size(),
        check.events_problem.empty() ? "" : "; events.jsonl: " + check.events_problem));
  }
  return Status::Ok();
}

struct CalibrationImagesOptions {
  std::string config;
  std::string out;
  std::string board = "chessboard";
  int poses = 12;
  int seed = 1;
};

// Renders the calibration board at `poses` seeded poses in front of the cameras' common target
// with every camera of the config: <out>/cam<k>/pose<NNN>.png, plus the ground truth
// (cameras.yaml, board.json, poses.csv = world_from_board, corners.csv = every inner corner's
// true pixel, with visible = 0 when off the image).
Status RunCalibrationImages(const CalibrationImagesOptions& options) {
  FACEDYN_ASSIGN_OR_RETURN(const capture::CaptureConfig config,
                           capture::LoadCaptureConfig(options.config));
  if (config.cameras.empty())
    return InvalidArgumentError(options.config +
                                ": no camera models (give cameras.calibration or ring)");
  if (options.poses < 1 || options.poses > 1000)
    return InvalidArgumentError("--poses must be in 1..1000");
  sim::CalibrationBoard board;
  if (options.board == "charuco") {
    board.kind = sim::BoardKind::kCharuco;
  } else if (options.board != "chessboard") {
    return InvalidArgumentError("--board '" + options.board + "' is not chessboard or charuco");
  }
  sim::RenderOptions render;
  render.supersample = 3;
  render.blur_sigma_px = 0.6;
  render.read_noise_dn = 1.0;
  render.seed = static_cast<uint64_t>(options.seed);
  if (config.sim) {  // the capture config's sensor settings, where it has them
    auto sim_options = sim::ParseSimCaptureOptions(
        *config.sim, std::filesystem::path(config.source_path).parent_path().string());
    if (sim_options.ok()) {
      render.read_noise_dn = sim_options->render.read_noise_dn;
      render.shot_noise_gain = sim_options->render.shot_noise_gain;
      render.blur_sigma_px = sim_options->render.blur_sigma_px;
    }
  }
  const sim::BoardRenderer renderer(board, render);
  // The point all cameras look at: the least-squares intersection of their optical axes.
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const capture::CameraModel& camera : config.cameras) {
    const Eigen::Vector3d c = camera.CenterInWorld();
    const Eigen::Vector3d d =
        camera.cam_from_world.Inverse().RotateVector(Eigen::Vector3d::UnitZ());
    const Eigen::Matrix3d p = Eigen::Matrix3d::Identity() - d * d.transpose();
    a += p;
    b += p * c;
  }
  const Eigen::Vector3d target =
      config.cameras.size() > 1
          ? Eigen::Vector3d(a.ldlt().solve(b))
          : Eigen::Vector3d(config.cameras[0].CenterInWorld() +
                            800 * config.cameras[0].cam_from_world.Inverse().RotateVector(
                                      Eigen::Vector3d::UnitZ()));
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(options.out));
  FACEDYN_RETURN_IF_ERROR(
      capture::WriteCameraModels(JoinPath(options.out, "cameras.yaml"), config.cameras));
  FACEDYN_RETURN_IF_ERROR(WriteJsonFile(
      JoinPath(options.out, "board.json"),
      Json{
          {"kind", options.board},
          {"squares_x", board.squares_x},
          {"squares_y", board.squares_y},
          {"square_mm", board.square_mm},
          {"marker_mm", board.marker_mm},
          {"aruco_dictionary", "DICT_4X4_50"},
          {"inner_corners", {board.squares_x - 1, board.squares_y - 1}},
          {"frame", "origin at the outer corner of square (0,0); corners at (i, j) x square_mm"}}));
  std::mt19937_64 rng(static_cast<uint64_t>(options.seed));
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  // Upright board facing +Z (the cameras): board X = world X, board Y = world -Y.
  Eigen::Matrix3d facing;
  facing << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  const Eigen::Vector3d half(board.squares_x * board.square_mm / 2,
                             board.squares_y * board.square_mm / 2, 0);
  std::string poses_csv = "pose,qw,qx,qy,qz,tx,ty,tz\n";
  std::string corners_csv = "camera,pose,corner,u,v,visible\n";
  for (int k = 0; k < static_cast<int>(config.cameras.size()); ++k)
    FACEDYN_RETURN_IF_ERROR(MakeDirectories(JoinPath(options.out, "cam" + std::to_string(k))));
  for (int pose = 0; pose < options.poses; ++pose) {
    const Eigen::Matrix3d tilt = (Eigen::AngleAxisd(0.6 * unit(rng), Eigen::Vector3d::UnitY()) *
                                  Eigen::AngleAxisd(0.5 * unit(rng), Eigen::Vector3d::UnitX()) *
                                  Eigen::AngleAxisd(0.25 * unit(rng), Eigen::Vector3d::UnitZ()))
                                     .toRotationMatrix();
    const Eigen::Matrix3d rotation = tilt * facing;
    const Eigen::Vector3d centre =
        target + Eigen::Vector3d(40 * unit(rng), 30 * unit(rng), 60 * unit(rng));
    const Rigid3 world_from_board(Eigen::Quaterniond(rotation), centre - rotation * half);
    const Eigen::Quaterniond& q = world_from_board.rotation();
    const Eigen::Vector3d& t = world_from_board.translation();
    poses_csv += fmt::format("{},{:.12g},{:.12g},{:.12g},{:.12g},{:.9g},{:.9g},{:.9g}\n", pose,
                             q.w(), q.x(), q.y(), q.z(), t.x(), t.y(), t.z());
    for (int k = 0; k < static_cast<int>(config.cameras.size()); ++k) {
      const capture::CameraModel& camera = config.cameras[k];
      cv::Mat image(camera.height_px, camera.width_px, CV_8U);
      renderer.Render(camera, world_from_board,
                      (static_cast<uint64_t>(k) << 32) | static_cast<uint64_t>(pose), image.data);
      const std::string path = JoinPath(JoinPath(options.out, "cam" + std::to_string(k)),
                                        fmt::format("pose{:03d}.png", pose));
      if (!cv::imwrite(path, image)) return UnavailableError(path + ": cannot write the image");
      const std::vector<Eigen::Vector2d> corners =
          renderer.ProjectInnerCorners(camera, world_from_board);
      for (size_t c = 0; c < corners.size(); ++c) {
        const bool visible = std::isfinite(corners[c].x());
        corners_csv +=
            fmt::format("{},{},{},{:.4f},{:.4f},{}\n", k, pose, c, visible ? corners[c].x() : 0.0,
                        visible ? corners[c].y() : 0.0, visible ? 1 : 0);
      }
    }
  }
  FACEDYN_RETURN_IF_ERROR(WriteFileAtomic(JoinPath(options.out, "poses.csv"), poses_csv));
  FACEDYN_RETURN_IF_ERROR(WriteFileAtomic(JoinPath(options.out, "corners.csv"), corners_csv));
  spdlog::info("wrote {} poses x {} cameras of a {} board to {}", options.poses,
               config.cameras.size(), options.board, options.out);
  return Status::Ok();
}
}  // namespace

void AddCaptureCommands(CLI::App& app, CommandRunner* selected) {
  auto options = std::make_shared<CaptureCommandOptions>();
  auto* capture = app.add_subcommand(
      "capture", "Record a multi-view take (or one take per sweep step) into a session folder");
  capture->add_option("--config", options->config, "CAPTURE.yaml (config/capture/)")->required();
  capture->add_option("--session", options->session, "Session folder (created, or appended to)")
      ->required();
  capture->add_option("--take", options->take, "Take name (never overwritten)");
  capture->add_option("--sweep", options->sweep,
                      "SWEEP.yaml: record one take per sweep step instead");
  capture->add_flag("--resume", options->resume, "With --sweep: continue an interrupted sweep");
  capture->add_flag("--json", options->json, "Print the take report as JSON");
  capture->callback(
      [options, selected] { *selected = [options] { return RunCaptureCommand(*options); }; });

  auto* session = app.add_subcommand("session", "Capture session folders");
  session->require_subcommand(1);
  auto dir = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  auto* check = session->add_subcommand(
      "check", "Report which takes of a session are complete (exit 1 if any is not)");
  check->add_option("DIR", *dir, "Session folder")->required();
  check->add_flag("--json", *json, "JSON output");
  check->callback(
      [dir, json, selected] { *selected = [dir, json] { return RunSessionCheck(*dir, *json); }; });

  // Calibration images of the simulated cameras, under `facedyn sim` (registered before us).
  CLI::App* sim = nullptr;
  try {
    sim = app.get_subcommand("sim");
  } catch (const CLI::OptionNotFound&) {
    sim = app.add_subcommand("sim", "The simulated stage");
  }
  auto calibration = std::make_shared<CalibrationImagesOptions>();
  auto* images = sim->add_subcommand(
      "calibration-images",
      "Render a chessboard/ChArUco target at seeded poses with a capture config's cameras");
  images->add_option("--config", calibration->config, "CAPTURE.yaml whose cameras film the board")
      ->required();
  images
      ->add_option("--out", calibration->out, "Output folder: cam<k>/pose<NNN>.png + ground truth")
      ->required();
  images
      ->add_option("--board", calibration->board, "chessboard | charuco (10 x 7 squares of 20 mm)")
      ->capture_default_str();
  images->add_option("--poses", calibration->poses, "Number of board poses")->capture_default_str();
  images->add_option("--seed", calibration->seed, "Pose and noise seed")->capture_default_str();
  images->callback([calibration, selected] {
    *selected = [calibration] { return RunCalibrationImages(*calibration); };
  });
}

// ------------------------------------------------------------------------------- demo stage

Status RunCaptureDemoStage(const std::string& out_dir, bool quick, Json* metrics) {
  // A small simulated rig in code, so the demo needs no config files: 3 cameras (quick) or 8.
  capture::CameraRing ring;
  ring.count = quick ? 3 : 8;
  ring.width_px = quick ? 640 : 1280;
  ring.height_px = quick ? 512 : 1024;
  ring.focal_px = quick ? 1800 : 3600;
  ring.span_deg = quick ? 90 : 150;
  ring.k1 = -0.05;
  capture::CaptureConfig config;
  config.name = quick ? "demo-sim3" : "demo-sim8";
  config.source_path = "(demo)";
  config.fps = 128.0;
  config.duration_s = quick ? 0.25 : 1.0;
  config.exposure_us = 2000;
  config.cameras = ring.Cameras();
  config.sim = ConfigNode::Parse(
                   "{face: procedural, expression: smile, motion: platform, platform_hz: 8, "
                   "amplitude_mm: 2}",
                   "(demo sim)")
                   .value();
  FACEDYN_RETURN_IF_ERROR(config.Check());
  const std::string session_dir = JoinPath(out_dir, "capture-session");
  std::error_code ec;
  std::filesystem::remove_all(session_dir, ec);  // the demo's own folder, replaced each run
  FACEDYN_ASSIGN_OR_RETURN(auto session, OpenSession(config, session_dir));
  TakeInputs inputs;
  inputs.name = "smile_8hz";
  FACEDYN_ASSIGN_OR_RETURN(const TakeOutput output,
                           CaptureTake(config, session.get(), inputs, nullptr));
  FACEDYN_ASSIGN_OR_RETURN(const capture::SessionCheck check, capture::CheckSession(session_dir));
  std::printf("\nCapture: simulated %d-camera rig (%dx%d at %.0f fps), session %s\n", ring.count,
              ring.width_px, ring.height_px, config.fps, session_dir.c_str());
  PrintTake(inputs.name, output);
  std::printf("  session check: %s\n", check.Complete() ? "complete" : "INCOMPLETE");
  if (metrics != nullptr) {
    *metrics = TakeJson(output);
    (*metrics)["cameras"] = ring.count;
    (*metrics)["session"] = session_dir;
    (*metrics)["session_complete"] = check.Complete();
  }
  if (output.report.result.status != "complete" || !check.Complete()) {
    return InternalError("capture demo: the simulated take is incomplete: " +
                         output.report.result.reason);
  }
  return Status::Ok();
}

StatusOr<std::string> CaptureSimulatedTake(const capture::CaptureConfig& config,
                                           const std::string& session_dir,
                                           const std::string& take_name) {
  FACEDYN_RETURN_IF_ERROR(config.Check());
  if (config.backend != "sim" || !config.sim) {
    return InvalidArgumentError(config.source_path + ": not a simulated capture (backend sim)");
  }
  std::error_code ec;
  std::filesystem::remove_all(session_dir, ec);  // the caller's own folder, replaced each run
  FACEDYN_ASSIGN_OR_RETURN(auto session, OpenSession(config, session_dir));
  TakeInputs inputs;
  inputs.name = take_name;
  FACEDYN_ASSIGN_OR_RETURN(const TakeOutput output,
                           CaptureTake(config, session.get(), inputs, nullptr));
  PrintTake(inputs.name, output);
  if (output.report.result.status != "complete") {
    return InternalError("simulated take " + take_name +
                         " is incomplete: " + output.report.result.reason);
  }
  return output.report.take_dir;
}

}  // namespace facedyn::app
