#include "capture/capture_config.h"

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>

#include "core/file_util.h"

namespace facedyn::capture {
namespace {

std::string Resolve(const std::string& base_dir, const std::string& path) {
  if (path.empty() || path[0] == '/') return path;
  return (std::filesystem::path(base_dir) / path).lexically_normal().string();
}

}  // namespace

Status CameraRing::Check() const {
  if (count < 1 || count > 64) return InvalidArgumentError("cameras.ring.count must be in 1..64");
  if (width_px < 16 || height_px < 16 || width_px > 16384 || height_px > 16384) {
    return InvalidArgumentError("cameras.ring.width_px/height_px must be in 16..16384");
  }
  if (!(focal_px > 0)) return InvalidArgumentError("cameras.ring.focal_px must be > 0");
  if (!(distance_mm > 50)) return InvalidArgumentError("cameras.ring.distance_mm must be > 50");
  if (!(span_deg >= 0 && span_deg <= 300))
    return InvalidArgumentError("cameras.ring.span_deg must be in 0..300");
  if (!(std::abs(elevation_deg) < 80))
    return InvalidArgumentError("cameras.ring.elevation_deg must be in (-80, 80)");
  if (!(std::abs(k1) < 1 && std::abs(k2) < 1))
    return InvalidArgumentError("cameras.ring.k1/k2 must be in (-1, 1)");
  return Status::Ok();
}

std::vector<CameraModel> CameraRing::Cameras() const {
  std::vector<CameraModel> cameras;
  for (int k = 0; k < count; ++k) {
    const double azimuth =
        (count == 1 ? 0.0 : -span_deg / 2 + k * span_deg / (count - 1)) * M_PI / 180;
    const double elevation =
        (elevation_deg + (k % 2 == 0 ? 0.5 : -0.5) * elevation_deg) * M_PI / 180;
    const Eigen::Vector3d direction(std::sin(azimuth) * std::cos(elevation), std::sin(elevation),
                                    std::cos(azimuth) * std::cos(elevation));
    CameraModel camera = CameraModel::LookAt("cam" + std::to_string(k), width_px, height_px,
                                             focal_px, target_mm + distance_mm * direction,
                                             target_mm, Eigen::Vector3d::UnitY());
    camera.intrinsics[4] = k1;
    camera.intrinsics[5] = k2;
    cameras.push_back(camera);
  }
  return cameras;
}

const char* CameraMountName(CameraMount mount) {
  return mount == CameraMount::kHead ? "head" : "world";
}

int64_t CaptureConfig::TriggerCount() const { return std::llround(fps * duration_s); }

CameraSettings CaptureConfig::SettingsFor(int camera) const {
  CameraSettings settings;
  if (camera < static_cast<int>(cameras.size())) {
    settings.width_px = cameras[camera].width_px;
    settings.height_px = cameras[camera].height_px;
  } else if (camera < static_cast<int>(uncalibrated_sizes.size())) {
    settings.width_px = uncalibrated_sizes[camera].width_px;
    settings.height_px = uncalibrated_sizes[camera].height_px;
  }
  settings.format = pixel_format;
  settings.exposure_us = exposure_us;
  settings.fps = fps;
  return settings;
}

Status CaptureConfig::Check() const {
  const std::string where = source_path + ": ";
  // kMaxTriggersPerTake (capture/frame.h) is 1000 fps x 3600 s: frame-file readers refuse any
  // trigger index beyond it, so raise it with these limits.
  if (!(fps >= 1 && fps <= 1000)) return InvalidArgumentError(where + "fps must be in 1..1000");
  if (!(duration_s > 0 && duration_s <= 3600))
    return InvalidArgumentError(where + "duration_s must be in (0, 3600]");
  if (TriggerCount() < 1) return InvalidArgumentError(where + "fps x duration_s gives no frames");
  if (exposure_us <= 0 || exposure_us > 1e6 / fps) {
    return InvalidArgumentError(where + "exposure_us must be in 1.." +
                                std::to_string(static_cast<int>(1e6 / fps)) +
                                " (the frame period)");
  }
  if (!(trigger_pace >= 0)) return InvalidArgumentError(where + "trigger.pace must be >= 0");
  if (timestamp_tolerance_ns < 0)
    return InvalidArgumentError(where + "sync.timestamp_tolerance_us must be >= 0");
  Status recorder_status = recorder.Check();
  if (!recorder_status.ok()) return recorder_status.WithContext(source_path);
  if (backend != "sim" && backend != "opencv" && backend != "aravis") {
    return InvalidArgumentError(where + "cameras.backend '" + backend +
                                "' is not one of sim, opencv, aravis");
  }
  if (backend == "sim" && cameras.empty())
    return InvalidArgumentError(where + "cameras: the sim backend needs calibration or ring");
  if (backend == "sim" && !sim)
    return InvalidArgumentError(where + "the sim backend needs a sim: section");
  if (backend == "opencv" && sources.empty())
    return InvalidArgumentError(where + "cameras.sources is empty");
  if (backend == "aravis" && devices.empty())
    return InvalidArgumentError(where + "cameras.devices is empty");
  if (backend != "sim") {
    const size_t count = backend == "opencv" ? sources.size() : devices.size();
    if (!cameras.empty() && cameras.size() != count) {
      return InvalidArgumentError(
          where + "cameras.calibration has " + std::to_string(cameras.size()) + " cameras for " +
          std::to_string(count) + " " + (backend == "opencv" ? "sources" : "devices"));
    }
    if (cameras.empty() && uncalibrated_sizes.size() != count) {
      return InvalidArgumentError(where +
                                  "cameras: give calibration or size_px [width, height] for the " +
                                  backend + " cameras");
    }
  }
  // Frame buffers are sized from these (width x height x bytes per pixel, per frame, per queue
  // slot), so a calibration or size_px claiming 100000 x 100000 px is refused here rather than
  // attempted as a 10 GB allocation per frame. Same caps as a frame file (capture/frame.h).
  for (const std::vector<CameraModel>* list : {&cameras, &uncalibrated_sizes}) {
    for (const CameraModel& camera : *list) {
      const std::string field = list == &cameras
                                    ? (calibration_path.empty() ? "cameras.ring" : calibration_path)
                                    : "cameras.size_px";
      if (camera.width_px < 1 || camera.width_px > kMaxFrameSidePx || camera.height_px < 1 ||
          camera.height_px > kMaxFrameSidePx) {
        return InvalidArgumentError(where + field + ": camera " + camera.name + " is " +
                                    std::to_string(camera.width_px) + "x" +
                                    std::to_string(camera.height_px) + " px, outside 1.." +
                                    std::to_string(kMaxFrameSidePx) + " a side");
      }
      // Both sides are at most 2^16 and a pixel at most 3 bytes: no wrap.
      const uint64_t bytes = uint64_t(camera.width_px) * uint64_t(camera.height_px) *
                             uint64_t(BytesPerPixel(pixel_format));
      if (bytes > kMaxFrameBytes) {
        return InvalidArgumentError(
            where + field + ": camera " + camera.name + " at " + std::to_string(camera.width_px) +
            "x" + std::to_string(camera.height_px) + " " + PixelFormatName(pixel_format) +
            " needs " + std::to_string(bytes) + " bytes a frame, more than " +
            std::to_string(kMaxFrameBytes));
      }
    }
  }
  if (!platform.rig_path.empty()) {
    if (!(platform.hz > 0)) return InvalidArgumentError(where + "platform.hz must be > 0");
    if (!(platform.settle_timeout_s > 0))
      return InvalidArgumentError(where + "platform.settle_timeout_s must be > 0");
    if (!(platform.telemetry_period_s > 0 && platform.telemetry_period_s <= 0.5)) {
      return InvalidArgumentError(
          where +
          "platform.telemetry_period_s must be in (0, 0.5] (it also feeds the drive's watchdog)");
    }
  }
  return Status::Ok();
}

StatusOr<CaptureConfig> LoadCaptureConfig(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode root, ConfigNode::ReadFile(path));
  if (!root.IsMap()) return root.Error("expected a map of capture settings");
  FACEDYN_RETURN_IF_ERROR(
      root.CheckFields({"name", "description", "fps", "duration_s", "exposure_us", "pixel_format",
                        "trigger", "recorder", "sync", "cameras", "platform", "sim"}));
  const std::string base_dir = std::filesystem::path(path).parent_path().string();
  CaptureConfig config;
  config.source_path = path;
  FACEDYN_ASSIGN_OR_RETURN(
      config.name, root.GetOr<std::string>("name", std::filesystem::path(path).stem().string()));
  FACEDYN_ASSIGN_OR_RETURN(config.fps, root.GetInRange("fps", 1, 1000));
  FACEDYN_ASSIGN_OR_RETURN(config.duration_s, root.GetInRange("duration_s", 1e-3, 3600));
  FACEDYN_ASSIGN_OR_RETURN(config.exposure_us, root.GetOr<int>("exposure_us", 2000));
  FACEDYN_ASSIGN_OR_RETURN(const std::string format,
                           root.GetOr<std::string>("pixel_format", "mono8"));
  auto parsed_format = ParsePixelFormat(format);
  if (!parsed_format.ok()) return root.Error("pixel_format", parsed_format.status().message());
  config.pixel_format = *parsed_format;
  if (root.Has("trigger")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode trigger, root.Child("trigger"));
    FACEDYN_RETURN_IF_ERROR(trigger.CheckFields({"kind", "pace"}));
    FACEDYN_ASSIGN_OR_RETURN(const std::string kind, trigger.GetOr<std::string>("kind", "virtual"));
    if (kind != "virtual")
      return trigger.Error("kind", "'" + kind +
                                       "': only 'virtual' is implemented (a hardware sync "
                                       "controller arrives with the rig's USB device)");
    FACEDYN_ASSIGN_OR_RETURN(config.trigger_pace, trigger.GetOr<double>("pace", 0.0));
  }
  if (root.Has("recorder")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode recorder, root.Child("recorder"));
    FACEDYN_RETURN_IF_ERROR(
        recorder.CheckFields({"queue_frames", "backpressure", "block_timeout_s", "sync_on_close"}));
    FACEDYN_ASSIGN_OR_RETURN(config.recorder.queue_frames, recorder.GetOr<int>("queue_frames", 16));
    FACEDYN_ASSIGN_OR_RETURN(const std::string policy,
                             recorder.GetOr<std::string>("backpressure", "block"));
    auto parsed = ParseBackpressurePolicy(policy);
    if (!parsed.ok()) return recorder.Error("backpressure", parsed.status().message());
    config.recorder.policy = *parsed;
    FACEDYN_ASSIGN_OR_RETURN(config.recorder.block_timeout_s,
                             recorder.GetOr<double>("block_timeout_s", 5.0));
    FACEDYN_ASSIGN_OR_RETURN(config.recorder.sync_on_close,
                             recorder.GetOr<bool>("sync_on_close", true));
  }
  if (root.Has("sync")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode sync, root.Child("sync"));
    FACEDYN_RETURN_IF_ERROR(sync.CheckFields({"timestamp_tolerance_us"}));
    FACEDYN_ASSIGN_OR_RETURN(const double tolerance_us,
                             sync.GetOr<double>("timestamp_tolerance_us", 100.0));
    config.timestamp_tolerance_ns = std::llround(tolerance_us * 1000);
  }
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode cameras, root.Child("cameras"));
  FACEDYN_RETURN_IF_ERROR(cameras.CheckFields(
      {"backend", "calibration", "ring", "sources", "devices", "size_px", "mount"}));
  FACEDYN_ASSIGN_OR_RETURN(config.backend, cameras.Get<std::string>("backend"));
  FACEDYN_ASSIGN_OR_RETURN(const std::string mount, cameras.GetOr<std::string>("mount", "world"));
  if (mount == "head") {
    config.mount = CameraMount::kHead;
  } else if (mount != "world") {
    return cameras.Error("mount", "'" + mount + "' is neither world nor head");
  }
  if (cameras.Has("calibration") && cameras.Has("ring"))
    return cameras.Error("give either calibration or ring, not both");
  if (cameras.Has("calibration")) {
    FACEDYN_ASSIGN_OR_RETURN(const std::string calibration,
                             cameras.Get<std::string>("calibration"));
    config.calibration_path = Resolve(base_dir, calibration);
    auto models = ReadCameraModels(config.calibration_path);
    if (!models.ok()) return cameras.Error("calibration", models.status().message());
    config.cameras = *models;
  } else if (cameras.Has("ring")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode ring_node, cameras.Child("ring"));
    FACEDYN_RETURN_IF_ERROR(
        ring_node.CheckFields({"count", "width_px", "height_px", "focal_px", "distance_mm",
                               "span_deg", "elevation_deg", "target_mm", "k1", "k2"}));
    CameraRing ring;
    FACEDYN_ASSIGN_OR_RETURN(ring.count, ring_node.GetOr<int>("count", ring.count));
    FACEDYN_ASSIGN_OR_RETURN(ring.width_px, ring_node.GetOr<int>("width_px", ring.width_px));
    FACEDYN_ASSIGN_OR_RETURN(ring.height_px, ring_node.GetOr<int>("height_px", ring.height_px));
    FACEDYN_ASSIGN_OR_RETURN(ring.focal_px, ring_node.GetOr<double>("focal_px", ring.focal_px));
    FACEDYN_ASSIGN_OR_RETURN(ring.distance_mm,
                             ring_node.GetOr<double>("distance_mm", ring.distance_mm));
    FACEDYN_ASSIGN_OR_RETURN(ring.span_deg, ring_node.GetOr<double>("span_deg", ring.span_deg));
    FACEDYN_ASSIGN_OR_RETURN(ring.elevation_deg,
                             ring_node.GetOr<double>("elevation_deg", ring.elevation_deg));
    FACEDYN_ASSIGN_OR_RETURN(ring.k1, ring_node.GetOr<double>("k1", ring.k1));
    FACEDYN_ASSIGN_OR_RETURN(ring.k2, ring_node.GetOr<double>("k2", ring.k2));
    if (ring_node.Has("target_mm")) {
      FACEDYN_ASSIGN_OR_RETURN(const std::vector<double> target,
                               ring_node.Get<std::vector<double>>("target_mm"));
      if (target.size() != 3) return ring_node.Error("target_mm", "expected [x, y, z]");
      ring.target_mm = Eigen::Vector3d(target[0], target[1], target[2]);
    }
    Status ring_status = ring.Check();
    if (!ring_status.ok()) return ring_node.Error(ring_status.message());
    config.cameras = ring.Cameras();
  }
  if (cameras.Has("sources")) {
    FACEDYN_ASSIGN_OR_RETURN(config.sources, cameras.Get<std::vector<std::string>>("sources"));
  }
  for (std::string& source : config.sources) {
    // Relative file paths are relative to the config; device nodes and pipelines stay as given.
    if (source.find('!') == std::string::npos && source.rfind("/dev/", 0) != 0 && !source.empty() &&
        std::isdigit(static_cast<unsigned char>(source[0])) == 0) {
      source = Resolve(base_dir, source);
    }
  }
  if (cameras.Has("devices")) {
    FACEDYN_ASSIGN_OR_RETURN(config.devices, cameras.Get<std::vector<std::string>>("devices"));
  }
  if (cameras.Has("size_px")) {
    // Uncalibrated hardware cameras: only the image size is known.
    if (!config.cameras.empty())
      return cameras.Error("size_px", "give size_px only without calibration or ring");
    FACEDYN_ASSIGN_OR_RETURN(const std::vector<int> size, cameras.Get<std::vector<int>>("size_px"));
    if (size.size() != 2 || size[0] < 1 || size[1] < 1)
      return cameras.Error("size_px", "expected [width, height]");
    const size_t count = config.backend == "opencv" ? config.sources.size() : config.devices.size();
    for (size_t k = 0; k < count; ++k) {
      CameraModel camera;
      camera.name = "cam" + std::to_string(k);
      camera.width_px = size[0];
      camera.height_px = size[1];
      config.uncalibrated_sizes.push_back(camera);
    }
  }
  if (root.Has("platform")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode platform, root.Child("platform"));
    FACEDYN_RETURN_IF_ERROR(platform.CheckFields(
        {"rig", "start_simulated_drive", "hz", "settle_timeout_s", "telemetry_period_s"}));
    FACEDYN_ASSIGN_OR_RETURN(const std::string rig, platform.Get<std::string>("rig"));
    config.platform.rig_path = Resolve(base_dir, rig);
    FACEDYN_ASSIGN_OR_RETURN(config.platform.start_simulated_drive,
                             platform.GetOr<bool>("start_simulated_drive", false));
    FACEDYN_ASSIGN_OR_RETURN(config.platform.hz, platform.Get<double>("hz"));
    FACEDYN_ASSIGN_OR_RETURN(config.platform.settle_timeout_s,
                             platform.GetOr<double>("settle_timeout_s", 30.0));
    FACEDYN_ASSIGN_OR_RETURN(config.platform.telemetry_period_s,
                             platform.GetOr<double>("telemetry_period_s", 0.1));
  }
  if (root.Has("sim")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode sim, root.Child("sim"));
    config.sim = sim;
  }
  FACEDYN_RETURN_IF_ERROR(config.Check());
  return config;
}

}  // namespace facedyn::capture
