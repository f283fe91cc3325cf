// The physical-twin stage of `facedyn demo` (issue 23). Subject B of the dynamics stage has
// tissue the methods are not told (app/demo_dynamics.h: another cheek frequency and damping
// than the model's defaults). This stage
//   1. fits B's twin (physics/twin.h FitTwin) to B's reconstructed platform takes — markers and
//      skull pose only — and prints the fitted cheek mode beside the configured one (read only
//      to score);
//   2. simulates the twin (its fitted material, as `facedyn twin perform` does) nodding and
//      shaking its head at frequencies and amplitudes of its own;
//   3. trains two removal networks for B on the same budget of optimiser steps: on B's
//      reconstructed takes alone ("captured") and with the twin's takes beside them on the
//      twin's own exact quasistatic ("augmented", dynamics::TrainingTake);
//   4. films B nodding and shaking at a frequency and amplitude no training take has
//      (reconstructed from projected marker centres, like every demo take) and scores both
//      networks, and no removal, against B's exact quasistatic.
// bench/twin_bench measures the same over seeds with more takes; this is the demo's one seed.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"
#include "core/take.h"
#include "eval/simulated_stage.h"
#include "physics/soft_tissue.h"
#include "sim/skull_motion.h"

namespace facedyn::app {

struct TwinDemoOptions {
  // A head rotation of the subject or the twin: nod or shake at hz with deg peak.
  struct HeadMotion {
    sim::MotionKind kind = sim::MotionKind::kNod;
    double hz = 2.0;
    double deg = 15.0;
  };
  // The subject's held-out takes (each differs from every twin motion in frequency and
  // amplitude) and the twin's training motions.
  std::vector<HeadMotion> test_motions = {{sim::MotionKind::kNod, 2.2, 12.0},
                                          {sim::MotionKind::kShake, 1.8, 16.0}};
  std::vector<HeadMotion> twin_motions = {{sim::MotionKind::kNod, 1.4, 8.0},
                                          {sim::MotionKind::kNod, 3.0, 20.0},
                                          {sim::MotionKind::kShake, 1.2, 10.0},
                                          {sim::MotionKind::kShake, 2.6, 22.0}};
  double twin_seconds = 1.5;
  double test_seconds = 2.0;
  // One stiffness scale for all the tissue (DefaultStiffnessGroups() when false): the quick
  // demo's subject B has a single platform take, too little for three regions.
  bool single_group = false;
  int removal_epochs = 10;
  int removal_batch = 2000;
  double twin_weight = 1.0;
  uint64_t seed = 1;
  static TwinDemoOptions ForDemo(bool quick, uint64_t seed);
};

// Runs the stage for `subject` (its reconstructed takes `captured`: the platform ones fit the
// twin, all of them train F) and writes <out_dir>/models/twin_B.json. `true_tissue` is the
// subject's configured tissue: it makes the held-out takes and scores the fit, and never
// reaches a method. Returns {"fit": fitted vs configured cheek mode, "removal": per held-out
// take each method's jiggle_mean_mm, "training", "seconds"}. Errors: no platform take among
// `captured`, and those of the fit, the simulation and the reconstruction.
StatusOr<Json> RunTwinDemoStage(const FaceRig& subject, const physics::TissueOptions& true_tissue,
                                const std::vector<Take>& captured,
                                const eval::SimulatedCameraRig& cameras,
                                const TwinDemoOptions& options, const std::string& out_dir);

}  // namespace facedyn::app
