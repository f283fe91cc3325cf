// CAPTURE.yaml: what `facedyn capture` records — frame rate, duration, exposure, the cameras
// (backend and calibration), the trigger, the recorder's queues and back-pressure policy, the
// sync tolerance, and optionally the platform (a RIG.yaml of the rig issue) to set and settle
// before recording. The `sim:` section is parsed by the simulator (sim/sim_capture.h); capture
// keeps it as a node so that this module does not depend on sim/.
//
//   name: sim8
//   fps: 128
//   duration_s: 2.0
//   exposure_us: 2000
//   pixel_format: mono8
//   trigger: {kind: virtual, pace: 0}          # pace 0: as fast as the cameras go
//   recorder: {queue_frames: 16, backpressure: block, block_timeout_s: 5, sync_on_close: true}
//   sync: {timestamp_tolerance_us: 100}
//   cameras:
//     backend: sim                              # sim | opencv | aravis
//     calibration: sim8_cameras.yaml            # OpenCV FileStorage YAML (capture/camera_model.h)
//     # or, instead of calibration, a ring of cameras around the subject:
//     ring: {count: 8, width_px: 1280, height_px: 1024, focal_px: 3600, distance_mm: 800,
//            span_deg: 150, elevation_deg: 10, target_mm: [0, -5, 60], k1: -0.08, k2: 0.02}
//     sources: [...]                            # opencv: files, /dev/videoN, GStreamer pipelines
//     devices: [...]                            # aravis: device ids ("Aravis-Fake-GV01", IP, ...)
//     size_px: [512, 512]                       # uncalibrated opencv/aravis cameras: the size only
//     mount: world                              # world (a stage rig) | head (head-mounted cameras:
//                                               # a helmet's, whose calibration frame moves with
//                                               # the skull; reconstruct then reads the markers in
//                                               # the skull frame and estimates no skull pose)
//   platform:
//     rig: ../rigs/sim-tcp.yaml                 # RIG.yaml (rig/rig_config.h)
//     start_simulated_drive: true               # serve the rig's simulated drive in-process
//     hz: 8
//     settle_timeout_s: 30
//     telemetry_period_s: 0.1                   # wall-clock period of rig reads during a take
//   sim: {...}
// Relative paths are resolved against the file's folder. Unknown fields are errors.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "capture/camera.h"
#include "capture/camera_model.h"
#include "capture/recorder.h"
#include "core/config_node.h"
#include "core/status.h"

namespace facedyn::capture {

// A ring of cameras on an arc around `target_mm`, all looking at it: camera k at azimuth
// -span/2 + k span/(count-1) about +Y from the +Z axis (the face looks along +Z), at the given
// elevation, alternating +-elevation/2 about it so the views are not coplanar.
struct CameraRing {
  int count = 8;
  int width_px = 1280;
  int height_px = 1024;
  double focal_px = 3600.0;
  double distance_mm = 800.0;
  double span_deg = 150.0;
  double elevation_deg = 10.0;
  Eigen::Vector3d target_mm{0.0, -5.0, 60.0};
  double k1 = 0.0;
  double k2 = 0.0;

  Status Check() const;
  std::vector<CameraModel> Cameras() const;
};

// Where the cameras are fixed: to the stage (the multi-view rig) or to the actor's head (a
// head-mounted camera, HMC). Recorded in capture.json as "camera_mount".
enum class CameraMount { kWorld, kHead };
const char* CameraMountName(CameraMount mount);

struct PlatformPlan {
  std::string rig_path;  // "" when the take does not set the platform
  bool start_simulated_drive = false;
  double hz = 8.0;
  double settle_timeout_s = 30.0;
  double telemetry_period_s = 0.1;
};

struct CaptureConfig {
  std::string name;
  std::string source_path;
  double fps = 128.0;
  double duration_s = 2.0;
  int exposure_us = 2000;
  PixelFormat pixel_format = PixelFormat::kMono8;
  double trigger_pace = 0.0;
  RecorderOptions recorder;
  int64_t timestamp_tolerance_ns = 100000;
  std::string backend = "sim";
  std::vector<CameraModel> cameras;  // from calibration or ring (sim), or sized from devices
  std::vector<CameraModel> uncalibrated_sizes;  // cameras.size_px: names and sizes only
  std::string calibration_path;                 // "" when the cameras came from a ring
  std::vector<std::string> sources;             // opencv
  std::vector<std::string> devices;             // aravis
  CameraMount mount = CameraMount::kWorld;
  PlatformPlan platform;
  std::optional<ConfigNode> sim;  // the sim: section, when present

  int64_t TriggerCount() const;
  CameraSettings SettingsFor(int camera) const;
  Status Check() const;
};

StatusOr<CaptureConfig> LoadCaptureConfig(const std::string& path);

}  // namespace facedyn::capture
