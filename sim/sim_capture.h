// The simulated capture stage: the sim: section of a CAPTURE.yaml (capture/capture_config.h)
// turned into a simulated performance, a renderer and one SimCamera per calibrated camera, and
// the ground truth written beside the recorded frames.
//
//   sim:
//     face: procedural            # or a FaceRig folder (relative to the CAPTURE.yaml)
//     expression: neutral         # sim/expressions.h name, or speech
//     motion: platform            # platform | walk | run | jump | none | file:SKULL.csv
//     platform_hz: 8              # used when no platform: section sets the real frequency
//     amplitude_mm: 2
//     lead_in_s: 0.5              # simulated before trigger 0 (the motion fades in from rest)
//     markers: 80                 # optional: the painted layout, a count (the face's first N
//                                 # markers) or a file of marker names (core/face_rig.h
//                                 # SelectMarkerLayout); default every marker of the face
//     markers_max_view_angle_deg: 70  # optional: first keep only the markers every camera sees
//                                 # on the neutral face within this angle of the skin normal (a
//                                 # head-mounted camera's layout: two cameras see the front)
//     seed: 1
//     render: {read_noise_dn: 1.2, shot_noise_gain: 0.25, blur_sigma_px: 0.6,
//              motion_blur_samples: 1, supersample: 1, skin_albedo: 0.72, marker_albedo: 0.06,
//              background: 0.04, ambient: 0.22, gain: 1.0}
//     faults: {cam1: {drop: [3], duplicate: [5], late: [7], timestamp_offset_ns: 0}}
//
// Trigger k shows the skin at t = k / fps on the session clock: the performance is simulated
// from -lead_in_s and trimmed, so the platform is already oscillating in steady state when the
// take starts, as it is on the real stage after the rig has settled.
//
// Head-mounted cameras (CAPTURE.yaml cameras.mount: head): the camera models are in the skull
// (helmet) frame, so each camera renders the skin in the skull frame, world_from_skull(t)^-1 x:
// the helmet follows the head rigidly (a helmet that slips is not simulated).
//
// Ground truth, in <take>/ground_truth/:
//   take/            a Take (core/take.h): positions = dynamic skin, quasistatic.pc2 (exact),
//                    dynamic_offset.pc2, skull.csv = world_from_skull, on the trigger times
//   cameras.yaml     the exact camera models (capture/camera_model.h)
//   face/            the FaceRig (markers, regions) the images were rendered from; with a
//                    markers: layout, only those markers
//   render.json      render options, platform frequency, lead-in, seeds
#pragma once

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "capture/camera_model.h"
#include "capture/capture_config.h"
#include "core/config_node.h"
#include "core/face_rig.h"
#include "core/status.h"
#include "core/take.h"
#include "sim/performance.h"
#include "sim/virtual_camera.h"

namespace facedyn::sim {

struct SimCaptureOptions {
  std::string face = "procedural";
  PerformanceOptions performance;  // expression, motion (platform_hz, amplitude), seed
  double lead_in_s = 0.5;
  std::string markers;  // "" = every marker of the face, else a SelectMarkerLayout spec
  double markers_max_view_angle_deg = 0.0;  // > 0: MarkersSeenByEveryCamera first
  RenderOptions render;
  std::map<std::string, SimCameraFaults> faults;  // by camera name

  Status Check() const;
};

StatusOr<SimCaptureOptions> ParseSimCaptureOptions(const ConfigNode& node,
                                                   const std::string& base_dir);

struct SimulatedStage {
  FaceRig rig;
  std::shared_ptr<const Take> take;  // trimmed: frame k at t = k / fps
  // What the cameras see: `take` itself, or for head-mounted cameras its skin in the skull frame.
  std::shared_ptr<const Take> camera_take;
  std::shared_ptr<const FaceRenderer> renderer;
  std::vector<std::unique_ptr<SimCamera>> cameras;
  double platform_hz = 0.0;
  double simulate_s = 0.0;
  // When the prompted expression is held, in s from trigger 0 (HeldExpressionStartS less the
  // lead-in, at least 0); nullopt for speech. The stage's script, not its truth: the capture
  // writes it into capture.json as a session records when it prompted the actor.
  std::optional<double> hold_start_s;
};

// Simulates `triggers` frames at `fps` (plus the lead-in) with the platform at `platform_hz`
// (<= 0: the options' own), and builds the cameras, fixed to the world or to the head (`mount`).
StatusOr<SimulatedStage> PrepareSimulatedStage(
    const SimCaptureOptions& options, const std::vector<capture::CameraModel>& cameras, double fps,
    int64_t triggers, double platform_hz,
    capture::CameraMount mount = capture::CameraMount::kWorld);

// The rig's markers (in its order) that every camera sees on the neutral face (skull frame, the
// cameras' world at rest) in front of it, inside its image, within `max_angle_deg` of the skin's
// outward normal. Occlusion by other parts of the face is not tested.
std::vector<Marker> MarkersSeenByEveryCamera(const FaceRig& rig,
                                             const std::vector<capture::CameraModel>& cameras,
                                             double max_angle_deg);

// The painted layout `options` asks for on `rig` (markers_max_view_angle_deg with `cameras`,
// then the markers: spec), or every marker of the rig. Errors name the spec.
StatusOr<std::vector<Marker>> PaintedMarkers(const FaceRig& rig, const SimCaptureOptions& options,
                                             const std::vector<capture::CameraModel>& cameras);

// The take's skin (and quasistatic channel, if any) in the skull frame, world_from_skull set to
// identity: what a head-mounted camera sees.
Take TakeInSkullFrame(const Take& take);

Status WriteGroundTruth(const SimulatedStage& stage, const SimCaptureOptions& options,
                        const std::vector<capture::CameraModel>& cameras,
                        const std::string& take_dir);

// Drops the first `first_frame` frames of a take (positions, channels, skull, jaw) and
// re-times it so the new frame 0 is at t = 0.
Take TrimTake(const Take& take, int first_frame);

}  // namespace facedyn::sim
