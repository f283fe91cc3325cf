#include "dynamics/joint_training.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "core/check.h"
#include "dynamics/training_frames.h"

namespace facedyn::dynamics {
namespace {

// The cycle's rows: one per performance frame (take * max_frames + frame); F's inputs are the
// frame's S samples [B(t); X_i(t)], H's the frame's [B(t); S(t)].
class CycleDataset final : public learn::MlpPairDataset {
 public:
  CycleDataset(int f_input_size, int h_input_size, int sample_count, int max_frames)
      : f_input_size_(f_input_size),
        h_input_size_(h_input_size),
        sample_count_(sample_count),
        max_frames_(max_frames) {}
  void Add(RemovalTakeFeatures removal, Eigen::MatrixXf synthesis) {
    removal_.push_back(std::move(removal));
    synthesis_.push_back(std::move(synthesis));
  }
  long RowOf(int take, int frame) const { return static_cast<long>(take) * max_frames_ + frame; }

  int first_input_size() const override { return f_input_size_; }
  int second_input_size() const override { return h_input_size_; }
  int group_size() const override { return sample_count_; }
  void Gather(const long* rows, long n, Eigen::MatrixXf* first,
              Eigen::MatrixXf* second) const override {
    first->resize(f_input_size_, n * sample_count_);
    second->resize(h_input_size_, n);
    for (long r = 0; r < n; ++r) {
      const int take = static_cast<int>(rows[r] / max_frames_);
      const int frame = static_cast<int>(rows[r] % max_frames_);
      const RemovalTakeFeatures& features = removal_[take];
      const Eigen::Index skull_size = features.skull.rows();
      for (int i = 0; i < sample_count_; ++i) {
        const Eigen::Index column = r * sample_count_ + i;
        first->col(column).head(skull_size) = features.skull.col(frame);
        first->col(column).tail(features.skin.rows()) =
            features.skin.col(static_cast<Eigen::Index>(frame) * sample_count_ + i);
      }
      second->col(r) = synthesis_[take].col(frame);
    }
  }

 private:
  int f_input_size_, h_input_size_, sample_count_, max_frames_;
  std::vector<RemovalTakeFeatures> removal_;
  std::vector<Eigen::MatrixXf> synthesis_;
};

// Step 3 on networks trained by steps 1-2 (or given): the cycle on the performances, beside
// each network's own supervised loss on its held rows.
Status FineTuneOnCycle(const RemovalTrainingData& f_data, const SynthesisTrainingData& h_data,
                       const std::vector<TrainingTake>& performances,
                       const JointTrainOptions& options, RemovalModel* f_model,
                       SynthesisModel* h_model, JointTrainSummary* local) {
  RemovalModel& f = *f_model;
  SynthesisModel& h = *h_model;
  int max_frames = 0;
  for (const TrainingTake& take : performances) {
    max_frames = std::max(max_frames, take.take->frame_count());
  }
  CycleDataset cycle(f.config().input_size(), h.config().input_size(), f.config().sample_count,
                     max_frames);
  const int window =
      std::max(f.config().features.window_frames(), h.config().features.window_frames());
  std::vector<FrameRange> ranges;
  for (size_t k = 0; k < performances.size(); ++k) {
    const Take& take = *performances[k].take;
    const FaceRig& rig = *performances[k].rig;
    const std::string context =
        fmt::format("performance {}{}", k,
                    take.info.expression.empty() ? "" : " (" + take.info.expression + ")");
    if (Status status = f.CheckCompatible(take, rig); !status.ok()) {
      return status.WithContext(context);
    }
    StatusOr<RemovalTakeFeatures> features = ComputeRemovalFeatures(take, rig, f.config().features);
    if (!features.ok()) return features.status().WithContext(context);
    // H's input: the stretch of step 1's quasistatic estimate (fixed here; see the header).
    StatusOr<Take> quasistatic = RemoveDynamics(f, take, rig);
    if (!quasistatic.ok()) return quasistatic.status().WithContext(context);
    StatusOr<Eigen::MatrixXf> inputs = SynthesisInputs(h, *quasistatic, take.world_from_skull, rig);
    if (!inputs.ok()) return inputs.status().WithContext(context);
    // Every frame whose windows lie inside the take: a performance has no hold to wait for.
    const FrameRange range = UsableFrames(take, window, false);
    if (range.empty()) {
      return FailedPreconditionError(fmt::format(
          "train-joint: {} has no frame whose feature window lies inside it (it needs more "
          "than {} frames)",
          context, 2 * window + 2));
    }
    cycle.Add(std::move(features).value(), std::move(inputs).value());
    ranges.push_back(range);
  }
  const FrameSplit split =
      SplitByBlocks(ranges, options.performance_validation_fraction, ValidationBlockFrames(window),
                    ValidationGapFrames(window), options.joint.seed);
  std::vector<long> cycle_rows, cycle_validation_rows;
  for (const TakeFrame& frame : split.train) {
    cycle_rows.push_back(cycle.RowOf(frame.first, frame.second));
  }
  for (const TakeFrame& frame : split.validation) {
    cycle_validation_rows.push_back(cycle.RowOf(frame.first, frame.second));
  }
  local->performance_frames = static_cast<long>(cycle_rows.size());
  local->performance_validation_frames = static_cast<long>(cycle_validation_rows.size());
  if (options.joint.keep_least_validation &&
      (f_data.validation_rows.empty() || cycle_validation_rows.empty())) {
    return FailedPreconditionError(fmt::format(
        "train-joint: early stopping needs held-out rows of F and of the cycle, and has {} of "
        "F (from the held takes) and {} performance frames held out; longer takes give them",
        f_data.validation_rows.size(), cycle_validation_rows.size()));
  }
  spdlog::info(
      "train-joint: 3/3, F and H together, the cycle on {} performance frames ({} held "
      "out)",
      local->performance_frames, local->performance_validation_frames);
  FACEDYN_RETURN_IF_ERROR(learn::TrainMlpPair(
      *f_data.data, f_data.train_rows, f_data.validation_rows, *h_data.data, h_data.train_rows,
      h_data.validation_rows, cycle, cycle_rows, cycle_validation_rows, options.joint,
      f.mutable_mlp(), h.mutable_mlp(), &local->joint));
  return Status::Ok();
}

// The performances: non-empty, each with a take and a rig, no targets or weights.
Status CheckPerformances(const std::vector<TrainingTake>& performances) {
  if (performances.empty()) return InvalidArgumentError("train-joint: no performance takes");
  FACEDYN_RETURN_IF_ERROR(CheckNoTargetsOrWeights(performances, "train-joint's performances"));
  for (const TrainingTake& take : performances) {
    FACEDYN_CHECK(take.take != nullptr && take.rig != nullptr,
                  "TrainJoint: performance without take or rig");
  }
  return Status::Ok();
}

// H's rows: the held takes decomposed by F (RemoveDynamics), kept in *decomposed.
StatusOr<SynthesisTrainingData> SynthesisRowsOfDecomposition(const RemovalModel& f,
                                                             const std::vector<TrainingTake>& held,
                                                             const SynthesisTrainOptions& options,
                                                             std::vector<Take>* decomposed) {
  decomposed->clear();
  decomposed->reserve(held.size());
  for (size_t k = 0; k < held.size(); ++k) {
    StatusOr<Take> removed = RemoveDynamics(f, *held[k].take, *held[k].rig);
    if (!removed.ok()) {
      return removed.status().WithContext(fmt::format("held take {}", k));
    }
    decomposed->push_back(std::move(removed).value());
  }
  std::vector<TrainingTake> h_takes;
  for (size_t k = 0; k < held.size(); ++k) h_takes.push_back({&(*decomposed)[k], held[k].rig});
  return BuildSynthesisTrainingData(h_takes, options);
}

}  // namespace

Status JointTrainOptions::Check() const {
  if (Status status = removal.Check(); !status.ok()) return status.WithContext("removal");
  if (Status status = synthesis.Check(); !status.ok()) return status.WithContext("synthesis");
  if (Status status = joint.Check(); !status.ok()) return status.WithContext("joint");
  if (!(performance_validation_fraction >= 0 && performance_validation_fraction <= 0.9)) {
    return InvalidArgumentError("performance_validation_fraction must be in [0, 0.9]");
  }
  return Status::Ok();
}

StatusOr<JointModels> TrainJoint(const std::vector<TrainingTake>& held,
                                 const std::vector<TrainingTake>& performances,
                                 const JointTrainOptions& options, JointTrainSummary* summary) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  if (held.empty()) return InvalidArgumentError("train-joint: no held-expression takes");
  FACEDYN_RETURN_IF_ERROR(CheckPerformances(performances));
  JointTrainSummary local;

  // 1. F on the held takes.
  spdlog::info("train-joint: 1/3, F on {} held takes", held.size());
  FACEDYN_ASSIGN_OR_RETURN(RemovalTrainingData f_data,
                           BuildRemovalTrainingData(held, options.removal));
  FACEDYN_ASSIGN_OR_RETURN(RemovalModel f,
                           RemovalModel::Create(f_data.config, options.removal.train.seed));
  FACEDYN_RETURN_IF_ERROR(learn::TrainMlp(*f_data.data, f_data.train_rows, f_data.validation_rows,
                                          options.removal.train, f.mutable_mlp(), &local.removal));
  if (f_data.learner) {
    FACEDYN_ASSIGN_OR_RETURN(SamplePropagation learned, f_data.learner->Fit());
    f.set_propagation(std::move(learned));
  }

  // 2. H on the held takes decomposed by F.
  spdlog::info("train-joint: 2/3, H on the held takes decomposed by F");
  std::vector<Take> decomposed;  // H's rows may refer to these takes: kept to the end
  FACEDYN_ASSIGN_OR_RETURN(SynthesisTrainingData h_data,
                           SynthesisRowsOfDecomposition(f, held, options.synthesis, &decomposed));
  FACEDYN_ASSIGN_OR_RETURN(SynthesisModel h,
                           SynthesisModel::Create(h_data.config, options.synthesis.train.seed));
  FACEDYN_RETURN_IF_ERROR(learn::TrainMlp(*h_data.data, h_data.train_rows, h_data.validation_rows,
                                          options.synthesis.train, h.mutable_mlp(),
                                          &local.synthesis));
  FACEDYN_RETURN_IF_ERROR(h.set_stretch_range(std::move(h_data.stretch_range)));
  if (h_data.learner) {
    FACEDYN_ASSIGN_OR_RETURN(SamplePropagation learned, h_data.learner->Fit());
    h.set_propagation(std::move(learned));
  }

  FACEDYN_RETURN_IF_ERROR(FineTuneOnCycle(f_data, h_data, performances, options, &f, &h, &local));
  if (summary != nullptr) *summary = std::move(local);
  return JointModels{std::move(f), std::move(h)};
}

StatusOr<JointModels> FineTuneJoint(const std::vector<TrainingTake>& held,
                                    const std::vector<TrainingTake>& performances, RemovalModel f,
                                    SynthesisModel h, const JointTrainOptions& options,
                                    JointTrainSummary* summary) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  if (held.empty()) return InvalidArgumentError("train-joint: no held-expression takes");
  FACEDYN_RETURN_IF_ERROR(CheckPerformances(performances));
  JointTrainSummary local;
  spdlog::info("train-joint: F's and H's rows of {} held takes (the networks are given)",
               held.size());
  FACEDYN_ASSIGN_OR_RETURN(RemovalTrainingData f_data,
                           BuildRemovalTrainingData(held, options.removal));
  // The rows are raw features (each network normalises its own inputs), so what must agree is
  // their layout: the network given and the one options.removal would make.
  auto same_layout = [](const auto& a, const auto& b) {  // RemovalConfig or SynthesisConfig
    return a.input_size() == b.input_size() && a.sample_count == b.sample_count &&
           a.features.window_frames() == b.features.window_frames() &&
           std::abs(a.features.fps - b.features.fps) <= 1e-9 * std::abs(b.features.fps);
  };
  auto layout = [](const auto& spec) {  // for the message only
    return fmt::format("{} inputs, {} samples, window {} frames at {:g} fps", spec.input_size(),
                       spec.sample_count, spec.features.window_frames(), spec.features.fps);
  };
  if (!same_layout(f.config(), f_data.config)) {
    return InvalidArgumentError(
        fmt::format("train-joint: the given F has {}, its rows from the held takes {}",
                    layout(f.config()), layout(f_data.config)));
  }
  std::vector<Take> decomposed;  // H's rows may refer to these takes: kept to the end
  FACEDYN_ASSIGN_OR_RETURN(SynthesisTrainingData h_data,
                           SynthesisRowsOfDecomposition(f, held, options.synthesis, &decomposed));
  if (!same_layout(h.config(), h_data.config)) {
    return InvalidArgumentError(
        fmt::format("train-joint: the given H has {}, its rows from the decomposed held takes {}",
                    layout(h.config()), layout(h_data.config)));
  }
  FACEDYN_RETURN_IF_ERROR(FineTuneOnCycle(f_data, h_data, performances, options, &f, &h, &local));
  if (summary != nullptr) *summary = std::move(local);
  return JointModels{std::move(f), std::move(h)};
}

}  // namespace facedyn::dynamics
