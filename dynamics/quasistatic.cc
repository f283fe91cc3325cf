#include "dynamics/quasistatic.h"

#include <Eigen/Dense>
#include <cmath>
#include <string>

#include "dynamics/features.h"

namespace facedyn::dynamics {

const char* QuasistaticMethodName(QuasistaticMethod method) {
  switch (method) {
    case QuasistaticMethod::kPlatformSynchronous:
      return "platform-synchronous";
    case QuasistaticMethod::kHeldMean:
      return "held-mean";
    case QuasistaticMethod::kMovingAverage:
      break;
  }
  return "moving-average";
}

Status QuasistaticOptions::Check() const {
  if (!std::isfinite(window_s) || window_s < 0.0 || window_s > 1.0) {
    return InvalidArgumentError("QuasistaticOptions.window_s must be in [0, 1] s, got " +
                                std::to_string(window_s));
  }
  if (platform_hz && !(std::isfinite(*platform_hz) && *platform_hz > 0)) {
    return InvalidArgumentError("QuasistaticOptions.platform_hz must be > 0 Hz, got " +
                                std::to_string(*platform_hz));
  }
  if (harmonics < 1 || harmonics > 4) {
    return InvalidArgumentError("QuasistaticOptions.harmonics must be in 1..4, got " +
                                std::to_string(harmonics));
  }
  if (trend_degree < 0 || trend_degree > 4) {
    return InvalidArgumentError("QuasistaticOptions.trend_degree must be in 0..4, got " +
                                std::to_string(trend_degree));
  }
  if (!(min_periods >= 1 && min_periods <= 10)) {
    return InvalidArgumentError("QuasistaticOptions.min_periods must be in [1, 10], got " +
                                std::to_string(min_periods));
  }
  return Status::Ok();
}

StatusOr<std::vector<double>> PlatformSynchronousWeights(double fps, double platform_hz,
                                                         int half_window_frames, int harmonics,
                                                         int trend_degree) {
  if (!(fps > 0) || !(platform_hz > 0) || half_window_frames < 1 || harmonics < 1) {
    return InvalidArgumentError("platform-synchronous weights: fps, platform_hz, window and "
                                "harmonics must be positive");
  }
  if (trend_degree < 0 || trend_degree > 4) {
    return InvalidArgumentError("platform-synchronous weights: trend_degree must be in 0..4, got " +
                                std::to_string(trend_degree));
  }
  if (harmonics * platform_hz >= 0.5 * fps) {
    return InvalidArgumentError(
        "platform_hz: harmonic " + std::to_string(harmonics) + " of " +
        std::to_string(platform_hz) + " Hz is at or above the Nyquist frequency of " +
        std::to_string(fps) + " fps (fit fewer harmonics)");
  }
  const int length = 2 * half_window_frames + 1;
  const int columns = 1 + trend_degree + 2 * harmonics;
  Eigen::MatrixXd basis(length, columns);
  for (int k = -half_window_frames; k <= half_window_frames; ++k) {
    const int row = k + half_window_frames;
    // Polynomial in the offset scaled to [-1, 1] (conditioning); its value at k = 0 is the
    // constant's coefficient, so e_0 still picks the quasistatic at the centre.
    const double u = static_cast<double>(k) / half_window_frames;
    double power = 1.0;
    for (int d = 0; d <= trend_degree; ++d, power *= u) basis(row, d) = power;
    for (int h = 1; h <= harmonics; ++h) {
      const double phase = 2.0 * M_PI * h * platform_hz * k / fps;
      basis(row, trend_degree + 2 * h - 1) = std::sin(phase);
      basis(row, trend_degree + 2 * h) = std::cos(phase);
    }
  }
  const Eigen::MatrixXd normal = basis.transpose() * basis;
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(normal);
  const double condition = svd.singularValues()(0) / svd.singularValues()(columns - 1);
  if (!(condition < 1e8)) {
    return InvalidArgumentError("platform-synchronous window of " + std::to_string(length) +
                                " frames is too short for " + std::to_string(platform_hz) +
                                " Hz (ill-conditioned fit)");
  }
  const Eigen::VectorXd weights =
      basis * normal.ldlt().solve(Eigen::VectorXd::Unit(columns, 0));
  return std::vector<double>(weights.data(), weights.data() + weights.size());
}

namespace {

Status CheckPoses(const PointCache& positions, const std::vector<Rigid3>& world_from_skull) {
  if (positions.frame_count() == 0) return FailedPreconditionError("take has no frames");
  if (static_cast<int>(world_from_skull.size()) != positions.frame_count()) {
    return FailedPreconditionError("positions have " + std::to_string(positions.frame_count()) +
                                   " frames but there are " +
                                   std::to_string(world_from_skull.size()) + " skull poses");
  }
  if (positions.positions.rows() != 3 * static_cast<Eigen::Index>(positions.vertex_count)) {
    return FailedPreconditionError("point cache rows do not match its vertex count");
  }
  return Status::Ok();
}

// skull_from_world * x for a whole frame, into `out` (3 x N, preallocated).
void Stabilise(const Eigen::Map<const Eigen::Matrix3Xf>& frame, const Rigid3& world_from_skull,
               Eigen::Ref<Eigen::Matrix3Xd> out) {
  const Eigen::Matrix3d skull_from_world_rotation = world_from_skull.RotationMatrix().transpose();
  out.noalias() = skull_from_world_rotation * frame.cast<double>();
  out.colwise() -= skull_from_world_rotation * world_from_skull.translation();
}

}  // namespace

StatusOr<PointCache> MovingAverageInSkull(const PointCache& positions,
                                          const std::vector<Rigid3>& world_from_skull,
                                          int window_frames) {
  FACEDYN_RETURN_IF_ERROR(CheckPoses(positions, world_from_skull));
  if (window_frames < 0) return InvalidArgumentError("moving-average window must be >= 0 frames");
  const int frame_count = positions.frame_count();
  const int point_count = positions.vertex_count;
  // Stabilised positions of every frame, once (3N x F doubles).
  Eigen::MatrixXd in_skull(3 * static_cast<Eigen::Index>(point_count), frame_count);
  for (int t = 0; t < frame_count; ++t) {
    Eigen::Map<Eigen::Matrix3Xd> out(in_skull.col(t).data(), 3, point_count);
    Stabilise(positions.Frame(t), world_from_skull[t], out);
  }
  // Running window sum over clamped indices: sum(t) = sum(t-1) + P(t+w) - P(t-w-1).
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(in_skull.rows());
  for (int k = -window_frames; k <= window_frames; ++k) sum += in_skull.col(ClampFrame(k, frame_count));
  const double inverse_count = 1.0 / (2 * window_frames + 1);
  PointCache result;
  result.vertex_count = point_count;
  result.start_frame = positions.start_frame;
  result.sampling = positions.sampling;
  result.positions.resize(positions.positions.rows(), frame_count);
  Eigen::Matrix3Xd mean_in_skull(3, point_count);
  for (int t = 0; t < frame_count; ++t) {
    if (t > 0) {
      sum += in_skull.col(ClampFrame(t + window_frames, frame_count));
      sum -= in_skull.col(ClampFrame(t - window_frames - 1, frame_count));
    }
    mean_in_skull = Eigen::Map<const Eigen::Matrix3Xd>(sum.data(), 3, point_count) * inverse_count;
    const Rigid3& pose = world_from_skull[t];
    result.Frame(t) = ((pose.RotationMatrix() * mean_in_skull).colwise() + pose.translation()).cast<float>();
  }
  return result;
}

StatusOr<PointCache> WeightedAverageInSkull(const PointCache& positions,
                                            const std::vector<Rigid3>& world_from_skull,
                                            const std::vector<double>& weights) {
  FACEDYN_RETURN_IF_ERROR(CheckPoses(positions, world_from_skull));
  if (weights.empty() || weights.size() % 2 == 0) {
    return InvalidArgumentError("weighted average: need an odd number of weights (2w+1)");
  }
  const int half_window = static_cast<int>(weights.size() / 2);
  const int frame_count = positions.frame_count();
  const int point_count = positions.vertex_count;
  Eigen::MatrixXd in_skull(3 * static_cast<Eigen::Index>(point_count), frame_count);
  for (int t = 0; t < frame_count; ++t) {
    Eigen::Map<Eigen::Matrix3Xd> out(in_skull.col(t).data(), 3, point_count);
    Stabilise(positions.Frame(t), world_from_skull[t], out);
  }
  PointCache result;
  result.vertex_count = point_count;
  result.start_frame = positions.start_frame;
  result.sampling = positions.sampling;
  result.positions.resize(positions.positions.rows(), frame_count);
  Eigen::VectorXd sum(in_skull.rows());
  for (int t = 0; t < frame_count; ++t) {
    sum.setZero();
    for (int k = -half_window; k <= half_window; ++k) {
      sum += weights[k + half_window] * in_skull.col(ClampFrame(t + k, frame_count));
    }
    const Eigen::Map<const Eigen::Matrix3Xd> mean_in_skull(sum.data(), 3, point_count);
    const Rigid3& pose = world_from_skull[t];
    result.Frame(t) =
        ((pose.RotationMatrix() * mean_in_skull).colwise() + pose.translation()).cast<float>();
  }
  return result;
}

StatusOr<PointCache> DynamicOffsets(const PointCache& positions, const PointCache& quasistatic,
                                    const std::vector<Rigid3>& world_from_skull) {
  FACEDYN_RETURN_IF_ERROR(CheckPoses(positions, world_from_skull));
  if (quasistatic.vertex_count != positions.vertex_count ||
      quasistatic.frame_count() != positions.frame_count()) {
    return FailedPreconditionError(
        "dynamic offsets: positions have " + std::to_string(positions.vertex_count) +
        " vertices x " + std::to_string(positions.frame_count()) + " frames, quasistatic has " +
        std::to_string(quasistatic.vertex_count) + " x " + std::to_string(quasistatic.frame_count()));
  }
  PointCache offsets = positions;
  for (int t = 0; t < positions.frame_count(); ++t) {
    const Eigen::Matrix3f skull_from_world_rotation =
        world_from_skull[t].RotationMatrix().transpose().cast<float>();
    offsets.Frame(t) = skull_from_world_rotation * (positions.Frame(t) - quasistatic.Frame(t));
  }
  return offsets;
}

StatusOr<Take> ExtractQuasistatic(const Take& take, const QuasistaticOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  if (!(take.info.fps > 0.0)) return FailedPreconditionError("take has no valid fps");
  int window_frames = WindowFrames(options.window_s, take.info.fps);
  PointCache quasistatic;
  std::optional<double> platform_hz;
  if (options.method == QuasistaticMethod::kPlatformSynchronous) {
    platform_hz = options.platform_hz ? options.platform_hz : take.info.platform_hz;
    if (!platform_hz) {
      return FailedPreconditionError(
          "platform_hz: the take records no platform frequency (info.platform_hz); give one "
          "for platform-synchronous extraction");
    }
    window_frames = std::max(
        window_frames,
        static_cast<int>(std::ceil(0.5 * options.min_periods * take.info.fps / *platform_hz)));
    FACEDYN_ASSIGN_OR_RETURN(
        const std::vector<double> weights,
        PlatformSynchronousWeights(take.info.fps, *platform_hz, window_frames, options.harmonics,
                                   options.trend_degree));
    FACEDYN_ASSIGN_OR_RETURN(quasistatic,
                             WeightedAverageInSkull(take.positions, take.world_from_skull, weights));
  } else if (options.method == QuasistaticMethod::kHeldMean) {
    if (static_cast<int>(take.world_from_skull.size()) != take.frame_count()) {
      return InvalidArgumentError("held mean: the take does not have one skull pose per frame");
    }
    const int first = FirstHeldFrame(take);
    if (first >= take.frame_count()) {
      return FailedPreconditionError(
          "held mean: the take has no held frame (hold_start_s is at or after its end)");
    }
    Eigen::Matrix3Xd sum = Eigen::Matrix3Xd::Zero(3, take.vertex_count());
    for (int t = first; t < take.frame_count(); ++t) {
      sum += take.world_from_skull[t].Inverse().Apply(take.FramePositions(t));
    }
    const Eigen::Matrix3Xd mean_in_skull = sum / (take.frame_count() - first);
    quasistatic = take.positions;
    for (int t = 0; t < take.frame_count(); ++t) {
      quasistatic.Frame(t) = take.world_from_skull[t].Apply(mean_in_skull).cast<float>();
    }
    window_frames = 0;
  } else {
    FACEDYN_ASSIGN_OR_RETURN(
        quasistatic, MovingAverageInSkull(take.positions, take.world_from_skull, window_frames));
  }
  FACEDYN_ASSIGN_OR_RETURN(PointCache offsets,
                           DynamicOffsets(take.positions, quasistatic, take.world_from_skull));
  Take result;
  result.info = take.info;
  result.info.source = "dynamics quasistatic";
  result.info.metadata["quasistatic_method"] = QuasistaticMethodName(options.method);
  // The half-window actually used (the platform-synchronous fit may have widened it).
  result.info.metadata["quasistatic_window_s"] =
      options.method == QuasistaticMethod::kHeldMean ? 0.0
      : platform_hz                                  ? window_frames / take.info.fps
                                                     : options.window_s;
  result.info.metadata["quasistatic_window_frames"] = window_frames;
  if (platform_hz) result.info.metadata["quasistatic_platform_hz"] = *platform_hz;
  result.info.metadata["quasistatic_input_source"] = take.info.source;
  result.topology = take.topology;
  result.positions = std::move(quasistatic);
  result.time_s = take.time_s;
  result.world_from_skull = take.world_from_skull;
  result.skull_from_jaw = take.skull_from_jaw;
  result.channels["dynamic_offset"] = std::move(offsets);
  return result;
}

}  // namespace facedyn::dynamics
