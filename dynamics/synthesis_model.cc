#include "dynamics/synthesis_model.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <random>
#include <utility>

#include "core/check.h"
#include "dynamics/features.h"
#include "dynamics/model_file.h"
#include "dynamics/training_frames.h"

namespace facedyn::dynamics {

namespace {

constexpr char kKind[] = "synthesis";
constexpr int kSynthesisFormatVersion = 1;
constexpr char kStretchRange[] = "stretch_range";  // attachment, 2 x 2S (SynthesisModel)

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// [B(t); S(t)] for every frame: input_size x F.
StatusOr<Eigen::MatrixXf> SynthesisFeatures(const Take& quasistatic,
                                            const std::vector<Rigid3>& world_from_skull,
                                            const FaceRig& rig, const FeatureSpec& spec,
                                            const StretchStencil& stencil) {
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd skull,
                           SkullDescriptors(world_from_skull, rig.skull_landmarks, spec.features));
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd stretch, StretchFeatures(quasistatic, stencil));
  Eigen::MatrixXf features(skull.rows() + stretch.rows(), quasistatic.frame_count());
  features.topRows(skull.rows()) = skull.cast<float>();
  features.bottomRows(stretch.rows()) = stretch.cast<float>();
  return features;
}

// Rows are frames: take * F_max + frame.
class SynthesisDataset final : public learn::MlpDataset {
 public:
  explicit SynthesisDataset(int max_frames) : max_frames_(max_frames) {}
  void Add(Eigen::MatrixXf features, Eigen::MatrixXf targets) {
    features_.push_back(std::move(features));
    targets_.push_back(std::move(targets));
  }
  long RowOf(int take, int frame) const { return static_cast<long>(take) * max_frames_ + frame; }
  int input_size() const override { return static_cast<int>(features_.front().rows()); }
  int output_size() const override { return static_cast<int>(targets_.front().rows()); }
  void Gather(const long* rows, long n, Eigen::MatrixXf* inputs,
              Eigen::MatrixXf* targets) const override {
    inputs->resize(input_size(), n);
    targets->resize(output_size(), n);
    for (long r = 0; r < n; ++r) {
      const int take = static_cast<int>(rows[r] / max_frames_);
      const int frame = static_cast<int>(rows[r] % max_frames_);
      inputs->col(r) = features_[take].col(frame);
      targets->col(r) = targets_[take].col(frame);
    }
  }

 private:
  int max_frames_;
  std::vector<Eigen::MatrixXf> features_;
  std::vector<Eigen::MatrixXf> targets_;
};

// The quasistatic take re-posed by new poses: T(t) T_q(t)^-1 y(t).
PointCache Repose(const Take& quasistatic, const std::vector<Rigid3>& world_from_skull) {
  PointCache out = quasistatic.positions;
  for (int t = 0; t < quasistatic.frame_count(); ++t) {
    const Rigid3 new_from_old = world_from_skull[t] * quasistatic.world_from_skull[t].Inverse();
    out.Frame(t) = new_from_old.Apply(quasistatic.positions.Frame(t).cast<double>()).cast<float>();
  }
  return out;
}

}  // namespace

Eigen::MatrixXf SampleOffsetsByFrame(const PointCache& offsets,
                                     const std::vector<SurfacePoint>& samples) {
  const int sample_count = static_cast<int>(samples.size());
  Eigen::MatrixXf out(3 * sample_count, offsets.frame_count());
  for (int t = 0; t < offsets.frame_count(); ++t) {
    const auto frame = offsets.Frame(t);
    for (int i = 0; i < sample_count; ++i) {
      out.col(t).segment<3>(3 * i) = samples[i].Evaluate(frame).cast<float>();
    }
  }
  return out;
}

Take ComposeSynthesis(const Take& quasistatic, const std::vector<Rigid3>& world_from_skull,
                      const std::string& source, const std::string& motion_name,
                      const SamplePropagation& propagation, const Eigen::MatrixXf& by_frame) {
  // Same memory as 3 x F*S with column t * S + i: the layout ComposeOffsets reads.
  const Eigen::Map<const Eigen::MatrixXf> sample_offsets(by_frame.data(), 3, by_frame.size() / 3);
  Take result;
  result.info = quasistatic.info;
  result.info.source = source;
  result.info.motion = motion_name;
  result.topology = quasistatic.topology;
  result.time_s = quasistatic.time_s;
  result.world_from_skull = world_from_skull;
  result.skull_from_jaw = quasistatic.skull_from_jaw;
  result.positions = Repose(quasistatic, world_from_skull);
  PointCache offsets, positions;
  ComposeOffsets(result, propagation, sample_offsets, +1.0f, &offsets, &positions);
  result.channels["quasistatic"] = std::move(result.positions);
  result.positions = std::move(positions);
  result.channels["dynamic_offset"] = std::move(offsets);
  return result;
}

SynthesisConfig SynthesisConfig::ForRig(const FaceRig& rig, double fps) {
  SynthesisConfig config;
  static_cast<FeatureSpec&>(config) = FeatureSpec::ForRig(rig, fps);
  return config;
}

Status SynthesisConfig::Check() const {
  FACEDYN_RETURN_IF_ERROR(FeatureSpec::Check());
  if (hidden_units < 1) return InvalidArgumentError("hidden_units must be >= 1");
  return Status::Ok();
}

StatusOr<SynthesisModel> SynthesisModel::Create(const SynthesisConfig& config, uint64_t seed) {
  FACEDYN_RETURN_IF_ERROR(config.Check());
  learn::MlpShape shape;
  shape.input_size = config.input_size();
  shape.hidden_units = config.hidden_units;
  shape.output_size = config.output_size();
  shape.linear_skip = config.linear_skip;
  SynthesisModel model;
  model.config_ = config;
  FACEDYN_ASSIGN_OR_RETURN(model.mlp_, learn::Mlp::Create(shape, seed));
  return model;
}

Eigen::MatrixXf SynthesisModel::Predict(const Eigen::MatrixXf& features) const {
  if (stretch_range_.size() == 0 || features.rows() != config_.input_size()) {
    return mlp_.Predict(features);  // a wrong size is the network's to report
  }
  return mlp_.Predict(ClampStretch(features));
}

Eigen::MatrixXf SynthesisModel::ClampStretch(const Eigen::MatrixXf& features) const {
  if (stretch_range_.size() == 0 || features.rows() != config_.input_size()) return features;
  Eigen::MatrixXf clamped = features;
  const int first = config_.skull_descriptor_size();
  const int count = static_cast<int>(stretch_range_.cols());
  clamped.middleRows(first, count) =
      clamped.middleRows(first, count)
          .cwiseMax(stretch_range_.row(0).transpose().replicate(1, clamped.cols()))
          .cwiseMin(stretch_range_.row(1).transpose().replicate(1, clamped.cols()));
  return clamped;
}

Status SynthesisModel::set_stretch_range(Eigen::MatrixXf range) {
  const int count = config_.input_size() - config_.skull_descriptor_size();
  if (range.size() != 0) {
    if (range.rows() != 2 || range.cols() != count) {
      return InvalidArgumentError(
          "synthesis model: a stretch range of " + std::to_string(range.rows()) + " x " +
          std::to_string(range.cols()) + ", expected 2 x " + std::to_string(count));
    }
    for (int c = 0; c < count; ++c) {
      if (!(range(0, c) <= range(1, c))) {
        return InvalidArgumentError("synthesis model: stretch feature " + std::to_string(c) +
                                    " has minimum " + std::to_string(range(0, c)) +
                                    " above maximum " + std::to_string(range(1, c)));
      }
    }
  }
  stretch_range_ = std::move(range);
  return Status::Ok();
}

Status SynthesisModel::Save(const std::string& path) const {
  learn::MlpAttachments extra;
  if (stretch_range_.size() != 0) extra[kStretchRange] = stretch_range_;
  return SaveFeatureModel(mlp_, config_, kKind, kSynthesisFormatVersion, propagation(), path,
                          extra);
}

StatusOr<SynthesisModel> SynthesisModel::Load(const std::string& path) {
  SynthesisModel model;
  learn::MlpAttachments extra;
  FACEDYN_ASSIGN_OR_RETURN(model.mlp_,
                           LoadFeatureModel(path, kKind, kSynthesisFormatVersion, &model.config_,
                                            &model.propagation_, &extra));
  model.config_.hidden_units = model.mlp_.shape().hidden_units;
  model.config_.linear_skip = model.mlp_.shape().linear_skip;
  FACEDYN_RETURN_IF_ERROR(CheckNetworkSizes(path, model.mlp_.shape(), model.config_.input_size(),
                                            model.config_.output_size()));
  if (auto found = extra.find(kStretchRange); found != extra.end()) {
    if (Status status = model.set_stretch_range(std::move(found->second)); !status.ok()) {
      return DataLossError(path + ": " + status.message());
    }
  }
  return model;
}

Status SynthesisTrainOptions::Check() const {
  FACEDYN_RETURN_IF_ERROR(train.Check());
  if (!(validation_fraction >= 0 && validation_fraction <= 0.9)) {
    return InvalidArgumentError("validation_fraction must be in [0, 0.9]");
  }
  if (hidden_units < 1) return InvalidArgumentError("hidden_units must be >= 1");
  if (!(window_s > 0 && window_s <= 1)) return InvalidArgumentError("window_s must be in (0, 1]");
  if (!(stretch_step_mm > 0 && stretch_step_mm <= 50)) {
    return InvalidArgumentError("stretch_step_mm must be in (0, 50]");
  }
  if (Status status = propagation.Check(); !status.ok()) return status.WithContext("propagation");
  return Status::Ok();
}

StatusOr<Take> DecomposeExact(const Take& simulated) {
  const auto quasistatic = simulated.channels.find("quasistatic");
  const auto offsets = simulated.channels.find("dynamic_offset");
  if (quasistatic == simulated.channels.end() || offsets == simulated.channels.end()) {
    return FailedPreconditionError(
        "the take has no exact quasistatic/dynamic_offset channels (only simulated takes do)");
  }
  Take out;
  out.info = simulated.info;
  out.info.source = "exact decomposition";
  out.topology = simulated.topology;
  out.time_s = simulated.time_s;
  out.world_from_skull = simulated.world_from_skull;
  out.skull_from_jaw = simulated.skull_from_jaw;
  out.positions = quasistatic->second;
  out.channels["dynamic_offset"] = offsets->second;
  return out;
}

Status CheckDecomposed(const Take& take, const std::string& context) {
  if (take.channels.count("dynamic_offset") == 0) {
    return FailedPreconditionError(context +
                                   ": no dynamic_offset channel (train on the output of "
                                   "`dynamics remove`, or on simulated takes with --exact)");
  }
  // A simulated dynamic take also carries a dynamic_offset channel, but its positions are
  // the dynamic skin: training on it would teach a model to add dynamics to dynamics.
  if (const auto quasistatic = take.channels.find("quasistatic");
      quasistatic != take.channels.end() &&
      (quasistatic->second.positions - take.positions.positions).cwiseAbs().maxCoeff() > 1e-3f) {
    return FailedPreconditionError(
        context +
        ": its positions are not quasistatic (they differ from its quasistatic "
        "channel: a simulated dynamic take?); decompose it first (DecomposeExact, "
        "`train-synthesis --exact`, or `--removal-model F.pt`)");
  }
  return Status::Ok();
}

StatusOr<SynthesisTrainingData> BuildSynthesisTrainingData(
    const std::vector<TrainingTake>& decomposed, const SynthesisTrainOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  if (decomposed.empty()) return InvalidArgumentError("train-synthesis: no training takes");
  FACEDYN_RETURN_IF_ERROR(CheckNoTargetsOrWeights(decomposed, "train-synthesis"));
  for (const TrainingTake& training : decomposed) {
    FACEDYN_CHECK(training.take != nullptr && training.rig != nullptr,
                  "TrainSynthesis: training take without take or rig");
  }
  SynthesisConfig config =
      SynthesisConfig::ForRig(*decomposed[0].rig, decomposed[0].take->info.fps);
  config.features.window_s = options.window_s;
  config.features.stretch_step_mm = options.stretch_step_mm;
  config.hidden_units = options.hidden_units;
  config.linear_skip = options.linear_skip;
  FACEDYN_RETURN_IF_ERROR(config.Check());
  FACEDYN_ASSIGN_OR_RETURN(const StretchStencil stencil,
                           BuildStretchStencil(*decomposed[0].rig, decomposed[0].rig->skin_samples,
                                               options.stretch_step_mm));

  int max_frames = 0;
  for (const TrainingTake& training : decomposed) {
    max_frames = std::max(max_frames, training.take->frame_count());
  }
  auto owned_data = std::make_unique<SynthesisDataset>(max_frames);
  SynthesisDataset& data = *owned_data;
  const int window = config.features.window_frames();
  std::optional<PropagationLearner> learner;
  if (options.learn_propagation) {
    FACEDYN_ASSIGN_OR_RETURN(learner, PropagationLearner::ForRig(*decomposed[0].rig, options.propagation));
  }
  std::vector<FrameRange> ranges;  // per take, the frames usable for training
  long usable_frames = 0;
  const int stretch_first = config.skull_descriptor_size();
  const int stretch_count = config.input_size() - stretch_first;
  Eigen::MatrixXf stretch_range(2, stretch_count);
  stretch_range.row(0).setConstant(std::numeric_limits<float>::infinity());
  stretch_range.row(1).setConstant(-std::numeric_limits<float>::infinity());
  for (size_t k = 0; k < decomposed.size(); ++k) {
    const Take& take = *decomposed[k].take;
    const FaceRig& rig = *decomposed[k].rig;
    const std::string context =
        "training take " + std::to_string(k) +
        (take.info.expression.empty() ? "" : " (" + take.info.expression + ")");
    if (Status status = config.CheckCompatible(take, rig); !status.ok()) {
      return status.WithContext(context);
    }
    FACEDYN_RETURN_IF_ERROR(CheckDecomposed(take, context));
    const auto offsets = take.channels.find("dynamic_offset");
    StatusOr<Eigen::MatrixXf> features =
        SynthesisFeatures(take, take.world_from_skull, rig, config, stencil);
    if (!features.ok()) return features.status().WithContext(context);
    // A decomposition by F of a held-expression take is an estimate that assumes the hold:
    // frames before hold_start_s are left out (training_frames.h); exact ones do not need it,
    // but a take cannot tell which it is, so the rule is the same for both.
    const FrameRange range = UsableFrames(take, window, true);
    if (learner && !range.empty()) {
      if (Status status = learner->Add(offsets->second, range.begin, range.end); !status.ok()) {
        return status.WithContext(context);
      }
    }
    if (!range.empty()) {
      const Eigen::MatrixXf stretch =
          features->block(stretch_first, range.begin, stretch_count, range.size());
      stretch_range.row(0) =
          stretch_range.row(0).cwiseMin(stretch.rowwise().minCoeff().transpose());
      stretch_range.row(1) =
          stretch_range.row(1).cwiseMax(stretch.rowwise().maxCoeff().transpose());
    }
    data.Add(std::move(features).value(), SampleOffsetsByFrame(offsets->second, rig.skin_samples));
    ranges.push_back(range);
    usable_frames += range.size();
  }
  if (usable_frames == 0) {
    return FailedPreconditionError(
        "train-synthesis: no take has a frame whose feature window lies inside its held part "
        "(at least " + std::to_string(2 * window + 2) + " frames after hold_start_s)");
  }
  const FrameSplit split =
      SplitByBlocks(ranges, options.validation_fraction, ValidationBlockFrames(window),
                    ValidationGapFrames(window), options.train.seed);
  std::vector<long> train_rows, validation_rows;
  for (const TakeFrame& frame : split.train) train_rows.push_back(data.RowOf(frame.first, frame.second));
  for (const TakeFrame& frame : split.validation) {
    validation_rows.push_back(data.RowOf(frame.first, frame.second));
  }
  SynthesisTrainingData result;
  result.config = config;
  result.data = std::move(owned_data);
  result.train_rows = std::move(train_rows);
  result.validation_rows = std::move(validation_rows);
  result.learner = std::move(learner);
  result.stretch_range = std::move(stretch_range);
  return result;
}

StatusOr<SynthesisModel> TrainSynthesis(const std::vector<TrainingTake>& decomposed,
                                        const SynthesisTrainOptions& options,
                                        learn::MlpTrainSummary* summary) {
  FACEDYN_ASSIGN_OR_RETURN(SynthesisTrainingData training,
                           BuildSynthesisTrainingData(decomposed, options));
  FACEDYN_ASSIGN_OR_RETURN(SynthesisModel model,
                           SynthesisModel::Create(training.config, options.train.seed));
  FACEDYN_RETURN_IF_ERROR(learn::TrainMlp(*training.data, training.train_rows,
                                          training.validation_rows, options.train,
                                          model.mutable_mlp(), summary));
  FACEDYN_RETURN_IF_ERROR(model.set_stretch_range(std::move(training.stretch_range)));
  if (training.learner) {
    FACEDYN_ASSIGN_OR_RETURN(SamplePropagation learned, training.learner->Fit());
    model.set_propagation(std::move(learned));
  }
  return model;
}

StatusOr<Eigen::MatrixXf> SynthesisInputs(const SynthesisModel& model, const Take& quasistatic,
                                          const std::vector<Rigid3>& world_from_skull,
                                          const FaceRig& rig) {
  FACEDYN_RETURN_IF_ERROR(model.CheckCompatible(quasistatic, rig));
  if (static_cast<int>(world_from_skull.size()) != quasistatic.frame_count()) {
    return InvalidArgumentError("the head motion has " + std::to_string(world_from_skull.size()) +
                                " poses, the quasistatic take " +
                                std::to_string(quasistatic.frame_count()) + " frames");
  }
  const SynthesisConfig& config = model.config();
  FACEDYN_ASSIGN_OR_RETURN(
      const StretchStencil stencil,
      BuildStretchStencil(rig, rig.skin_samples, config.features.stretch_step_mm));
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXf features,
                           SynthesisFeatures(quasistatic, world_from_skull, rig, config, stencil));
  return model.ClampStretch(features);
}

StatusOr<Take> SynthesizeDynamics(const SynthesisModel& model, const Take& quasistatic,
                                  const std::vector<Rigid3>& world_from_skull,
                                  const std::string& motion_name, const FaceRig& rig,
                                  const SamplePropagation* propagation, SynthesisSummary* summary) {
  const auto start = std::chrono::steady_clock::now();
  StatusOr<Eigen::MatrixXf> features = SynthesisInputs(model, quasistatic, world_from_skull, rig);
  if (!features.ok()) return features.status().WithContext("synthesize");
  // Already clamped, so the network is asked directly.
  const Eigen::MatrixXf by_frame = model.mlp().Predict(*features);  // 3S x F
  const double predict_s = SecondsSince(start);

  const auto propagate_start = std::chrono::steady_clock::now();
  std::optional<SamplePropagation> built;
  FACEDYN_ASSIGN_OR_RETURN(propagation,
                           SelectPropagation(model.propagation(), propagation, rig, &built));
  Take result = ComposeSynthesis(quasistatic, world_from_skull, "dynamics synthesize",
                                 motion_name, *propagation, by_frame);
  if (summary != nullptr) {
    summary->predict_s = predict_s;
    summary->propagate_s = SecondsSince(propagate_start);
    const double total = summary->predict_s + summary->propagate_s;
    summary->frames_per_s = total > 0 ? quasistatic.frame_count() / total : 0.0;
  }
  return result;
}

Eigen::Matrix3Xd MeanShapeInSkull(const Take& take, int skip) {
  int begin = std::max(0, skip);
  int end = take.frame_count() - begin;
  if (end <= begin) {
    begin = 0;
    end = take.frame_count();
  }
  Eigen::Matrix3Xd sum = Eigen::Matrix3Xd::Zero(3, take.vertex_count());
  for (int t = begin; t < end; ++t) {
    sum += take.world_from_skull[t].Inverse().Apply(take.FramePositions(t));
  }
  return sum / std::max(end - begin, 1);
}

Take HeldShapeTake(const FaceRig& rig, const Eigen::Matrix3Xd& shape_in_skull,
                   const std::vector<Rigid3>& world_from_skull, double fps) {
  FACEDYN_CHECK(shape_in_skull.cols() == rig.vertex_count(), "HeldShapeTake: wrong vertex count");
  Take take;
  take.info.fps = fps;
  take.info.subject = rig.name;
  take.info.source = "held shape";
  take.topology = rig.neutral;
  take.world_from_skull = world_from_skull;
  const int frame_count = static_cast<int>(world_from_skull.size());
  take.positions.vertex_count = rig.vertex_count();
  take.positions.positions.resize(3 * static_cast<Eigen::Index>(rig.vertex_count()), frame_count);
  for (int t = 0; t < frame_count; ++t) {
    take.positions.Frame(t) = world_from_skull[t].Apply(shape_in_skull).cast<float>();
  }
  take.SetUniformTimes();
  return take;
}

StatusOr<Take> NaiveDeltaTransfer(const Take& source, const FaceRig& source_rig,
                                  const Take& target_quasistatic, const FaceRig& target_rig,
                                  const SamplePropagation* target_propagation) {
  const auto offsets = source.channels.find("dynamic_offset");
  if (offsets == source.channels.end()) {
    return FailedPreconditionError("naive transfer: the source take has no dynamic_offset channel");
  }
  if (source_rig.skin_samples.size() != target_rig.skin_samples.size()) {
    return FailedPreconditionError(
        "naive transfer: the source rig has " + std::to_string(source_rig.skin_samples.size()) +
        " samples, the target " + std::to_string(target_rig.skin_samples.size()));
  }
  if (source.frame_count() != target_quasistatic.frame_count()) {
    return FailedPreconditionError("naive transfer: the source has " +
                                   std::to_string(source.frame_count()) + " frames, the target " +
                                   std::to_string(target_quasistatic.frame_count()));
  }
  std::optional<SamplePropagation> built;
  if (target_propagation == nullptr) {
    FACEDYN_ASSIGN_OR_RETURN(built, SamplePropagation::Build(target_rig));
    target_propagation = &*built;
  }
  return ComposeSynthesis(target_quasistatic, source.world_from_skull, "naive delta transfer",
                          source.info.motion, *target_propagation,
                          SampleOffsetsByFrame(offsets->second, source_rig.skin_samples));
}

}  // namespace facedyn::dynamics
