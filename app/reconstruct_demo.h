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
#include "eval/simulated_stage.h"

namespace facedyn::app {

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
                               eval::SimulatedCameraRig* cameras = nullptr, Take* reconstructed = nullptr);

}  // namespace facedyn::app
