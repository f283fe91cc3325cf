// The physical-twin stage of `facedyn demo` (issue 23). Subject B of the dynamics stage has
// tissue the methods are not told (app/demo_dynamics.h: another cheek frequency and damping
// than the model's defaults). This stage
//   1. fits B's twin (physics/twin.h FitTwin) to B's reconstructed platform takes — markers and
//      skull pose only — and prints the fitted cheek mode (and body, from three frequencies)
//      beside the configured one (read only to score);
//   2. simulates the twin (its fitted material, as `facedyn twin perform` does) nodding and
//      shaking its head at frequencies and amplitudes of its own;
//   3. trains B's removal network with the twin's takes beside B's reconstructed ones, on the
//      twin's own exact quasistatic ("augmented", dynamics::TrainingTake), for as many optimiser
//      steps as the dynamics stage's F_B took on B's reconstructed takes alone ("captured");
//   4. films B nodding and shaking at a frequency and amplitude no training take has
//      (filmed: rendered by the 8 cameras, dots detected, like every demo take) and scores both
//      networks, and no removal, against B's exact quasistatic;
//   5. films B holding an expression lying back (gravity turned in the skull frame) and fits
//      the held frames with the blendshapes and with the twin (physics/twin_targeting.h),
//      scoring each fit's expression against the configured one.
// bench/twin_bench measures the same over seeds with more takes; this is the demo's one seed.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"
#include "core/take.h"
#include "dynamics/removal_model.h"
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
  // Section 5: the held expression, the lie-back angle and the take's length (the transition
  // takes sim::MotionOptions' lie_back_s; the held window starts 1 s after it).
  std::string targeting_expression = "smile";
  double lie_back_deg = 45.0;
  double lie_back_seconds = 3.0;
  double twin_seconds = 1.5;
  double test_seconds = 2.0;
  // One stiffness scale for all the tissue (DefaultStiffnessGroups() when false): the quick
  // demo's subject B has a single platform take, too little for three regions.
  bool single_group = false;
  double twin_weight = 1.0;
  // The platform's peak displacement as the demo's rig is configured (the simulator's default):
  // the twin fit is given it, as a studio's rig config gives it, to fit the body between
  // platform and skull (needs takes at three frequencies: not the quick demo's).
  double platform_amplitude_mm = sim::MotionOptions{}.amplitude_mm;
  uint64_t seed = 1;
  static TwinDemoOptions ForDemo(bool quick, uint64_t seed);
};

// The subject's removal network on its captured takes alone, as the dynamics stage trained it
// (app/demo_dynamics.h DemoDynamicsArtifacts): the augmented network is trained with the same
// targets for the captured takes, the same batch and the same number of optimiser steps.
struct CapturedRemoval {
  const dynamics::RemovalModel* model = nullptr;
  dynamics::RemovalTargets targets = dynamics::RemovalTargets::kPlatformSynchronousWhereKnown;
  long optimizer_steps = 0;
  int batch_size = 0;
  uint64_t seed = 1;
};

// Runs the stage for `subject` (its reconstructed takes `captured`: the platform ones fit the
// twin, all of them trained `captured_removal` and train the augmented F beside the twin's) and
// writes <out_dir>/models/twin_B.json. `true_tissue` is the
// subject's configured tissue: it makes the held-out takes and scores the fit, and never
// reaches a method. Returns {"fit": fitted vs configured cheek mode, "removal": per held-out
// take each method's jiggle_mean_mm, "training", "seconds"}. Errors: no platform take among
// `captured`, no model or steps < 1 or batch < 1 in `captured_removal`, and those of the fit, the
// training, the simulation and the reconstruction.
StatusOr<Json> RunTwinDemoStage(const FaceRig& subject, const physics::TissueOptions& true_tissue,
                                const std::vector<Take>& captured,
                                const CapturedRemoval& captured_removal,
                                const eval::SimulatedCameraRig& cameras,
                                const TwinDemoOptions& options, const std::string& out_dir);

}  // namespace facedyn::app
