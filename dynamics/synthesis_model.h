// The synthesis network H of Zoss et al. 2020, section 6: all sample offsets of a frame jointly
// from the skull's kinematic history and the current expression,
//
//   dY(t) = H(B(t), S(t)),   x_i(t) = T(t) (T_q(t)^-1 y_i(t) + dy_i(t))
//
// with B(t) the skull descriptor of the (new) head motion T (Eq. 1-2), S(t) the per-sample uv
// stretch of the quasistatic skin y against the neutral (Eq. 8), and T_q the poses the
// quasistatic take was given in. Two hidden layers of 256 with ReLU, L2 loss, Adam 1e-3, batch
// 50, 30 epochs (the paper's settings as defaults). Normalisation lives in the model (mlp.h).
//
// Training pairs are "decomposed" takes: positions = a quasistatic performance y, channel
// "dynamic_offset" = its secondary dynamics dx (skull frame). The paper obtains them by running
// the removal network F on captured takes (RemoveDynamics output is exactly such a take); the
// simulator can give the exact decomposition (DecomposeExact).
//
// Root-motion retargeting (paper Figs. 9-10) is synthesis on the target subject's quasistatic
// performance with the source's skull trajectory; NaiveDeltaTransfer is the baseline of
// Fig. 10(b), copying the source's per-sample offsets onto the target.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/rigid3.h"
#include "core/status.h"
#include "core/take.h"
#include "dynamics/feature_spec.h"
#include "dynamics/propagation.h"
#include "dynamics/removal_model.h"
#include "learn/mlp.h"

namespace facedyn::dynamics {

struct SynthesisConfig : FeatureSpec {
  int hidden_units = 256;
  bool linear_skip = false;  // learn::MlpShape::linear_skip

  static SynthesisConfig ForRig(const FaceRig& rig, double fps);
  int input_size() const { return skull_descriptor_size() + 2 * sample_count; }
  int output_size() const { return 3 * sample_count; }
  Status Check() const;
};

class SynthesisModel {
 public:
  static StatusOr<SynthesisModel> Create(const SynthesisConfig& config, uint64_t seed);
  static StatusOr<SynthesisModel> Load(const std::string& path);
  Status Save(const std::string& path) const;

  const SynthesisConfig& config() const { return config_; }
  Status CheckCompatible(const Take& take, const FaceRig& rig) const {
    return config_.CheckCompatible(take, rig);
  }
  // Raw features (input_size x F, columns = [B(t); S(t)]) -> dY (3S x F, skull frame, mm), with
  // the stretch rows S(t) clamped to stretch_range() when the model has one.
  Eigen::MatrixXf Predict(const Eigen::MatrixXf& features) const;
  // The features with their stretch rows clamped as Predict does (unchanged without a range).
  Eigen::MatrixXf ClampStretch(const Eigen::MatrixXf& features) const;

  // Per stretch feature (2 x 2S: row 0 the minimum, row 1 the maximum) the range over the
  // training takes' usable frames, kept by TrainSynthesis; empty for a model without one (made
  // by Create, or saved before it was kept). H learns the expression's effect on the dynamics
  // only over the expressions it saw. Beyond them an MLP extrapolates without bound: an H
  // trained on held neutral takes resynthesised a talking take with 2.9-5.1 mm of residual
  // where the true offset was 1.1 mm (`facedyn demo --quick --seeds 1,2,3` at 4a08148, Fig. 7
  // on speech). Clamped, it is given the nearest expression it knows instead; the skull
  // descriptor B(t) is not clamped (a larger motion is the physics' to extrapolate, not an
  // unknown face).
  const Eigen::MatrixXf& stretch_range() const { return stretch_range_; }
  // Precondition (checked): 2 x 2S with min <= max, or empty (no clamp).
  Status set_stretch_range(Eigen::MatrixXf range);
  std::vector<float> FlatParameters() const { return mlp_.FlatParameters(); }
  learn::Mlp* mutable_mlp() { return &mlp_; }
  const learn::Mlp& mlp() const { return mlp_; }
  // A deep copy (network, propagation, stretch range), to fine-tune while keeping this one.
  SynthesisModel Clone() const {
    SynthesisModel copy;
    copy.config_ = config_;
    copy.mlp_ = mlp_.Clone();
    copy.propagation_ = propagation_;
    copy.stretch_range_ = stretch_range_;
    return copy;
  }

  // The propagation learned from the training offsets (propagation.h), or null.
  const SamplePropagation* propagation() const {
    return propagation_ ? &*propagation_ : nullptr;
  }
  void set_propagation(std::optional<SamplePropagation> propagation) {
    propagation_ = std::move(propagation);
  }

 private:
  SynthesisConfig config_;
  learn::Mlp mlp_;
  std::optional<SamplePropagation> propagation_;
  Eigen::MatrixXf stretch_range_;
};

struct SynthesisTrainOptions {
  // Optimisation: the paper's 30 epochs, batch 50 and Adam at 1e-3 (sec. 6.2).
  learn::MlpTrainOptions train = Defaults();
  double validation_fraction = 0.1;  // fraction of usable frames held out (blocks, with a gap)
  int hidden_units = 256;
  // H plus a linear map of its inputs (learn::MlpShape::linear_skip); false is the paper's network.
  bool linear_skip = false;
  double window_s = 0.08;
  double stretch_step_mm = 2.0;  // Eq. (8)'s ~2 mm uv steps
  // Fit the propagation to the training takes' per-vertex dynamic offsets and keep it in the
  // model (as RemovalTrainOptions).
  bool learn_propagation = true;
  PropagationLearnOptions propagation;
  // train valid; ranges as RemovalTrainOptions; stretch_step_mm in (0, 50]. Names the field.
  Status Check() const;

  static learn::MlpTrainOptions Defaults() {
    learn::MlpTrainOptions train;
    train.epochs = 30;
    train.batch_size = 50;
    train.progress_label = "train-synthesis";
    return train;
  }
};

// A simulated take (positions dynamic, channels "quasistatic" and "dynamic_offset") as a
// decomposed take: positions = the exact quasistatic, channel dynamic_offset = the exact dx.
// Errors when either channel is missing.
StatusOr<Take> DecomposeExact(const Take& simulated);

// FailedPrecondition (prefixed by `context`) unless `take` is a decomposed take: a
// "dynamic_offset" channel, and positions equal to its "quasistatic" channel when it has one.
Status CheckDecomposed(const Take& take, const std::string& context);

// Trains H on decomposed takes (positions quasistatic, channel "dynamic_offset"). Frames within
// the feature window of either end, or of the first frame, or before the take's hold_start_s,
// are left out; validation holds out contiguous blocks with a gap (training_frames.h). Errors: no takes, a take without the channel,
// mismatched rigs.
StatusOr<SynthesisModel> TrainSynthesis(const std::vector<TrainingTake>& decomposed,
                                        const SynthesisTrainOptions& options,
                                        learn::MlpTrainSummary* summary = nullptr);

// What TrainSynthesis trains H on, for trainers that add losses of their own
// (joint_training.h): H's config, the rows (input [B; S], target dY, 3S, skull frame, mm; one
// per frame), the training and validation rows, the propagation learner fed with the training
// offsets (empty unless options.learn_propagation), and the training frames' stretch range
// (SynthesisModel::stretch_range). The same rules and errors as TrainSynthesis.
struct SynthesisTrainingData {
  SynthesisConfig config;
  std::unique_ptr<learn::MlpDataset> data;
  std::vector<long> train_rows, validation_rows;
  std::optional<PropagationLearner> learner;
  Eigen::MatrixXf stretch_range;
};
StatusOr<SynthesisTrainingData> BuildSynthesisTrainingData(
    const std::vector<TrainingTake>& decomposed, const SynthesisTrainOptions& options);

// H's inputs [B(t); S(t)] for a quasistatic take under a head motion (one pose per frame),
// input_size x F, the stretch clamped as Predict clamps it. Errors as SynthesizeDynamics.
StatusOr<Eigen::MatrixXf> SynthesisInputs(const SynthesisModel& model, const Take& quasistatic,
                                          const std::vector<Rigid3>& world_from_skull,
                                          const FaceRig& rig);

struct SynthesisSummary {
  double predict_s = 0.0;
  double propagate_s = 0.0;
  double frames_per_s = 0.0;
};

// New dynamics for a quasistatic take under a new head motion (one pose per frame of
// `quasistatic`): the result's positions are T(t) (T_q(t)^-1 y(t) + d(t)), its channels
// "quasistatic" (the re-posed quasistatic T(t) T_q(t)^-1 y(t)) and "dynamic_offset" (d, skull
// frame); info.source "dynamics synthesize", info.motion `motion_name`. Errors: incompatible
// take or rig, a pose count that differs from the frame count.
StatusOr<Take> SynthesizeDynamics(const SynthesisModel& model, const Take& quasistatic,
                                  const std::vector<Rigid3>& world_from_skull,
                                  const std::string& motion_name, const FaceRig& rig,
                                  const SamplePropagation* propagation = nullptr,
                                  SynthesisSummary* summary = nullptr);
// (`propagation` is used only for a model without its own, as RemoveDynamics.)

// The held shape of a take in the skull frame (3 x V, mm): the mean over frames
// [skip, F - skip) of T(t)^-1 x(t). Of a quasistatic estimate of a held expression (F's
// removal) it is the expression's shape, which HeldShapeTake carries along a new head motion.
// The whole take when it has fewer than 2 skip + 1 frames.
Eigen::Matrix3Xd MeanShapeInSkull(const Take& take, int skip);

// A held shape (3 x V, skull frame, mm) posed by `world_from_skull` at `fps`: the quasistatic
// take of a subject holding one expression under a given head motion.
Take HeldShapeTake(const FaceRig& rig, const Eigen::Matrix3Xd& shape_in_skull,
                   const std::vector<Rigid3>& world_from_skull, double fps);

// Per-sample values of a per-vertex cache (3V x F): 3S x F, rows 3i..3i+2 = sample i.
Eigen::MatrixXf SampleOffsetsByFrame(const PointCache& offsets,
                                     const std::vector<SurfacePoint>& samples);

// A synthesised take from per-sample offsets (3S x F, skull frame, mm, as SampleOffsetsByFrame):
// positions T(t) (T_q(t)^-1 y(t) + d(t)) with d the offsets propagated to every vertex, channels
// "quasistatic" and "dynamic_offset"; info.source `source`, info.motion `motion_name`.
// Preconditions (checked by the callers): one pose per frame, the propagation's rig.
Take ComposeSynthesis(const Take& quasistatic, const std::vector<Rigid3>& world_from_skull,
                      const std::string& source, const std::string& motion_name,
                      const SamplePropagation& propagation, const Eigen::MatrixXf& by_frame);

// Paper Fig. 10(b): the source's per-sample dynamic offsets (channel "dynamic_offset" of a
// decomposed or simulated source take, sampled at the source rig's samples) copied sample by
// sample onto the target's quasistatic take, posed by the source motion. Requires the same
// sample count and frame count. Channels as SynthesizeDynamics.
StatusOr<Take> NaiveDeltaTransfer(const Take& source, const FaceRig& source_rig,
                                  const Take& target_quasistatic, const FaceRig& target_rig,
                                  const SamplePropagation* target_propagation = nullptr);

}  // namespace facedyn::dynamics
