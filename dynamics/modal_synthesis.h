// Modal synthesis: secondary dynamics from the skull's motion through a bank of fixed damped
// resonators and one linear map, fitted by ridge regression to decomposed takes. The
// alternative to the synthesis network H (synthesis_model.h) where a subject has few takes, as
// in retargeting (issue 20; Zoss et al. 2020, Figs. 9-10).
//
// Why. Soft tissue on a moving skull is, to first order, a linear time-invariant system driven
// by the inertial load of the skull's acceleration: in the skull frame each point feels
// -(a(t) + alpha(t) x r), with a the acceleration of the skull origin and alpha the angular
// acceleration, both in the skull frame (the centripetal term is second order at the
// platform's amplitudes). The response at a point is a sum of damped modes. H sees the skull's
// kinematics only through a short window of landmark velocities (B(t), +-0.08 s): a damped mode
// rings for longer than that (8.5 Hz with damping 0.17 decays by e in 0.11 s), and an MLP on a
// window wide enough to hold the ringing has hundreds of inputs per frame, which two or three
// takes of one subject cannot pin down. Measured with bench/retarget_bench (seeds 1-3, simulated
// takes, B trained on 5 platform takes and 2 walks): H_B trained on B's EXACT decomposition is
// 0.89 +- 0.27 mm from B's walk, no dynamics 0.58; this model, on the held mean, 0.083 +- 0.003
// (README, "Synthesis for new head motions and retargeting").
//
// The model. The six inertial inputs u(t) = [a(t) (mm/s^2); alpha(t) (rad/s^2)], skull frame,
// each scaled by its standard deviation over the training frames, are filtered by K
// second-order resonators r_k(s) = w_k^2 / (s^2 + 2 z w_k s + w_k^2) (unity gain at rest; Tustin
// with prewarping at each w_k). The regressors of a frame are, per input and resonator, the
// filtered value at t and t - 1 (together: the mode's displacement and velocity), the input
// itself (the instantaneous term) and a constant: P = 6 (2K + 1) + 1. The per-sample offsets
// dY(t) (3S, skull frame, mm) are dY(t) = W^T x(t), with W (P x 3S) the ridge solution
//
//   W = (X^T X + lambda mean(diag(X^T X)) I)^-1 X^T Y      (the constant column unpenalised)
//
// The resonator bank is fixed by rule (log-spaced across the band where faces ring, not fitted to
// any take), so the map is linear in W and the fit is one P x P solve, whatever S. The filters
// are causal and stable by construction: unlike an autoregressive fit, synthesis can never
// diverge. lambda is chosen from a list by leave-one-take-out validation (the model is meant for
// motions it never saw; validation blocks within a take chose ridges that only interpolate, and
// on one seed of bench/retarget_bench that model was 0.95 mm off B's walk where no dynamics is
// 0.56), or on validation blocks when there is one take; then W is refitted on every usable
// frame.
//
// What it does not model: the expression's effect on the dynamics (H's stretch input S(t)); it
// is a model of one subject's held face. Per-vertex offsets come from the samples by the
// propagation (propagation.h), learned from the training takes as for H.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/rigid3.h"
#include "core/status.h"
#include "core/take.h"
#include "dynamics/propagation.h"
#include "dynamics/removal_model.h"

namespace facedyn::dynamics {

// How the ridge is chosen from the validation errors of the grid (ModalSynthesisOptions::ridge).
enum class RidgeRule {
  kMinimum,  // the ridge with the least validation error
  // The largest ridge whose validation error is within one standard error (over the folds) of
  // the least (Hastie, Tibshirani and Friedman, The Elements of Statistical Learning, 2nd ed.,
  // section 7.10.1): with few folds the minimum is a noisy choice, and of the errors it cannot
  // tell apart the simplest model is preferred. Needs two folds or more (several takes); with
  // the blocks of a single take it is the minimum.
  kOneStandardError,
};
// "minimum", "one-standard-error"; and back (InvalidArgument listing them). RidgeRuleNames()
// lists every rule's name, for command-line validators.
const char* RidgeRuleName(RidgeRule rule);
std::vector<std::string> RidgeRuleNames();
StatusOr<RidgeRule> ParseRidgeRule(const std::string& name);

struct ModalSynthesisOptions {
  // Resonator natural frequencies (Hz), and their damping ratio. The defaults span 2-19 Hz in
  // log steps of 1.25x (faces ring at 5-15 Hz; the bank must also reach below the slowest mode
  // and above the fastest). Spacing and damping were chosen on an analytic case, not on any
  // take: a single damped mode (8.5 Hz, damping 0.17, between two lines of the bank) under a
  // broadband head motion it never saw (tests/dynamics/modal_synthesis_test), where this bank
  // leaves 4.2% RMS; 1.5x steps left 12% (damping 0.3) to 42% (0.1), 1.3x up to 22 Hz 4.9%.
  std::vector<double> resonator_hz = {2.0,   2.5,   3.125, 3.906, 4.883, 6.104,
                                      7.629, 9.537, 11.92, 14.90, 18.63};
  double resonator_damping = 0.3;
  // Ridge weights tried, relative to the mean diagonal of X^T X; ridge_rule picks one by the
  // validation errors.
  std::vector<double> ridge = {1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0};
  RidgeRule ridge_rule = RidgeRule::kMinimum;
  // With a single training take: the fraction of its usable frames validated, in blocks
  // (training_frames.h).
  double validation_fraction = 0.2;
  // Frames within this of a take's ends (or before its hold start) do not train: the
  // decompositions (moving average, platform fit, F) are least reliable there. Nor do the first
  // 1 / (resonator_damping 2 pi min(resonator_hz)) seconds (0.27 s by default), while the
  // resonators' state still depends on how they were started.
  double margin_s = 0.08;
  uint64_t seed = 1;  // the validation blocks' draw
  bool learn_propagation = true;
  PropagationLearnOptions propagation;
  // resonator_hz non-empty, each in (0, fps/2) at training time, damping in (0, 2], ridge
  // non-empty and each > 0, validation_fraction in (0, 0.9], margin_s in [0, 1]. Names the field.
  Status Check() const;
};

// The six inertial inputs per frame (6 x F): the skull origin's acceleration (mm/s^2) and the
// angular acceleration (rad/s^2), both in the skull frame, by central differences of the poses
// at `fps`. The two end frames repeat their neighbours (a clamped difference would read the
// take's cut as an impact). Errors: fps <= 0.
StatusOr<Eigen::MatrixXd> SkullInertialInputs(const std::vector<Rigid3>& world_from_skull,
                                              double fps);

struct ModalSynthesisFit {
  double chosen_ridge = 0.0;
  std::string validation;                 // "leave one take out" or "blocks of the one take"
  std::vector<double> validation_rms_mm;  // per ridge tried: RMS sample offset error
  // per ridge tried: sqrt of the mean over folds of (squared error / offsets' energy); the
  // ridge rule reads these
  std::vector<double> validation_relative;
  // per ridge tried: the standard error of that mean over the folds (before the sqrt: of the
  // folds' squared error / energy), 0 with fewer than two folds
  std::vector<double> validation_standard_error;
  RidgeRule ridge_rule = RidgeRule::kMinimum;  // the rule that chose
  long training_frames = 0;    // usable frames (the final fit uses all of them)
  long validation_frames = 0;  // frames held out in some fold
};

// Whether `path` starts with the modal model file's magic (so the CLI can take F, H and modal
// model files under one --model). False for a missing or short file.
bool IsModalModelFile(const std::string& path);

class ModalSynthesisModel {
 public:
  // Trains on decomposed takes (positions quasistatic, channel "dynamic_offset"), as
  // TrainSynthesis. Errors: no takes, a take without the channel or with positions that are
  // not quasistatic, rigs or frame rates that differ, no usable frame, bad options.
  static StatusOr<ModalSynthesisModel> Train(const std::vector<TrainingTake>& decomposed,
                                             const ModalSynthesisOptions& options,
                                             ModalSynthesisFit* fit = nullptr);

  // Per-sample offsets (3S x F, skull frame, mm) under a head motion.
  StatusOr<Eigen::MatrixXf> PredictSampleOffsets(const std::vector<Rigid3>& world_from_skull) const;

  // As SynthesizeDynamics (synthesis_model.h): the quasistatic take re-posed by the new head
  // motion plus the synthesised offsets; channels "quasistatic" and "dynamic_offset". Errors: a
  // rig whose samples or a take whose frame rate differ from the model's, a pose count that
  // differs from the frame count.
  StatusOr<Take> Synthesize(const Take& quasistatic, const std::vector<Rigid3>& world_from_skull,
                            const std::string& motion_name, const FaceRig& rig) const;

  // Removal by synthesis: the captured take minus the offsets this model predicts from the
  // take's own (estimated) head motion, Eq. 7 with d(t) from the skull's motion rather than from
  // the face's shape. A copy of `captured` whose positions are the quasistatic estimate and whose
  // only channel is "dynamic_offset" (skull frame, mm), as RemoveDynamics (removal_model.h), so
  // everything downstream of F takes it. What it cannot remove: dynamics the head motion does
  // not explain (the expression's own, and the part of the jiggle that depends on the
  // expression). Errors: as Synthesize.
  StatusOr<Take> Remove(const Take& captured, const FaceRig& rig) const;

  // Remove, then the skull-frame zero-phase low-pass (baselines.h) at
  // LowPassCutoffAfterRemoval(captured, validation_residual()): the filter takes only the share
  // of the jiggle this model is expected to leave on a motion it did not train on, so its cutoff
  // sits higher than the plain low-pass's and a performance keeps more of its own motion. The
  // take's metadata records the cutoff ("removal_lowpass_hz"), and so does *cutoff_hz if given.
  // Errors: as Remove.
  StatusOr<Take> RemoveThenLowPass(const Take& captured, const FaceRig& rig,
                                   double* cutoff_hz = nullptr) const;

  // The leave-one-take-out relative RMS error at the chosen ridge (ModalSynthesisFit's
  // validation_relative): what share of a new motion's jiggle the model is expected to miss. 1
  // when training had nothing to validate on.
  double validation_residual() const { return validation_residual_; }
  // Model file (binary, little-endian as written by this machine): "FDMODAL" magic and a NUL,
  // uint32 format version, the rig's name, fps, resonator frequencies and damping, the validation
  // residual, input scales,
  // sample count and samples hash, W, the learned propagation if any (method, V x S floats),
  // "END." trailer. Load checks every count against the ones before it and names what is
  // truncated or inconsistent (DataLoss starting with the path); applying a loaded model to
  // another rig fails by name as for a trained one.
  Status Save(const std::string& path) const;
  static StatusOr<ModalSynthesisModel> Load(const std::string& path);

  const std::string& rig_name() const { return rig_name_; }
  double fps() const { return fps_; }
  int sample_count() const { return sample_count_; }
  const std::vector<double>& resonator_hz() const { return resonator_hz_; }
  double resonator_damping() const { return resonator_damping_; }
  const Eigen::MatrixXd& weights() const { return weights_; }  // P x 3S

 private:
  Status CheckRig(const FaceRig& rig) const;
  // The regressors (P x F) of a head motion.
  StatusOr<Eigen::MatrixXd> Regressors(const std::vector<Rigid3>& world_from_skull) const;

  std::string rig_name_;
  double fps_ = 0.0;
  std::vector<double> resonator_hz_;
  double resonator_damping_ = 0.0;
  double validation_residual_ = 1.0;
  Eigen::VectorXd input_scale_;  // 6: the training inputs' standard deviations
  Eigen::MatrixXd weights_;      // P x 3S
  int sample_count_ = 0;
  uint64_t samples_hash_ = 0;
  std::optional<SamplePropagation> propagation_;
};

}  // namespace facedyn::dynamics
