// The simulated stage's camera rig as the demo and the benches use it: the simulated 8-camera
// face rig calibrated from a simulated ChArUco board, and a simulated take reconstructed through
// reconstruct/'s pipeline from the markers' projected centres, or filmed: rendered and detected.
// Here, not in app/, so benches (bench/twin_bench) reconstruct takes by the same path as `facedyn
// demo`; it uses the simulator's truth (true cameras, true skin) to make the images' stand-in, and
// it gives the methods only what a capture has (calibrated cameras, 2D marker positions).
#pragma once

#include <cstdint>
#include <vector>

#include "core/face_rig.h"
#include "core/status.h"
#include "core/take.h"
#include "reconstruct/calibration.h"
#include "reconstruct/camera.h"
#include "reconstruct/pipeline.h"
#include "sim/virtual_camera.h"

namespace facedyn::eval {

// The simulated stage's 8-camera face rig: the true cameras (reconstruct/synthetic_views.h
// MakeFaceCameraRing, k1 = -0.06), which project the markers, and their calibration, which
// the reconstruction uses, expressed in the stage's world frame.
struct SimulatedCameraRig {
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
StatusOr<SimulatedCameraRig> CalibrateSimulatedCameraRig(int board_views, uint64_t seed);

// Reconstructs one simulated take as if filmed by `cameras`: the markers of `face` on every
// frame's dynamic skin (positions) projected through the true cameras with 0.2 px noise
// (projected, not rendered and detected, to keep the demo fast; detection on rendered images
// is measured by bench/reconstruct_bench), then reconstruct::ReconstructTake with the
// calibrated cameras (triangulation, tracking, skull pose, dense fit). The result's take
// carries the simulated take's expression, motion and platform frequency. Errors: an empty
// take, a take whose vertex count is not the face's, and the pipeline's own.
StatusOr<reconstruct::Reconstruction> ReconstructSimulatedTake(const FaceRig& face,
                                                               const SimulatedCameraRig& cameras,
                                                               const Take& simulated,
                                                               uint64_t seed);

// Wall time of filming's stages (seconds), for the caller's report.
struct FilmTimings {
  double render_s = 0.0;       // the 8 cameras' images, every frame
  double detect_s = 0.0;       // marker detection in them
  double reconstruct_s = 0.0;  // reconstruct::ReconstructTake on the detections
};

// Films one simulated take for real: every frame's dynamic skin rendered by the true cameras
// (sim::FaceRenderer: shaded skin, painted dots, lens distortion, blur, read and shot noise,
// self-occlusion), the dots detected in the images (reconstruct::DetectMarkersInImages, with
// the detector tuned to the dots' size at the face's distance), then reconstruct::ReconstructTake
// with the calibrated cameras, as `facedyn capture` + `facedyn reconstruct` would. The demo
// films every take it reconstructs this way (README: what it costs per frame). `render`
// defaults to
// config/capture/sim8.yaml's optics; `threads` 0 = every core. Errors: as
// ReconstructSimulatedTake, and a detection failure (naming the frame and camera).
struct FilmOptions {
  sim::RenderOptions render;
  int threads = 0;
  bool progress = false;           // a "film" progress bar on stderr (core/progress.h)
  FilmTimings* timings = nullptr;  // filled when given
};
StatusOr<reconstruct::Reconstruction> FilmSimulatedTake(const FaceRig& face,
                                                        const SimulatedCameraRig& cameras,
                                                        const Take& simulated, uint64_t seed,
                                                        const FilmOptions& options = FilmOptions());

}  // namespace facedyn::eval
