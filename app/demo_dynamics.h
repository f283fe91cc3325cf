// The dynamics stage of `facedyn demo` (issue 8): Zoss et al. 2020's method run on RECONSTRUCTED
// takes, i.e. on what the capture stage would give, while the simulator keeps the exact truth
// the paper could only estimate.
//
//   1. Subject A (the demo's procedural face) holds expressions on the vibrating platform at the
//      training frequencies, and a neutral face while walking in place at other step rates than
//      the test walk's; every take is simulated, then filmed by the simulated 8-camera rig and
//      reconstructed
//      (app/reconstruct_demo.h, one calibration for all takes).
//   2. The removal network F is trained on the reconstructed takes with the paper's
//      moving-average targets (RemovalTargets::kMovingAverage: a reconstructed take has no exact
//      channel), and removes the dynamics of the held-out frequency's reconstructed take; the
//      result is compared with the simulator's exact quasistatic, next to the baselines (no
//      removal, low-pass, moving average) and to F trained on fewer frequencies (paper Fig. 5).
//      F also removes the dynamics of a performance (speech) at that frequency and of the test
//      walk (step 3's), filmed and reconstructed: its step rate is new, and its dynamics lie in
//      the band a low-pass must keep.
//   3. The synthesis network H is trained on the training takes decomposed by F (as in the
//      paper); remove-then-resynthesise residual on the held-out take (Fig. 7); and synthesis
//      for a new head motion never trained on: the held-out take's quasistatic shape carried
//      by a walk in place (sim/skull_motion.h kWalk), against subject A simulated walking.
//   4. Root-motion retargeting (Figs. 9-10): subject B, a procedural face of another shape
//      (scaled) and another tissue (fundamental frequency and damping), with its own F and H
//      trained on its own reconstructed takes; A's walk drives B's quasistatic through B's H,
//      compared with B simulated walking the same walk, next to NaiveDeltaTransfer of A's
//      offsets.
//
// It lives in app/ because it wires sim/ (data with truth), reconstruct/ (the capture path) and
// dynamics/ (the method); none of them may depend on another.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "app/reconstruct_demo.h"
#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"
#include "core/take.h"
#include "dynamics/modal_synthesis.h"
#include "dynamics/removal_model.h"
#include "physics/soft_tissue.h"

namespace facedyn::app {

struct DemoDynamicsOptions {
  // Subject A's training takes: every expression at every frequency (Hz). The held-out take
  // (passed to the stage) must be at a frequency not in this list.
  std::vector<double> train_hz = {6, 7, 8, 9, 10};
  std::vector<std::string> expressions = {"neutral", "smile"};
  // Subject B's training takes (its first expression must be "neutral": B's quasistatic for
  // the retargeting is taken from it). With only 7 and 9 Hz, B's H was worse than no dynamics
  // on the retargeted walk (0.92 vs 0.70 mm); with all five, 0.46.
  // B holds only the neutral face: its retargeting is of a neutral walk, and each take costs
  // about 40 s of the default demo's 20 minutes.
  std::vector<double> second_subject_hz = {6, 7, 8, 9, 10};
  std::vector<std::string> second_subject_expressions = {"neutral"};
  // Neutral walks in place at these step rates (steps/s), added to both subjects' training
  // takes: the paper trains on walking, running and jumping as well as the platform. The test
  // walk has another step rate and seed, so its head motion is new.
  std::vector<double> training_walk_step_hz = {1.5, 2.3};
  double test_walk_step_hz = 1.9;
  // A changing expression filmed on the held-out frequency (a performance, never trained on):
  // F is also tested on it. Empty: skip.
  std::string performance_expression = "speech";
  double seconds = 1.5;       // per training take
  double walk_seconds = 2.0;  // the new head motion
  // F's training targets (dynamics/removal_model.h). A capture has no exact quasistatic: the
  // default fits the platform takes at their recorded frequency and takes each walk's held mean
  // (chosen on the quick demo's validation seeds 101-103 over platform-synchronous-where-known,
  // whose walks kept the moving average: F's walk error 0.317 +- 0.013 against 0.394 +- 0.012 mm,
  // the held 11 Hz and speech takes tied; README, "F's targets on walks").
  dynamics::RemovalTargets removal_targets =
      dynamics::RemovalTargets::kPlatformSynchronousElseHeldMean;
  int removal_epochs = 20;
  // F's mini-batch. The paper's 10,000 leaves a 10-epoch F under-trained (about 70 steps per
  // epoch on the demo's data); 2,000 gives five times the steps for about the same time.
  int removal_batch = 2000;
  int synthesis_epochs = 30;  // the paper's; H sees one row per frame, so it is cheap
  // F_B only decomposes subject B's training takes for H_B, so it gets fewer epochs than F.
  int second_subject_removal_epochs = 10;
  // Paper Fig. 5: F also trained on the first 1 .. n-1 training frequencies (0: skip).
  int subset_epochs = 3;
  // Joint F/H training with the cycle loss (dynamics/joint_training.h; issue 20): subject A
  // also performs `training_performance_expression` on the platform at these frequencies
  // (each a training frequency; filmed and reconstructed like every take, and read without a
  // target), and F_joint and H_joint are F and H fine-tuned together with the cycle on them.
  // Scored beside F and H on every held-out take. Empty: no joint training.
  std::vector<double> training_performance_hz;
  std::string training_performance_expression = "speech";
  int joint_steps = 2000;           // dynamics::JointTrainOptions::joint.steps
  double joint_cycle_weight = 1.0;  // joint.pair_weight (chosen on dynamics_bench's validation)
  // joint.keep_least_validation: keep the joint report of least validation objective.
  bool joint_early_stopping = false;
  // !joint.pair_trains_second: the cycle's gradient reaches F only (H then fine-tunes on its
  // own supervised loss alone and teaches F on the performances).
  bool joint_cycle_trains_f_only = false;
  // How both subjects' modal models choose their ridge (dynamics/modal_synthesis.h).
  dynamics::RidgeRule modal_ridge_rule = dynamics::RidgeRule::kMinimum;
  uint64_t seed = 1;
  // Subject B: procedural face scaled by this per axis (skull frame, x = width, y = height,
  // z = depth), tissue with this fundamental and damping (physics/soft_tissue.h TissueOptions).
  double second_subject_scale_x = 0.92;
  double second_subject_scale_y = 1.06;
  double second_subject_scale_z = 0.96;
  double second_subject_fundamental_hz = 8.5;
  double second_subject_damping_ratio = 0.17;

  // The demo's settings: quick (under 5 minutes with everything else on 2 cores) or default
  // (under 20).
  static DemoDynamicsOptions ForDemo(bool quick);
  // At least two training frequencies in 0.5..30, at least one expression, the second subject's
  // first expression "neutral", seconds and walk_seconds >= 1, epochs >= 1 (subset_epochs
  // >= 0), scales in [0.7, 1.3], fundamental in 3..30 Hz, damping in (0, 1], training
  // performances at training frequencies with an expression named, joint_steps >= 1 and the
  // cycle weight finite and >= 0. Names the field.
  Status Check() const;
};

// What the stage made, for the renders (all takes of subject A unless named).
struct DemoDynamicsArtifacts {
  Take test_simulated;        // held-out take as simulated (channels quasistatic, dynamic_offset)
  Take test_reconstructed;    // the same take reconstructed from the simulated cameras
  Take test_removed;          // F's removal of the reconstructed take
  Take test_resynthesised;    // H on test_removed with the take's own head motion
  Take walk_truth;            // A simulated walking (exact channels)
  Take walk_synthesised;      // H: A's quasistatic estimate carried by the walk
  double walk_step_hz = 0.0;  // the test walk's step rate
  FaceRig second_face;        // subject B
  // B's configured tissue (the simulator's; for making and scoring B's takes only) and B's
  // reconstructed training takes (platform and walks), for the twin stage (app/twin_demo.h).
  physics::TissueOptions second_subject_tissue;
  std::vector<Take> second_subject_reconstructed;
  // B's removal network F_B as the dynamics stage trained it on second_subject_reconstructed,
  // with its targets, optimiser steps and batch: the twin stage's "captured" F, which the
  // augmented F matches step for step (so F_B is not trained twice).
  std::optional<dynamics::RemovalModel> second_subject_removal;
  dynamics::RemovalTargets second_subject_removal_targets =
      dynamics::RemovalTargets::kPlatformSynchronousWhereKnown;
  long second_subject_removal_steps = 0;
  int second_subject_removal_batch = 0;
  Take retarget_truth;    // B simulated walking A's walk
  Take retargeted;        // B's H on B's quasistatic under A's walk
  Take naive;             // NaiveDeltaTransfer of A's walk offsets onto B
  Take retargeted_modal;  // B's modal synthesis (dynamics/modal_synthesis.h) under A's walk
  // The performance on the held-out frequency (options.performance_expression; empty takes when
  // there is none): as simulated (exact channels), reconstructed, and after F's removal.
  Take performance_simulated;
  Take performance_reconstructed;
  Take performance_removed;
};

// Runs the stage for subject `face` (A) with the calibrated `cameras`; `test_simulated` and
// `test_reconstructed` are the held-out take (the reconstruction stage's). Writes model files
// under <out_dir>/models, prints progress and tables, and returns the figures in *metrics:
// "setup", "reconstruction" (per take), "removal" (held-out take: every method's face mean,
// p95, max and mean over the jiggling vertices, the reconstruction's own error and
// "perfect_removal_mm", the floor the estimated skull pose sets for every method),
// "removal_performance" (the same for a changing expression at that frequency), "removal_walk"
// (the same for the test walk, reconstructed: a step rate no training walk has),
// "removal_by_training_frequencies" (Fig. 5), "synthesis" ("resynthesis", "walk"), "retarget" and
// "training". `reference_removal` (may be null) is another removal model for A's rig, reported as
// "F_exact_targets_simulated" (e.g. the simulated-data study's). *artifacts may be null.
Status RunDemoDynamicsStage(const FaceRig& face, const eval::SimulatedCameraRig& cameras,
                            const Take& test_simulated, const Take& test_reconstructed,
                            const DemoDynamicsOptions& options, const std::string& out_dir,
                            const dynamics::RemovalModel* reference_removal, Json* metrics,
                            DemoDynamicsArtifacts* artifacts);

// Renders of the stage's artifacts coloured by signed dynamic offset (report/face_render.h), PNGs
// under <out_dir>/renders: the held-out take at two extremal frames (reconstructed and after
// removal, each minus the exact quasistatic; resynthesised minus removed), the walk (H's
// synthesised offsets and the simulated truth's) and the retargeting (B's H, the naive
// transfer, the truth); colour saturates at +-5 mm for the held-out take and +-2 mm for the
// walks, as in the paper's figures. Returns {"range_mm" (the largest), "groups": [{group,
// range_mm}], "images": [{group, range_mm, frame, view, path, max_abs_offset_mm}], "viewers":
// [{title, path, megabytes}]} (browser pages under <out_dir>/viewers: the held-out removal and
// the retargeting, one second each). Errors: a file that cannot be written.
StatusOr<Json> RenderDemoDynamics(const FaceRig& face, const DemoDynamicsArtifacts& artifacts,
                                  const std::string& out_dir);

}  // namespace facedyn::app
