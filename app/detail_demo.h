// The fine-detail stage of `facedyn demo` (issue 22, Masquerade): subject A's range of motion
// reconstructed on the multi-view rig trains the upsampler; a head-mounted-camera take (the
// simulated HMC of config/capture/hmc.yaml: a seated dialogue) is filmed through the capture
// path, reconstructed by the head-mounted path and upsampled; the result is scored against the
// simulator's skin beside the large-scale-only skin, and rendered for the report. It only wires
// detail/ (the method), reconstruct/ and the simulated capture; the truth is read only to score.
#pragma once

#include <cstdint>
#include <string>

#include "app/reconstruct_demo.h"
#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::app {

struct DetailDemoOptions {
  bool quick = false;
  uint64_t seed = 1;
  double rom_fps = 30.0;     // the range of motion lasts 10.7 s (every pose once)
  int rom_frames = 320;      // range-of-motion frames (Masquerade: 320)
  int global_frames = 80;    // greedy training frames (Masquerade: 80 of 320)
  double hmc_seconds = 2.0;  // the HMC take
  static DetailDemoOptions ForDemo(bool quick, uint64_t seed);
};

// Runs the stage into <out_dir>/detail (model, HMC session, takes) and <out_dir>/renders, and
// returns the figures: "training" (frames, markers, seconds), "hmc" (the filmed markers' error
// against their true positions, observed share, marker-frames filled), "methods" (face and lips
// mean and p95 vertex error in mm for "large_scale_only" and "masquerade", skull frame) and
// "images" (renders of one frame: truth, both results, and their signed error along the normal).
// Errors: no config folder with capture/hmc.yaml, a failed capture or reconstruction.
StatusOr<Json> RunDetailDemoStage(const FaceRig& face, const eval::SimulatedCameraRig& cameras,
                                  const DetailDemoOptions& options, const std::string& out_dir);

}  // namespace facedyn::app
