#include "dynamics/modal_synthesis.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>

#include "core/binary_io.h"
#include "core/check.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "dynamics/baselines.h"
#include "dynamics/feature_spec.h"
#include "dynamics/synthesis_model.h"
#include "dynamics/training_frames.h"

namespace facedyn::dynamics {
namespace {

constexpr int kInputs = 6;  // a (3) and alpha (3)
constexpr char kMagic[8] = {'F', 'D', 'M', 'O', 'D', 'A', 'L', '\0'};
constexpr char kTrailer[4] = {'E', 'N', 'D', '.'};
constexpr uint32_t kModalFormatVersion = 1;
constexpr int64_t kMaxResonators = 1000;
constexpr int64_t kMaxSamples = 1'000'000;
constexpr int64_t kMaxVertices = 10'000'000;

int RegressorCount(int resonators) { return kInputs * (2 * resonators + 1) + 1; }

// One resonator w^2 / (s^2 + 2 z w s + w^2) by the bilinear transform prewarped at w, run over
// `input` from rest at input(0) (the filter's steady state for a constant input, gain 1).
Eigen::VectorXd Resonate(const Eigen::VectorXd& input, double hz, double damping, double fps) {
  const double w = 2.0 * M_PI * hz;
  const double k = w / std::tan(w / (2.0 * fps));
  const double a0 = k * k + 2.0 * damping * w * k + w * w;
  const double a1 = (2.0 * w * w - 2.0 * k * k) / a0;
  const double a2 = (k * k - 2.0 * damping * w * k + w * w) / a0;
  const double b0 = w * w / a0, b1 = 2.0 * b0, b2 = b0;
  Eigen::VectorXd out(input.size());
  if (input.size() == 0) return out;
  double u1 = input(0), u2 = input(0), y1 = input(0), y2 = input(0);
  for (Eigen::Index t = 0; t < input.size(); ++t) {
    const double u = input(t);
    const double y = b0 * u + b1 * u1 + b2 * u2 - a1 * y1 - a2 * y2;
    out(t) = y;
    u2 = u1;
    u1 = u;
    y2 = y1;
    y1 = y;
  }
  return out;
}

// Rotation vector (rad) of a unit quaternion, shortest way.
Eigen::Vector3d RotationVector(Eigen::Quaterniond q) {
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const Eigen::AngleAxisd aa(q);
  return aa.angle() * aa.axis();
}

}  // namespace

Status ModalSynthesisOptions::Check() const {
  if (resonator_hz.empty()) return InvalidArgumentError("resonator_hz: at least one frequency");
  for (double hz : resonator_hz) {
    if (!(hz > 0 && hz < 1000)) {
      return InvalidArgumentError(fmt::format("resonator_hz: {} not in (0, 1000)", hz));
    }
  }
  if (!(resonator_damping > 0 && resonator_damping <= 2)) {
    return InvalidArgumentError("resonator_damping must be in (0, 2]");
  }
  if (ridge.empty()) return InvalidArgumentError("ridge: at least one weight");
  for (double r : ridge) {
    if (!(r > 0 && std::isfinite(r))) {
      return InvalidArgumentError(fmt::format("ridge: {} is not a positive weight", r));
    }
  }
  if (!(validation_fraction > 0 && validation_fraction <= 0.9)) {
    return InvalidArgumentError("validation_fraction must be in (0, 0.9]");
  }
  if (!(margin_s >= 0 && margin_s <= 1)) return InvalidArgumentError("margin_s must be in [0, 1]");
  if (Status status = propagation.Check(); !status.ok()) return status.WithContext("propagation");
  return Status::Ok();
}

const char* RidgeRuleName(RidgeRule rule) {
  switch (rule) {
    case RidgeRule::kMinimum:
      return "minimum";
    case RidgeRule::kOneStandardError:
      return "one-standard-error";
  }
  return "unknown";
}

namespace {
constexpr RidgeRule kRidgeRules[] = {RidgeRule::kMinimum, RidgeRule::kOneStandardError};
}  // namespace

std::vector<std::string> RidgeRuleNames() {
  std::vector<std::string> names;
  for (RidgeRule rule : kRidgeRules) names.emplace_back(RidgeRuleName(rule));
  return names;
}

StatusOr<RidgeRule> ParseRidgeRule(const std::string& name) {
  for (RidgeRule rule : kRidgeRules) {
    if (name == RidgeRuleName(rule)) return rule;
  }
  return InvalidArgumentError(
      fmt::format("ridge rule '{}' is not one of: {}", name, fmt::join(RidgeRuleNames(), ", ")));
}

StatusOr<Eigen::MatrixXd> SkullInertialInputs(const std::vector<Rigid3>& world_from_skull,
                                              double fps) {
  if (!(fps > 0)) return InvalidArgumentError("skull inertial inputs: fps must be > 0");
  const int n = static_cast<int>(world_from_skull.size());
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(kInputs, n);
  if (n < 3) return out;
  auto pose = [&](int t) -> const Rigid3& { return world_from_skull[std::clamp(t, 0, n - 1)]; };
  // Body angular velocity between frames t and t + 1, rad/s, in the skull frame at t.
  auto omega = [&](int t) {
    const Eigen::Quaterniond step = pose(t).rotation().conjugate() * pose(t + 1).rotation();
    return Eigen::Vector3d(RotationVector(step) * fps);
  };
  for (int t = 0; t < n; ++t) {
    const Eigen::Vector3d accel_world =
        (pose(t + 1).translation() - 2.0 * pose(t).translation() + pose(t - 1).translation()) *
        fps * fps;
    out.col(t).head<3>() = pose(t).rotation().conjugate() * accel_world;
    // omega(t - 1) is in the frame at t - 1: bring it to t before differencing.
    const Eigen::Vector3d previous =
        pose(t).rotation().conjugate() * (pose(t - 1).rotation() * omega(t - 1));
    out.col(t).tail<3>() = (omega(t) - previous) * fps;
  }
  // At the two end frames a clamped difference reads the take's cut as the head stopping dead:
  // an acceleration spike that never happened, which would ring through every resonator. The
  // end frames repeat their neighbours' values instead.
  out.col(0) = out.col(1);
  out.col(n - 1) = out.col(n - 2);
  return out;
}

StatusOr<Eigen::MatrixXd> ModalSynthesisModel::Regressors(
    const std::vector<Rigid3>& world_from_skull) const {
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd inputs,
                           SkullInertialInputs(world_from_skull, fps_));
  const int frames = static_cast<int>(inputs.cols());
  const int k_count = static_cast<int>(resonator_hz_.size());
  Eigen::MatrixXd x(RegressorCount(k_count), frames);
  int row = 0;
  for (int i = 0; i < kInputs; ++i) {
    const Eigen::VectorXd u = inputs.row(i).transpose() / input_scale_(i);
    for (int k = 0; k < k_count; ++k) {
      const Eigen::VectorXd y = Resonate(u, resonator_hz_[k], resonator_damping_, fps_);
      x.row(row++) = y.transpose();
      // The previous frame's value (the mode's velocity, with the current one).
      for (int t = 0; t < frames; ++t) x(row, t) = y(std::max(t - 1, 0));
      ++row;
    }
    x.row(row++) = u.transpose();
  }
  x.row(row++).setOnes();
  FACEDYN_CHECK(row == x.rows(), "ModalSynthesisModel: regressor count");
  return x;
}

StatusOr<ModalSynthesisModel> ModalSynthesisModel::Train(
    const std::vector<TrainingTake>& decomposed, const ModalSynthesisOptions& options,
    ModalSynthesisFit* fit) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  if (decomposed.empty()) return InvalidArgumentError("modal synthesis: no training takes");
  FACEDYN_RETURN_IF_ERROR(CheckNoTargetsOrWeights(decomposed, "modal synthesis"));
  for (const TrainingTake& training : decomposed) {
    FACEDYN_CHECK(training.take != nullptr && training.rig != nullptr,
                  "ModalSynthesisModel::Train: training take without take or rig");
  }
  const FaceRig& rig = *decomposed.front().rig;
  ModalSynthesisModel model;
  model.rig_name_ = rig.name;
  model.fps_ = decomposed.front().take->info.fps;
  model.resonator_hz_ = options.resonator_hz;
  model.resonator_damping_ = options.resonator_damping;
  model.sample_count_ = static_cast<int>(rig.skin_samples.size());
  model.samples_hash_ = HashSurfacePoints(rig.skin_samples);
  for (double hz : options.resonator_hz) {
    if (hz >= model.fps_ / 2) {
      return InvalidArgumentError(fmt::format(
          "modal synthesis: resonator {} Hz is not below the takes' Nyquist frequency ({} Hz)", hz,
          model.fps_ / 2));
    }
  }
  const int margin = WindowFrames(options.margin_s, model.fps_);
  // The resonators start from rest at the first frame's input, not from the motion's true
  // history: their state is unreliable until the slowest has decayed by e (1 / (z w_min)).
  const double slowest_hz =
      *std::min_element(options.resonator_hz.begin(), options.resonator_hz.end());
  const int settle = static_cast<int>(
      std::ceil(model.fps_ / (options.resonator_damping * 2.0 * M_PI * slowest_hz)));

  // The inputs' scales first (over every take's usable frames), so the ridge sees regressors
  // of comparable size.
  std::vector<Eigen::MatrixXd> inputs;
  std::vector<FrameRange> ranges;
  Eigen::VectorXd sum_sq = Eigen::VectorXd::Zero(kInputs);
  long usable = 0;
  for (size_t n = 0; n < decomposed.size(); ++n) {
    const Take& take = *decomposed[n].take;
    const std::string context =
        fmt::format("modal synthesis: training take {}{}", n,
                    take.info.expression.empty() ? "" : " (" + take.info.expression + ")");
    FACEDYN_RETURN_IF_ERROR(CheckDecomposed(take, context));
    if (std::abs(take.info.fps - model.fps_) > 1e-6 * model.fps_) {
      return FailedPreconditionError(
          fmt::format("{}: {} fps, the first take {} fps", context, take.info.fps, model.fps_));
    }
    if (HashSurfacePoints(decomposed[n].rig->skin_samples) != model.samples_hash_ ||
        take.vertex_count() != rig.vertex_count()) {
      return FailedPreconditionError(context + ": another rig than the first take's");
    }
    if (static_cast<int>(take.world_from_skull.size()) != take.frame_count()) {
      return FailedPreconditionError(context + ": not one skull pose per frame");
    }
    FACEDYN_ASSIGN_OR_RETURN(Eigen::MatrixXd u,
                             SkullInertialInputs(take.world_from_skull, model.fps_));
    FrameRange range = UsableFrames(take, margin, true);
    range.begin = std::max(range.begin, settle);
    for (int t = range.begin; t < range.end; ++t) sum_sq += u.col(t).cwiseAbs2();
    usable += range.size();
    inputs.push_back(std::move(u));
    ranges.push_back(range);
  }
  if (usable == 0) {
    return FailedPreconditionError(fmt::format(
        "modal synthesis: no take has a frame {} frames from its end, {} from its start and "
        "after its hold start",
        margin, settle));
  }
  model.input_scale_ = (sum_sq / static_cast<double>(usable)).cwiseSqrt();
  for (int i = 0; i < kInputs; ++i) {
    // A motion without this component (e.g. no rotation): any scale keeps the zeros zero.
    if (!(model.input_scale_(i) > 1e-12)) model.input_scale_(i) = 1.0;
  }

  // Regressors and targets of every usable frame.
  const int p = RegressorCount(static_cast<int>(options.resonator_hz.size()));
  const int outputs = 3 * model.sample_count_;
  std::vector<Eigen::MatrixXd> regressors(decomposed.size());
  std::vector<Eigen::MatrixXd> targets(decomposed.size());
  std::optional<PropagationLearner> learner;
  if (options.learn_propagation) {
    FACEDYN_ASSIGN_OR_RETURN(learner, PropagationLearner::ForRig(rig, options.propagation));
  }
  for (size_t n = 0; n < decomposed.size(); ++n) {
    const Take& take = *decomposed[n].take;
    FACEDYN_ASSIGN_OR_RETURN(regressors[n], model.Regressors(take.world_from_skull));
    const PointCache& offsets = take.channels.at("dynamic_offset");
    targets[n] = SampleOffsetsByFrame(offsets, rig.skin_samples).cast<double>();
    if (learner && !ranges[n].empty()) {
      FACEDYN_RETURN_IF_ERROR(learner->Add(offsets, ranges[n].begin, ranges[n].end));
    }
  }

  // Validation folds. The model is used on head motions it never saw, so with two or more
  // takes each take is a fold (leave one take out): a ridge that only interpolates within a
  // motion scores badly there. With one take, validation blocks as the networks draw them.
  std::vector<std::vector<int>> fold_of(decomposed.size());  // per frame, -1: no fold
  for (size_t n = 0; n < decomposed.size(); ++n) {
    fold_of[n].assign(decomposed[n].take->frame_count(), -1);
  }
  int folds = 0;
  long takes_with_frames = 0;
  for (const FrameRange& range : ranges) takes_with_frames += range.empty() ? 0 : 1;
  ModalSynthesisFit result;
  if (takes_with_frames >= 2) {
    for (size_t n = 0; n < decomposed.size(); ++n) {
      if (ranges[n].empty()) continue;
      for (int t = ranges[n].begin; t < ranges[n].end; ++t) fold_of[n][t] = folds;
      ++folds;
    }
    result.validation = "leave one take out";
  } else {
    const FrameSplit split =
        SplitByBlocks(ranges, options.validation_fraction, ValidationBlockFrames(margin),
                      ValidationGapFrames(margin), options.seed);
    for (const TakeFrame& frame : split.validation) fold_of[frame.first][frame.second] = 0;
    folds = split.validation.empty() ? 0 : 1;
    result.validation = "blocks of the one take";
  }
  Eigen::MatrixXd gram_all = Eigen::MatrixXd::Zero(p, p);
  Eigen::MatrixXd cross_all = Eigen::MatrixXd::Zero(p, outputs);
  std::vector<Eigen::MatrixXd> gram_fold(folds, gram_all);
  std::vector<Eigen::MatrixXd> cross_fold(folds, cross_all);
  for (size_t n = 0; n < decomposed.size(); ++n) {
    for (int t = ranges[n].begin; t < ranges[n].end; ++t) {
      const auto x = regressors[n].col(t);
      const auto y = targets[n].col(t);
      gram_all.noalias() += x * x.transpose();
      cross_all.noalias() += x * y.transpose();
      if (const int fold = fold_of[n][t]; fold >= 0) {
        gram_fold[fold].noalias() += x * x.transpose();
        cross_fold[fold].noalias() += x * y.transpose();
        ++result.validation_frames;
      }
    }
  }
  // The constant (last) regressor is not penalised.
  auto solve = [&](const Eigen::MatrixXd& gram, const Eigen::MatrixXd& cross, double ridge) {
    Eigen::MatrixXd a = gram;
    const double scale = gram.diagonal().head(p - 1).mean();
    a.diagonal().head(p - 1).array() += ridge * std::max(scale, 1e-12);
    a(p - 1, p - 1) += 1e-12 * std::max(scale, 1.0);
    return Eigen::MatrixXd(a.ldlt().solve(cross));
  };
  result.training_frames = usable;
  result.ridge_rule = options.ridge_rule;
  result.chosen_ridge = options.ridge.front();
  std::vector<double> mean_relative;  // per ridge, the mean over folds of squared error / energy
  // Each fold needs frames outside it to fit on: two folds or more, or blocks of one take.
  if (folds >= 2 || (folds == 1 && result.validation_frames < usable)) {
    for (double ridge : options.ridge) {
      // Each fold's squared error relative to its offsets' energy, averaged over the folds:
      // every held-out motion counts the same whatever its amplitude (a walk's offsets are a
      // fifth of a platform take's).
      double sq = 0.0, relative = 0.0;
      std::vector<double> fold_relative;
      for (int fold = 0; fold < folds; ++fold) {
        const Eigen::MatrixXd w =
            solve(gram_all - gram_fold[fold], cross_all - cross_fold[fold], ridge);
        double fold_sq = 0.0, fold_energy = 0.0;
        for (size_t n = 0; n < decomposed.size(); ++n) {
          for (int t = ranges[n].begin; t < ranges[n].end; ++t) {
            if (fold_of[n][t] != fold) continue;
            fold_sq += (w.transpose() * regressors[n].col(t) - targets[n].col(t)).squaredNorm();
            fold_energy += targets[n].col(t).squaredNorm();
          }
        }
        sq += fold_sq;
        fold_relative.push_back(fold_sq / std::max(fold_energy, 1e-12));
        relative += fold_relative.back() / folds;
      }
      double variance = 0.0;
      for (double r : fold_relative) variance += (r - relative) * (r - relative);
      result.validation_standard_error.push_back(
          folds >= 2 ? std::sqrt(variance / (folds - 1) / folds) : 0.0);
      mean_relative.push_back(relative);
      result.validation_rms_mm.push_back(
          std::sqrt(sq / (static_cast<double>(result.validation_frames) * model.sample_count_)));
      result.validation_relative.push_back(std::sqrt(relative));
    }
    size_t best = 0;
    for (size_t r = 1; r < mean_relative.size(); ++r)
      if (mean_relative[r] < mean_relative[best]) best = r;
    size_t chosen = best;
    if (options.ridge_rule == RidgeRule::kOneStandardError && folds >= 2) {
      const double bound = mean_relative[best] + result.validation_standard_error[best];
      for (size_t r = 0; r < mean_relative.size(); ++r)
        if (mean_relative[r] <= bound && options.ridge[r] > options.ridge[chosen]) chosen = r;
    }
    result.chosen_ridge = options.ridge[chosen];
    model.validation_residual_ = std::sqrt(mean_relative[chosen]);
  }
  model.weights_ = solve(gram_all, cross_all, result.chosen_ridge);
  if (!model.weights_.allFinite()) {
    return InternalError("modal synthesis: the ridge solve gave non-finite weights");
  }
  if (learner) {
    FACEDYN_ASSIGN_OR_RETURN(SamplePropagation learned, learner->Fit());
    model.propagation_ = std::move(learned);
  }
  if (fit != nullptr) *fit = result;
  return model;
}

Status ModalSynthesisModel::CheckRig(const FaceRig& rig) const {
  if (static_cast<int>(rig.skin_samples.size()) != sample_count_ ||
      HashSurfacePoints(rig.skin_samples) != samples_hash_) {
    return FailedPreconditionError(fmt::format(
        "modal synthesis: the rig \"{}\"'s skin samples ({}) are not the model's ({}, trained "
        "on rig \"{}\")",
        rig.name, rig.skin_samples.size(), sample_count_, rig_name_));
  }
  return Status::Ok();
}

StatusOr<Eigen::MatrixXf> ModalSynthesisModel::PredictSampleOffsets(
    const std::vector<Rigid3>& world_from_skull) const {
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd x, Regressors(world_from_skull));
  return Eigen::MatrixXf((weights_.transpose() * x).cast<float>());
}

StatusOr<Take> ModalSynthesisModel::Synthesize(const Take& quasistatic,
                                               const std::vector<Rigid3>& world_from_skull,
                                               const std::string& motion_name,
                                               const FaceRig& rig) const {
  FACEDYN_RETURN_IF_ERROR(CheckRig(rig));
  if (std::abs(quasistatic.info.fps - fps_) > 1e-6 * fps_) {
    return FailedPreconditionError(
        fmt::format("modal synthesis: the take is at {} fps, the model was trained at {} fps",
                    quasistatic.info.fps, fps_));
  }
  if (static_cast<int>(world_from_skull.size()) != quasistatic.frame_count()) {
    return InvalidArgumentError(
        fmt::format("modal synthesis: the head motion has {} poses, the quasistatic take {} frames",
                    world_from_skull.size(), quasistatic.frame_count()));
  }
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXf by_frame, PredictSampleOffsets(world_from_skull));
  std::optional<SamplePropagation> built;
  FACEDYN_ASSIGN_OR_RETURN(
      const SamplePropagation* propagation,
      SelectPropagation(propagation_ ? &*propagation_ : nullptr, nullptr, rig, &built));
  return ComposeSynthesis(quasistatic, world_from_skull, "dynamics modal synthesis", motion_name,
                          *propagation, by_frame);
}

StatusOr<Take> ModalSynthesisModel::Remove(const Take& captured, const FaceRig& rig) const {
  FACEDYN_RETURN_IF_ERROR(CheckRig(rig));
  if (std::abs(captured.info.fps - fps_) > 1e-6 * fps_) {
    return FailedPreconditionError(
        fmt::format("modal removal: the take is at {} fps, the model was trained at {} fps",
                    captured.info.fps, fps_));
  }
  if (static_cast<int>(captured.world_from_skull.size()) != captured.frame_count()) {
    return FailedPreconditionError(
        fmt::format("modal removal: the take has {} skull poses for {} frames",
                    captured.world_from_skull.size(), captured.frame_count()));
  }
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXf by_frame,
                           PredictSampleOffsets(captured.world_from_skull));
  std::optional<SamplePropagation> built;
  FACEDYN_ASSIGN_OR_RETURN(
      const SamplePropagation* propagation,
      SelectPropagation(propagation_ ? &*propagation_ : nullptr, nullptr, rig, &built));
  // 3S x F is the memory of 3 x F*S with column t * S + i, the layout ComposeOffsets reads.
  const Eigen::Map<const Eigen::MatrixXf> sample_offsets(by_frame.data(), 3, by_frame.size() / 3);
  return RemoveSampleOffsets(captured, *propagation, sample_offsets, "dynamics modal removal");
}

StatusOr<Take> ModalSynthesisModel::RemoveThenLowPass(const Take& captured, const FaceRig& rig,
                                                      double* cutoff_hz) const {
  FACEDYN_ASSIGN_OR_RETURN(Take removed, Remove(captured, rig));
  const double cutoff = LowPassCutoffAfterRemoval(captured, validation_residual_);
  FACEDYN_ASSIGN_OR_RETURN(PointCache filtered, LowPassBaseline(removed, cutoff));
  // The offset channel follows: what was taken away in all, removal and filter.
  PointCache& offsets = removed.channels.at("dynamic_offset");
  for (int t = 0; t < removed.frame_count(); ++t) {
    const Eigen::Matrix3f to_skull =
        removed.world_from_skull[t].RotationMatrix().transpose().cast<float>();
    offsets.Frame(t) += to_skull * (removed.positions.Frame(t) - filtered.Frame(t));
  }
  removed.positions = std::move(filtered);
  removed.info.source = "dynamics modal removal + low-pass";
  removed.info.metadata["removal_lowpass_hz"] = cutoff;
  removed.info.metadata["removal_validation_residual"] = validation_residual_;
  if (cutoff_hz != nullptr) *cutoff_hz = cutoff;
  return removed;
}

bool IsModalModelFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  char magic[sizeof(kMagic)] = {};
  return in.read(magic, sizeof(magic)) && std::memcmp(magic, kMagic, sizeof(kMagic)) == 0;
}

Status ModalSynthesisModel::Save(const std::string& path) const {
  BinaryWriter w;
  w.Raw(kMagic, sizeof(kMagic));
  w.Pod<uint32_t>(kModalFormatVersion);
  w.Str(rig_name_);
  w.Pod(fps_);
  w.Doubles(resonator_hz_.data(), static_cast<int64_t>(resonator_hz_.size()));
  w.Pod(resonator_damping_);
  w.Pod(validation_residual_);
  w.Doubles(input_scale_.data(), input_scale_.size());
  w.Pod<int64_t>(sample_count_);
  w.Pod<uint64_t>(samples_hash_);
  w.Pod<int64_t>(weights_.rows());
  w.Doubles(weights_.data(), weights_.size());
  w.Pod<uint8_t>(propagation_ ? 1 : 0);
  if (propagation_) {
    w.Str(propagation_->method());
    w.Pod<int64_t>(propagation_->vertex_count());
    const Eigen::MatrixXf& p = propagation_->weights();
    w.Array(p.data(), p.size());
  }
  w.Raw(kTrailer, sizeof(kTrailer));
  return WriteFileAtomic(path, w.bytes());
}

StatusOr<ModalSynthesisModel> ModalSynthesisModel::Load(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(std::string bytes, ReadFileToString(path));
  BinaryReader r(std::move(bytes), path);
  FACEDYN_RETURN_IF_ERROR(r.Expect(kMagic, sizeof(kMagic), "the modal model's magic (FDMODAL)"));
  uint32_t version = 0;
  FACEDYN_RETURN_IF_ERROR(r.Pod(&version, "the format version"));
  if (version != kModalFormatVersion) {
    return DataLossError(fmt::format("{}: modal model format version {}, this facedyn reads {}",
                                     path, version, kModalFormatVersion));
  }
  ModalSynthesisModel model;
  FACEDYN_RETURN_IF_ERROR(r.Str(&model.rig_name_, "the rig's name"));
  FACEDYN_RETURN_IF_ERROR(r.Pod(&model.fps_, "fps"));
  FACEDYN_RETURN_IF_ERROR(r.Array(&model.resonator_hz_, -1, "the resonator frequencies"));
  FACEDYN_RETURN_IF_ERROR(r.Pod(&model.resonator_damping_, "the resonator damping"));
  FACEDYN_RETURN_IF_ERROR(r.Pod(&model.validation_residual_, "the validation residual"));
  std::vector<double> scale;
  FACEDYN_RETURN_IF_ERROR(r.Array(&scale, kInputs, "the input scales"));
  int64_t samples = 0;
  FACEDYN_RETURN_IF_ERROR(r.Count(&samples, kMaxSamples, "the sample count"));
  FACEDYN_RETURN_IF_ERROR(r.Pod(&model.samples_hash_, "the samples' hash"));
  int64_t rows = 0;
  FACEDYN_RETURN_IF_ERROR(r.Count(&rows, kInputs * (2 * kMaxResonators + 1) + 1, "W's rows"));
  std::vector<double> weights;
  FACEDYN_RETURN_IF_ERROR(r.Array(&weights, rows * 3 * samples, "W"));
  uint8_t has_propagation = 0;
  FACEDYN_RETURN_IF_ERROR(r.Pod(&has_propagation, "the propagation flag"));
  if (has_propagation > 1) {
    return DataLossError(fmt::format("{}: the propagation flag is {}", path, has_propagation));
  }
  // Values, not only counts: a model that would filter at or above Nyquist, or divide by a
  // zero scale, is as corrupt as a truncated one.
  const int resonators = static_cast<int>(model.resonator_hz_.size());
  if (!(model.fps_ > 0) || !std::isfinite(model.fps_) || resonators == 0 ||
      resonators > kMaxResonators || !(model.resonator_damping_ > 0) ||
      !(model.resonator_damping_ <= 2) || !(model.validation_residual_ >= 0) ||
      !std::isfinite(model.validation_residual_)) {
    return DataLossError(fmt::format(
        "{}: bad header (fps {}, {} resonators, damping {}, validation residual {})", path,
        model.fps_, resonators, model.resonator_damping_, model.validation_residual_));
  }
  for (double hz : model.resonator_hz_) {
    if (!(hz > 0) || !(hz < model.fps_ / 2)) {
      return DataLossError(
          fmt::format("{}: resonator at {} Hz, outside (0, {} Hz)", path, hz, model.fps_ / 2));
    }
  }
  if (rows != RegressorCount(resonators) || samples < 1) {
    return DataLossError(
        fmt::format("{}: W has {} rows for {} resonators (expected {}), {} samples", path, rows,
                    resonators, RegressorCount(resonators), samples));
  }
  model.input_scale_ = Eigen::Map<const Eigen::VectorXd>(scale.data(), kInputs);
  model.weights_ = Eigen::Map<const Eigen::MatrixXd>(weights.data(), rows, 3 * samples);
  if (!model.input_scale_.allFinite() || (model.input_scale_.array() <= 0).any() ||
      !model.weights_.allFinite()) {
    return DataLossError(fmt::format("{}: non-finite or non-positive values in the model", path));
  }
  model.sample_count_ = static_cast<int>(samples);
  if (has_propagation == 1) {
    std::string method;
    FACEDYN_RETURN_IF_ERROR(r.Str(&method, "the propagation's method"));
    int64_t vertices = 0;
    FACEDYN_RETURN_IF_ERROR(r.Count(&vertices, kMaxVertices, "the propagation's vertex count"));
    std::vector<float> p;
    FACEDYN_RETURN_IF_ERROR(r.Array(&p, vertices * samples, "the propagation"));
    auto propagation = SamplePropagation::FromWeights(
        Eigen::Map<const Eigen::MatrixXf>(p.data(), vertices, samples), method);
    if (!propagation.ok()) {
      return DataLossError(fmt::format("{}: {}", path, propagation.status().message()));
    }
    model.propagation_ = std::move(propagation).value();
  }
  FACEDYN_RETURN_IF_ERROR(r.Expect(kTrailer, sizeof(kTrailer), "the trailer (END.)"));
  if (!r.AtEnd()) {
    return DataLossError(fmt::format("{}: {} bytes after the trailer", path, r.remaining()));
  }
  return model;
}

}  // namespace facedyn::dynamics
