// The dynamics validation protocols of Zoss et al. 2020 run end to end on simulated takes, where
// the simulator's exact quasistatic lets facedyn measure what the paper could only estimate:
//
//   - removal (paper Fig. 5): F trained on held-expression platform takes at some frequencies,
//     tested on a frequency never seen, and on a speech take with changing expression;
//   - synthesis (paper Fig. 7): H trained on decomposed takes, then remove-and-resynthesise an
//     unseen take and measure the residual against the original;
//   - speed: training rows/s next to the machine's LibTorch GEMM rate, removal + propagation
//     frames/s.
//
// Run by bench/dynamics_bench on simulated takes with the exact skull; `facedyn demo` runs the
// same protocols on reconstructed takes (app/demo_dynamics.cc, scoring from eval/). It lives in
// eval/ because it wires sim/ (the data) to dynamics/ (the method); neither module may depend
// on the other.
#pragma once

#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"
#include "core/take.h"
#include "dynamics/removal_model.h"

namespace facedyn::eval {

struct DynamicsStudyOptions {
  std::vector<double> train_hz = {6, 7, 8, 9, 10};
  double test_hz = 11.0;
  std::vector<std::string> expressions = {"neutral", "smile", "jaw_open"};
  // Platform amplitudes (peak, mm) of the training takes: one take per frequency, expression
  // and amplitude (speech takes too). Several amplitudes per frequency are the data diversity
  // the paper's captures have and one simulated take per condition lacks: the head's velocity
  // and acceleration at the test frequency then lie inside the training range instead of beyond
  // it (the body transmits less at higher frequencies, see sim/skull_motion.h), and F sees that
  // the offsets scale with the excitation. The first amplitude's takes keep the seeds of a
  // one-amplitude study, so {2.0} reproduces it exactly; the others get seeds of their own.
  std::vector<double> train_amplitudes_mm = {2.0};
  double test_amplitude_mm = 2.0;  // platform amplitude of every test take
  double seconds = 2.0;            // per simulated take
  double fps = 128.0;
  double window_s = 0.08;  // feature half-window of both networks (the paper's 10 frames)
  int vertices = 4000;     // procedural face size
  double speech_hz = 8.0;  // platform frequency of the speech test take; <= 0: no speech test
  // Held-out expression: test takes of expressions no training take holds (none may be in
  // `expressions`), on the platform at held_out_expression_hz — a training frequency by
  // default, so that only the expression is new.
  std::vector<std::string> held_out_expressions = {"pucker"};
  double held_out_expression_hz = 8.0;
  // Held-out motion kind: neutral test takes under head motions no training take has ("walk",
  // "run", "jump"; walk and run in place: forward speed changes nothing for the tissue, but the
  // skull descriptor holds velocities and would put the take far outside the platform takes).
  std::vector<std::string> held_out_motions = {"walk", "run"};
  // Also train F (exact targets) and H on speech takes at every training frequency (other seeds
  // than the test take's). Only the simulator can give exact targets for a changing expression;
  // the paper's moving-average targets exist for held expressions only, so F_moving_average
  // never sees these takes.
  bool train_speech = true;
  double final_learning_rate_fraction = 0.05;  // learning-rate decay of both networks (mlp.h)
  int removal_epochs = 40;
  int removal_batch = 10000;             // the paper's
  int removal_hidden_units = 128;        // width of F's two hidden layers (the paper's 128)
  double removal_weight_decay = 0.0;     // decoupled weight decay of F's training (mlp.h)
  double removal_input_noise_std = 0.0;  // noise on F's normalised training inputs (mlp.h)
  bool removal_linear_skip = true;       // F plus a linear map of its inputs (mlp.h)
  double learning_rate = 1e-3;           // Adam, both networks (the paper's)
  int synthesis_epochs = 30;             // the paper's
  int synthesis_batch = 50;              // the paper's
  bool moving_average_targets = true;    // also train F on the paper's moving-average targets
  // Also train F on platform-synchronous targets (quasistatic.h; held takes only, like the
  // moving average), and report that filter itself as a method beside the baselines.
  bool platform_targets = true;
  bool synthesis = true;
  // Also train F and H together (dynamics/joint_training.h), "F_joint": F on the held takes'
  // platform-synchronous targets (as F_platform_targets, the same seed), H on its
  // decomposition, then the cycle on the training speech takes, which give their positions and
  // poses only (train_speech must be on). What a capture session can do with performances it
  // has no target for; F_platform_targets is the same F without them.
  bool joint = false;
  long joint_steps = 2000;          // learn::MlpPairTrainOptions::steps
  double joint_cycle_weight = 1.0;  // learn::MlpPairTrainOptions::pair_weight
  double joint_learning_rate = 1e-4;
  // Keep the joint phase's report of least validation objective (F's and H's held-out losses
  // plus the cycle's on held-out performance frames; MlpPairTrainOptions::keep_least_validation).
  bool joint_keep_least_validation = false;
  // Propagation of each network: learned from its training offsets (propagation.h) or the
  // rig's Laplacian.
  bool removal_learned_propagation = true;
  bool synthesis_learned_propagation = true;
  double propagation_prior_weight = 1e-3;  // PropagationLearnOptions::prior_weight, both
  // Paper Fig. 5: also train F (exact targets) on the first 1, 2, ... n-1 training frequencies
  // and test each on the first test take; the full set is the main model.
  bool frequency_subsets = false;
  int subset_epochs = 0;  // epochs of the subset models; 0: removal_epochs
  int threads = 0;        // LibTorch threads; 0: leave
  uint64_t seed = 1;
  bool show_progress = true;
  // Frequencies in 0.5..30, amplitudes in (0, 50], at least one expression and amplitude,
  // seconds >= 0.5, vertices 4000..10000, epochs, batches and hidden units >= 1, weight decay
  // and input noise >= 0. The message names the field.
  Status Check() const;
};

// Runs the study; the JSON has "setup", "removal" (per test take: its "protocol" — held-out
// frequency, held-out performance, held-out expression, held-out motion kind — each method's
// mean, p95, max error over the face and the mean error over the jiggling vertices relative to
// the mean true dynamic offset there), "synthesis" and "training" sections. Progress on the terminal.
// What the study made, for renders: the rig, the first test take (dynamic, with the exact
// quasistatic and dynamic_offset channels), its removal by F (exact targets) and, when synthesis
// ran, its resynthesis by H under its own head motion.
struct DynamicsStudyArtifacts {
  FaceRig rig;
  Take test_take;
  Take removed;
  Take resynthesised;
  dynamics::RemovalModel removal_model;  // F trained on exact targets
};

StatusOr<Json> RunDynamicsStudy(const DynamicsStudyOptions& options,
                                DynamicsStudyArtifacts* artifacts = nullptr);

}  // namespace facedyn::eval
