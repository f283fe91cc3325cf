#include "dynamics/removal_model.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <random>
#include <utility>

#include "core/check.h"
#include "dynamics/model_file.h"
#include "dynamics/quasistatic.h"
#include "dynamics/training_frames.h"

namespace facedyn::dynamics {

namespace {

constexpr char kKind[] = "removal";
constexpr int kRemovalFormatVersion = 2;

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Skin-sample values of a per-vertex cache (3V x F): 3 x (F * S), column t * S + i.
Eigen::MatrixXf SampleCache(const PointCache& cache, const std::vector<SurfacePoint>& samples) {
  const int sample_count = static_cast<int>(samples.size());
  Eigen::MatrixXf out(3, static_cast<Eigen::Index>(cache.frame_count()) * sample_count);
  for (int t = 0; t < cache.frame_count(); ++t) {
    const auto frame = cache.Frame(t);
    for (int i = 0; i < sample_count; ++i) {
      out.col(static_cast<Eigen::Index>(t) * sample_count + i) =
          samples[i].Evaluate(frame).cast<float>();
    }
  }
  return out;
}

// Rows are (take, frame, sample) packed into a long: ((take * F_max) + frame) * S + sample.
class RemovalDataset final : public learn::MlpDataset {
 public:
  RemovalDataset(int skull_size, int skin_size, int sample_count, int max_frames)
      : skull_size_(skull_size),
        skin_size_(skin_size),
        sample_count_(sample_count),
        max_frames_(max_frames) {}

  void Add(RemovalTakeFeatures features, Eigen::MatrixXf targets) {
    features_.push_back(std::move(features));
    targets_.push_back(std::move(targets));
  }
  long RowOf(int take, int frame, int sample) const {
    return (static_cast<long>(take) * max_frames_ + frame) * sample_count_ + sample;
  }

  int input_size() const override { return skull_size_ + skin_size_; }
  int output_size() const override { return 3; }
  void Gather(const long* rows, long n, Eigen::MatrixXf* inputs,
              Eigen::MatrixXf* targets) const override {
    inputs->resize(input_size(), n);
    targets->resize(3, n);
    for (long r = 0; r < n; ++r) {
      const long sample = rows[r] % sample_count_;
      const long frame_index = rows[r] / sample_count_;
      const int take = static_cast<int>(frame_index / max_frames_);
      const int frame = static_cast<int>(frame_index % max_frames_);
      const Eigen::Index column = static_cast<Eigen::Index>(frame) * sample_count_ + sample;
      inputs->col(r).head(skull_size_) = features_[take].skull.col(frame);
      inputs->col(r).tail(skin_size_) = features_[take].skin.col(column);
      targets->col(r) = targets_[take].col(column);
    }
  }

 private:
  int skull_size_, skin_size_, sample_count_, max_frames_;
  std::vector<RemovalTakeFeatures> features_;
  std::vector<Eigen::MatrixXf> targets_;  // 3 x F*S per take
};

}  // namespace

StatusOr<RemovalTakeFeatures> ComputeRemovalFeatures(const Take& take, const FaceRig& rig,
                                                     const FeatureConfig& config) {
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd skull,
                           SkullDescriptors(take.world_from_skull, rig.skull_landmarks, config));
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd skin,
                           SkinDescriptors(take, rig.skin_samples, config));
  return RemovalTakeFeatures{skull.cast<float>(), skin.cast<float>()};
}

const char* RemovalTargetsName(RemovalTargets targets) {
  switch (targets) {
    case RemovalTargets::kExact:
      return "exact";
    case RemovalTargets::kPlatformSynchronous:
      return "platform-synchronous";
    case RemovalTargets::kPlatformSynchronousWhereKnown:
      return "platform-synchronous-where-known";
    case RemovalTargets::kHeldMean:
      return "held-mean";
    case RemovalTargets::kPlatformSynchronousElseHeldMean:
      return "platform-synchronous-else-held-mean";
    case RemovalTargets::kMovingAverage:
      break;
  }
  return "moving-average";
}

namespace {
constexpr RemovalTargets kAllRemovalTargets[] = {RemovalTargets::kMovingAverage,
                                                 RemovalTargets::kExact,
                                                 RemovalTargets::kPlatformSynchronous,
                                                 RemovalTargets::kPlatformSynchronousWhereKnown,
                                                 RemovalTargets::kHeldMean,
                                                 RemovalTargets::kPlatformSynchronousElseHeldMean};
}  // namespace

std::vector<std::string> RemovalTargetsNames(bool include_exact) {
  std::vector<std::string> names;
  for (RemovalTargets targets : kAllRemovalTargets) {
    if (targets != RemovalTargets::kExact || include_exact) {
      names.push_back(RemovalTargetsName(targets));
    }
  }
  return names;
}

StatusOr<RemovalTargets> ParseRemovalTargets(const std::string& name) {
  for (RemovalTargets targets : kAllRemovalTargets) {
    if (name == RemovalTargetsName(targets)) return targets;
  }
  std::string known;
  for (const std::string& one : RemovalTargetsNames(true))
    known += (known.empty() ? "" : ", ") + one;
  return InvalidArgumentError("targets: unknown \"" + name + "\" (" + known + ")");
}

RemovalConfig RemovalConfig::ForRig(const FaceRig& rig, double fps) {
  RemovalConfig config;
  static_cast<FeatureSpec&>(config) = FeatureSpec::ForRig(rig, fps);
  return config;
}

Status RemovalConfig::Check() const {
  FACEDYN_RETURN_IF_ERROR(FeatureSpec::Check());
  if (hidden_units < 1) return InvalidArgumentError("hidden_units must be >= 1");
  return Status::Ok();
}

StatusOr<RemovalModel> RemovalModel::Create(const RemovalConfig& config, uint64_t seed) {
  FACEDYN_RETURN_IF_ERROR(config.Check());
  learn::MlpShape shape;
  shape.input_size = config.input_size();
  shape.hidden_units = config.hidden_units;
  shape.linear_skip = config.linear_skip;
  shape.output_size = 3;
  RemovalModel model;
  model.config_ = config;
  FACEDYN_ASSIGN_OR_RETURN(model.mlp_, learn::Mlp::Create(shape, seed));
  return model;
}

Status RemovalModel::Save(const std::string& path) const {
  return SaveFeatureModel(mlp_, config_, kKind, kRemovalFormatVersion, propagation(), path);
}

StatusOr<RemovalModel> RemovalModel::Load(const std::string& path) {
  RemovalModel model;
  FACEDYN_ASSIGN_OR_RETURN(model.mlp_, LoadFeatureModel(path, kKind, kRemovalFormatVersion,
                                                        &model.config_, &model.propagation_));
  model.config_.hidden_units = model.mlp_.shape().hidden_units;
  model.config_.linear_skip = model.mlp_.shape().linear_skip;
  FACEDYN_RETURN_IF_ERROR(
      CheckNetworkSizes(path, model.mlp_.shape(), model.config_.input_size(), 3));
  return model;
}

Status RemovalTrainOptions::Check() const {
  FACEDYN_RETURN_IF_ERROR(train.Check());
  if (!(validation_fraction >= 0 && validation_fraction <= 0.9)) {
    return InvalidArgumentError("validation_fraction must be in [0, 0.9]");
  }
  if (hidden_units < 1) return InvalidArgumentError("hidden_units must be >= 1");
  if (!(window_s > 0 && window_s <= 1)) return InvalidArgumentError("window_s must be in (0, 1]");
  if (target_trend_degree < 0 || target_trend_degree > 4) {
    return InvalidArgumentError("target_trend_degree must be in 0..4, got " +
                                std::to_string(target_trend_degree));
  }
  if (!(target_min_periods >= 1 && target_min_periods <= 10)) {
    return InvalidArgumentError("target_min_periods must be in [1, 10], got " +
                                std::to_string(target_min_periods));
  }
  // A trend asked for with targets that never use the fit would be silently ignored.
  if (target_trend_degree != 0 &&
      (targets == RemovalTargets::kMovingAverage || targets == RemovalTargets::kExact ||
       targets == RemovalTargets::kHeldMean)) {
    return InvalidArgumentError(std::string("target_trend_degree applies to platform-synchronous "
                                            "targets only, not ") +
                                RemovalTargetsName(targets));
  }
  if (Status status = propagation.Check(); !status.ok()) return status.WithContext("propagation");
  return Status::Ok();
}

Status CheckNoTargetsOrWeights(const std::vector<TrainingTake>& takes, const std::string& trainer) {
  for (size_t k = 0; k < takes.size(); ++k) {
    if (takes[k].targets.has_value() || takes[k].weight != 1.0) {
      return InvalidArgumentError(trainer + ": training take " + std::to_string(k) +
                                  " sets its own targets or a weight, which only the removal "
                                  "network's training (TrainRemoval) uses");
    }
  }
  return Status::Ok();
}

StatusOr<RemovalTrainingData> BuildRemovalTrainingData(const std::vector<TrainingTake>& takes,
                                                       const RemovalTrainOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  if (takes.empty()) return InvalidArgumentError("train-removal: no training takes");
  for (size_t k = 0; k < takes.size(); ++k) {
    const TrainingTake& training = takes[k];
    FACEDYN_CHECK(training.take != nullptr && training.rig != nullptr,
                  "TrainRemoval: training take without take or rig");
    if (!(std::isfinite(training.weight) && training.weight > 0)) {
      return InvalidArgumentError("train-removal: training take " + std::to_string(k) +
                                  " has weight " + std::to_string(training.weight) +
                                  "; a weight must be finite and > 0");
    }
  }
  RemovalConfig config = RemovalConfig::ForRig(*takes[0].rig, takes[0].take->info.fps);
  config.features.window_s = options.window_s;
  config.hidden_units = options.hidden_units;
  config.linear_skip = options.linear_skip;
  FACEDYN_RETURN_IF_ERROR(config.Check());

  int max_frames = 0;
  for (const TrainingTake& training : takes) {
    max_frames = std::max(max_frames, training.take->frame_count());
  }
  auto owned_data = std::make_unique<RemovalDataset>(config.skull_descriptor_size(),
                                                     config.features.SkinDescriptorSize(),
                                                     config.sample_count, max_frames);
  RemovalDataset& data = *owned_data;
  const int window = config.features.window_frames();
  std::optional<PropagationLearner> learner;
  if (options.learn_propagation) {
    FACEDYN_ASSIGN_OR_RETURN(learner,
                             PropagationLearner::ForRig(*takes[0].rig, options.propagation));
  }
  std::vector<FrameRange> ranges;  // per take, the frames usable for training
  long usable_frames = 0;
  for (size_t k = 0; k < takes.size(); ++k) {
    const Take& take = *takes[k].take;
    const FaceRig& rig = *takes[k].rig;
    const std::string context =
        "training take " + std::to_string(k) +
        (take.info.expression.empty() ? "" : " (" + take.info.expression + ")");
    if (Status status = config.CheckCompatible(take, rig); !status.ok()) {
      return status.WithContext(context);
    }
    StatusOr<RemovalTakeFeatures> features = ComputeRemovalFeatures(take, rig, config.features);
    if (!features.ok()) return features.status().WithContext(context);
    // The targets, and the half-window (frames) over which they were estimated: frames nearer
    // the ends than that have edge-clamped estimates (for the platform-synchronous fit, whose
    // window spans 1.5 platform periods, up to 0.3 mm wrong on a 11 Hz take) and are not used.
    int target_window = 0;
    const RemovalTargets kind = takes[k].targets.value_or(options.targets);
    auto targets = [&]() -> StatusOr<PointCache> {
      if (kind == RemovalTargets::kExact) {
        const auto channel = take.channels.find("quasistatic");
        if (channel == take.channels.end()) {
          return FailedPreconditionError(
              "exact targets requested but the take has no quasistatic channel (only simulated "
              "takes have one)");
        }
        return DynamicOffsets(take.positions, channel->second, take.world_from_skull);
      }
      QuasistaticOptions quasistatic;
      quasistatic.window_s = options.window_s;
      const bool platform_fit_if_known = kind == RemovalTargets::kPlatformSynchronousWhereKnown ||
                                         kind == RemovalTargets::kPlatformSynchronousElseHeldMean;
      if (kind == RemovalTargets::kPlatformSynchronous ||
          (platform_fit_if_known && take.info.platform_hz)) {
        quasistatic.method = QuasistaticMethod::kPlatformSynchronous;
        quasistatic.trend_degree = options.target_trend_degree;
        quasistatic.min_periods = options.target_min_periods;
      } else if (kind == RemovalTargets::kHeldMean ||
                 kind == RemovalTargets::kPlatformSynchronousElseHeldMean) {
        quasistatic.method = QuasistaticMethod::kHeldMean;
      }
      FACEDYN_ASSIGN_OR_RETURN(Take estimate, ExtractQuasistatic(take, quasistatic));
      target_window = estimate.info.metadata.value("quasistatic_window_frames", 0);
      return std::move(estimate.channels.at("dynamic_offset"));
    };
    StatusOr<PointCache> offsets = targets();
    if (!offsets.ok()) return offsets.status().WithContext(context);
    const int margin = std::max(window, target_window);
    // Estimated targets assume a held expression: frames before the take's hold start are not
    // trained on (training_frames.h). Exact targets hold everywhere.
    const FrameRange range = UsableFrames(take, margin, kind != RemovalTargets::kExact);
    if (learner && !range.empty()) {
      if (Status status = learner->Add(*offsets, range.begin, range.end); !status.ok()) {
        return status.WithContext(context);
      }
    }
    data.Add(std::move(features).value(), SampleCache(*offsets, rig.skin_samples));
    ranges.push_back(range);
    usable_frames += range.size();
  }
  if (usable_frames == 0) {
    return FailedPreconditionError(
        "train-removal: no take has a frame whose feature (or target estimate) window lies "
        "inside its held part (at least " +
        std::to_string(2 * window + 2) + " frames after hold_start_s)");
  }

  // Validation by contiguous blocks with a gap, seeded (training_frames.h).
  const FrameSplit split =
      SplitByBlocks(ranges, options.validation_fraction, ValidationBlockFrames(window),
                    ValidationGapFrames(window), options.train.seed);
  std::vector<double> weights;
  for (const TrainingTake& training : takes) weights.push_back(training.weight);
  const std::vector<TakeFrame> weighted_train =
      WeightedFrames(split.train, weights, options.train.seed);
  std::vector<long> train_rows, validation_rows;
  for (const auto& [frames, rows] : {std::pair{&weighted_train, &train_rows},
                                     std::pair{&split.validation, &validation_rows}}) {
    for (const TakeFrame& frame : *frames) {
      for (int i = 0; i < config.sample_count; ++i) {
        rows->push_back(data.RowOf(frame.first, frame.second, i));
      }
    }
  }
  RemovalTrainingData result;
  result.config = config;
  result.data = std::move(owned_data);
  result.train_rows = std::move(train_rows);
  result.validation_rows = std::move(validation_rows);
  result.learner = std::move(learner);
  return result;
}

StatusOr<RemovalModel> TrainRemoval(const std::vector<TrainingTake>& takes,
                                    const RemovalTrainOptions& options,
                                    learn::MlpTrainSummary* summary) {
  FACEDYN_ASSIGN_OR_RETURN(RemovalTrainingData training, BuildRemovalTrainingData(takes, options));
  FACEDYN_ASSIGN_OR_RETURN(RemovalModel model,
                           RemovalModel::Create(training.config, options.train.seed));
  FACEDYN_RETURN_IF_ERROR(learn::TrainMlp(*training.data, training.train_rows,
                                          training.validation_rows, options.train,
                                          model.mutable_mlp(), summary));
  if (training.learner) {
    FACEDYN_ASSIGN_OR_RETURN(SamplePropagation learned, training.learner->Fit());
    model.set_propagation(std::move(learned));
  }
  return model;
}

StatusOr<const SamplePropagation*> SelectPropagation(const SamplePropagation* model_propagation,
                                                     const SamplePropagation* fallback,
                                                     const FaceRig& rig,
                                                     std::optional<SamplePropagation>* built) {
  if (model_propagation != nullptr) {
    if (model_propagation->vertex_count() != rig.vertex_count()) {
      return FailedPreconditionError(
          "vertex_count: the model's propagation was learned on a rig with " +
          std::to_string(model_propagation->vertex_count()) + " vertices, this rig has " +
          std::to_string(rig.vertex_count()));
    }
    return model_propagation;
  }
  if (fallback != nullptr) return fallback;
  FACEDYN_ASSIGN_OR_RETURN(*built, SamplePropagation::Build(rig));
  return &**built;
}

StatusOr<Eigen::MatrixXf> PredictSampleOffsets(const RemovalModel& model, const Take& take,
                                               const FaceRig& rig) {
  FACEDYN_RETURN_IF_ERROR(model.CheckCompatible(take, rig));
  const RemovalConfig& config = model.config();
  FACEDYN_ASSIGN_OR_RETURN(const RemovalTakeFeatures features,
                           ComputeRemovalFeatures(take, rig, config.features));
  const int frame_count = take.frame_count();
  const int sample_count = config.sample_count;
  const int skull_size = static_cast<int>(features.skull.rows());
  const int skin_size = static_cast<int>(features.skin.rows());
  Eigen::MatrixXf sample_offsets(3, static_cast<Eigen::Index>(frame_count) * sample_count);
  // Batches of whole frames, about 16k rows: large enough for an efficient GEMM, small enough
  // to stay in cache-friendly memory.
  const int chunk_frames = std::max(1, 16384 / sample_count);
  Eigen::MatrixXf inputs;
  for (int t0 = 0; t0 < frame_count; t0 += chunk_frames) {
    const int t1 = std::min(frame_count, t0 + chunk_frames);
    inputs.resize(skull_size + skin_size, static_cast<Eigen::Index>(t1 - t0) * sample_count);
    for (int t = t0; t < t1; ++t) {
      const Eigen::Index base = static_cast<Eigen::Index>(t - t0) * sample_count;
      inputs.middleCols(base, sample_count).topRows(skull_size).colwise() = features.skull.col(t);
      inputs.middleCols(base, sample_count).bottomRows(skin_size) =
          features.skin.middleCols(static_cast<Eigen::Index>(t) * sample_count, sample_count);
    }
    sample_offsets.middleCols(static_cast<Eigen::Index>(t0) * sample_count, inputs.cols()) =
        model.Predict(inputs);
  }
  return sample_offsets;
}

void ComposeOffsets(const Take& take, const SamplePropagation& propagation,
                    const Eigen::MatrixXf& sample_offsets, float sign, PointCache* vertex_offsets,
                    PointCache* positions) {
  const int frame_count = take.frame_count();
  const int sample_count = propagation.sample_count();
  FACEDYN_CHECK(sample_offsets.cols() == static_cast<Eigen::Index>(frame_count) * sample_count,
                "ComposeOffsets: sample offsets do not match the take");
  *vertex_offsets = take.positions;
  *positions = take.positions;
  for (int t = 0; t < frame_count; ++t) {
    Eigen::Map<Eigen::Matrix3Xf> offset = vertex_offsets->Frame(t);
    propagation.Apply(
        sample_offsets.middleCols(static_cast<Eigen::Index>(t) * sample_count, sample_count),
        offset);
    const Eigen::Matrix3f rotation = take.world_from_skull[t].RotationMatrix().cast<float>();
    positions->Frame(t).noalias() += (sign * rotation) * offset;
  }
}

Take RemoveSampleOffsets(const Take& take, const SamplePropagation& propagation,
                         const Eigen::Ref<const Eigen::MatrixXf>& sample_offsets,
                         const std::string& source) {
  Take result;
  result.info = take.info;
  result.info.source = source;
  result.info.metadata["removal_propagation"] = propagation.method();
  result.topology = take.topology;
  result.time_s = take.time_s;
  result.world_from_skull = take.world_from_skull;
  result.skull_from_jaw = take.skull_from_jaw;
  PointCache offsets;
  ComposeOffsets(take, propagation, sample_offsets, -1.0f, &offsets, &result.positions);
  result.channels["dynamic_offset"] = std::move(offsets);
  return result;
}

StatusOr<Take> RemoveDynamics(const RemovalModel& model, const Take& take, const FaceRig& rig,
                              const SamplePropagation* propagation, RemovalSummary* summary) {
  const auto start = std::chrono::steady_clock::now();
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXf sample_offsets,
                           PredictSampleOffsets(model, take, rig));
  const double predict_s = SecondsSince(start);

  const auto propagate_start = std::chrono::steady_clock::now();
  std::optional<SamplePropagation> built;
  FACEDYN_ASSIGN_OR_RETURN(propagation,
                           SelectPropagation(model.propagation(), propagation, rig, &built));
  Take result = RemoveSampleOffsets(take, *propagation, sample_offsets, "dynamics remove");
  result.info.metadata["removal_sample_count"] = model.config().sample_count;
  result.info.metadata["removal_window_frames"] = model.config().features.window_frames();
  const double propagate_s = SecondsSince(propagate_start);
  if (summary != nullptr) {
    summary->predict_s = predict_s;
    summary->propagate_s = propagate_s;
    const double total = predict_s + propagate_s;
    summary->frames_per_s = total > 0 ? take.frame_count() / total : 0.0;
  }
  return result;
}

}  // namespace facedyn::dynamics
