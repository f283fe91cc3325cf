// The reconstruction stage of `facedyn demo`: simulated takes seen by the simulated 8-camera
// rig, calibrated once, reconstructed, and compared with the simulator's ground truth. The
// calibration and the per-take reconstruction are separate functions because the dynamics
// stage (app/demo_dynamics.h) reconstructs every take it trains on through the same path.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"
#include "core/take.h"
#include "reconstruct/calibration.h"
#include "reconstruct/camera.h"
#include "reconstruct/pipeline.h"

namespace facedyn::app {

// The demo's 8-camera face rig: the true cameras (reconstruct/synthetic_views.h
// MakeFaceCameraRing, k1 = -0.06), which project the markers, and their calibration, which
// the reconstruction uses, expressed in the stage's world frame.
struct DemoCameraRig {
  std::vector<reconstruct::Camera> truth;
  reconstruct::RigCalibration calibration;  // cameras in the stage's world frame
  double worst_centre_error_mm = 0.0;       // calibrated vs true camera centres
};

// Calibrates the rig from a ChArUco board (charuco:10x7:25:18) waved through it in
// `board_views` poses in front of the face: board corners projected through the true cameras
// with 0.2 px noise, then reconstruct::Calibrate (intrinsics + bundle adjustment). The
// calibration's world (camera 0) is brought into the stage's world by the rigid motion that
// best maps the calibrated camera centres onto the true ones (what surveying the rig once
// would give). Deterministic for a seed. Errors: board_views < 3, a failed calibration.
StatusOr<DemoCameraRig> CalibrateDemoCameraRig(int board_views, uint64_t seed);

// Reconstructs one simulated take as if filmed by `cameras`: the markers of `face` on every
// frame's dynamic skin (positions) projected through the true cameras with 0.2 px noise
// (projected, not rendered and detected, to keep the demo fast; detection on rendered images
// is measured by bench/reconstruct_bench), then reconstruct::ReconstructTake with the
// calibrated cameras (triangulation, tracking, skull pose, dense fit). The result's take
// carries the simulated take's expression, motion and platform frequency. Errors: an empty
// take, a take whose vertex count is not the face's, and the pipeline's own.
StatusOr<reconstruct::Reconstruction> ReconstructSimulatedTake(const FaceRig& face,
                                                               const DemoCameraRig& cameras,
                                                               const Take& simulated,
                                                               uint64_t seed);

// The stage: calibrates (60 board views, 30 with `quick`) into
// <out_dir>/reconstruct/calibration.yaml, reconstructs `simulated` into
// <out_dir>/takes/reconstructed (per-frame quality in <out_dir>/reconstruct/quality.json),
// prints and returns in *metrics (may be null) the errors against the simulator's truth after
// the first 0.5 s: calibration RMS (overall and per camera, "calibration_per_camera") and worst
// camera-centre error, skull origin and rotation error (RMS, max), 344-sample RMS, the
// correlation of the recovered dynamic offsets (reconstructed - true quasistatic) with the true
// ones (needs the take's "quasistatic" channel), and frames/s of each stage. The calibrated rig
// and the reconstructed take are returned in *cameras and *reconstructed (each may be null)
// for later stages.
Status RunReconstructDemoStage(const FaceRig& face, const Take& simulated,
                               const std::string& out_dir, bool quick, Json* metrics,
                               DemoCameraRig* cameras = nullptr, Take* reconstructed = nullptr);

}  // namespace facedyn::app
