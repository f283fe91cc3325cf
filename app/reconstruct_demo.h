// The reconstruction stage of `facedyn demo`: the simulated take seen by the simulated
// 8-camera rig, calibrated, reconstructed, and compared with the simulator's ground truth.
#pragma once

#include <string>

#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"
#include "core/take.h"

namespace facedyn::app {

// (1) Calibrates the 8-camera face rig (reconstruct/synthetic_views.h MakeFaceCameraRing,
//     k1 = -0.06) from a ChArUco board (charuco:10x7:25:18) waved through it: board corners
//     projected through the true cameras with 0.2 px noise, 60 views (30 with `quick`);
//     writes <out_dir>/reconstruct/calibration.yaml.
// (2) Marker detections of every frame of `simulated` (its dynamic skin, `face`'s markers)
//     projected through the true cameras with 0.2 px noise, reconstructed with the
//     calibrated cameras (triangulation, tracking, skull pose, dense fit); the take is saved
//     as <out_dir>/takes/reconstructed and its per-frame quality as
//     <out_dir>/reconstruct/quality.json.
// (3) Prints and returns in *metrics (may be null) the errors against the simulator's truth
//     after the first 0.5 s: calibration RMS and worst camera-centre error, skull origin and
//     rotation error (RMS, max), 344-sample RMS, the correlation of the recovered dynamic
//     offsets (reconstructed - true quasistatic) with the true ones (needs the take's
//     "quasistatic" channel), and frames/s of each stage.
// Detections are projected, not rendered and detected, to keep the demo fast; marker
// detection on rendered images is measured by bench/reconstruct_bench.
Status RunReconstructDemoStage(const FaceRig& face, const Take& simulated,
                               const std::string& out_dir, bool quick, Json* metrics);

}  // namespace facedyn::app
