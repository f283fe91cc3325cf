// Marker detections of a recorded take, read from a capture session folder
// (capture/session.h): every camera's frames matched by trigger index, checked for sync,
// and run through DetectMarkers.
//
// Bad input is reported per frame and does not stop the take: a camera with no frame for a
// trigger (dropped), a frame that cannot be read (corrupt record), a frame whose timestamp is
// more than half a frame period from the other cameras' median (out of sync) — that camera
// contributes nothing to that frame. A camera of the take without calibration, or whose frame
// file cannot be opened, is left out of the whole take (reported once).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/status.h"
#include "reconstruct/camera.h"
#include "reconstruct/marker_detection.h"
#include "reconstruct/triangulation.h"

namespace facedyn::reconstruct {

struct SessionInputOptions {
  std::string calibration_path;  // "" = the session's calibration.yaml
  MarkerDetectionOptions detection;
  Status Check() const;
};

struct SessionDetections {
  std::vector<Camera> cameras;  // the cameras used, calibrated
  double fps = 0.0;
  // The platform frequency the rig measured when the take started (capture.json
  // "platform.measured_hz_at_start", else its target_hz), when the take was on a platform: what
  // platform-synchronous quasistatic extraction needs (dynamics/quasistatic.h).
  std::optional<double> platform_hz;
  // From when (s from trigger 0) a held expression is held, when the capture recorded it
  // (capture.json "hold_start_s"): the take's held part for training and evaluation
  // (core/take.h TakeInfo::hold_start_s). Absent: every frame counts as held.
  std::optional<double> hold_start_s;
  // The cameras were head-mounted (capture.json "camera_mount": "head"): their calibration is in
  // the skull (helmet) frame (reconstruct/pipeline.h ReconstructionOptions::head_mounted).
  // Such takes are always detected without occlusion refits
  // (MarkerDetectionOptions::occlusion_refit, which is off by default anyway): close to the
  // face, neighbouring dots are foreshortened differently, which breaks the refit's premise
  // that neighbours share a shape. On the simulated HMC's 2 s dialogue (config/capture/hmc.yaml)
  // refits moved the reprojection RMS from 0.042 to 0.128 px and the markers' skull-frame RMS
  // against the truth from 0.088 to 0.273 mm.
  bool head_mounted = false;
  // detections[f][c]: frame f (trigger index f), camera c of `cameras`.
  std::vector<std::vector<std::vector<ImageObservation>>> detections;
  std::vector<std::vector<std::string>> frame_problems;  // per frame
  std::vector<std::string> take_problems;                // cameras left out, ...
  double detect_s = 0.0;
  // The detector's counters and per-stage CPU time summed over every image of the take (what
  // reconstruct_bench reports per image, here for a real session's images).
  MarkerDetectionSummary detection_totals;
  int64_t images_detected = 0;
};

StatusOr<SessionDetections> DetectSessionTake(const std::string& session_dir,
                                              const std::string& take_name,
                                              const SessionInputOptions& options);

}  // namespace facedyn::reconstruct
