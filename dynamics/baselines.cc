#include "dynamics/baselines.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "dynamics/features.h"
#include "dynamics/quasistatic.h"

namespace facedyn::dynamics {

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr double kSqrt2 = 1.41421356237309504880;
}  // namespace

const char* BaselineName(BaselineKind kind) {
  switch (kind) {
    case BaselineKind::kNoRemoval: return "no_removal";
    case BaselineKind::kLowPass: return "lowpass";
    case BaselineKind::kMovingAverage: return "moving_average";
  }
  return "unknown";
}

Status BaselineOptions::Check() const {
  if (!std::isfinite(lowpass_cutoff_hz) || lowpass_cutoff_hz < 0.0) {
    return InvalidArgumentError("BaselineOptions.lowpass_cutoff_hz must be > 0 (or 0 for the rule), got " +
                                std::to_string(lowpass_cutoff_hz));
  }
  if (!std::isfinite(window_s) || window_s < 0.0 || window_s > 1.0) {
    return InvalidArgumentError("BaselineOptions.window_s must be in [0, 1] s, got " +
                                std::to_string(window_s));
  }
  return Status::Ok();
}

Biquad ButterworthLowPass(double cutoff_hz, double sample_hz) {
  FACEDYN_CHECK(cutoff_hz > 0.0 && cutoff_hz < 0.5 * sample_hz, "cutoff must be in (0, fs/2)");
  const double k = std::tan(kPi * cutoff_hz / sample_hz);  // pre-warped analogue cutoff
  const double k2 = k * k;
  const double norm = 1.0 / (1.0 + kSqrt2 * k + k2);
  Biquad filter;
  filter.b0 = k2 * norm;
  filter.b1 = 2.0 * filter.b0;
  filter.b2 = filter.b0;
  filter.a1 = 2.0 * (k2 - 1.0) * norm;
  filter.a2 = (1.0 - kSqrt2 * k + k2) * norm;
  return filter;
}

namespace {

// One causal pass (direct form II transposed) over `length` columns of `data` in the order
// given by `column(i)`, all rows at once. `z1`, `z2`, `y` are preallocated. The state starts at
// the steady state of the constant input data.col(column(0)) (unit DC gain).
template <typename ColumnOf>
void BiquadPass(const Biquad& f, Eigen::MatrixXd* data, int length, ColumnOf column,
                Eigen::VectorXd* z1, Eigen::VectorXd* z2, Eigen::VectorXd* y) {
  const auto x0 = data->col(column(0));
  *z1 = (1.0 - f.b0) * x0;
  *z2 = (f.b2 - f.a2) * x0;
  for (int i = 0; i < length; ++i) {
    auto x = data->col(column(i));
    *y = f.b0 * x + *z1;
    *z1 = f.b1 * x - f.a1 * *y + *z2;
    *z2 = f.b2 * x - f.a2 * *y;
    x = *y;
  }
}

}  // namespace

StatusOr<Eigen::MatrixXd> ZeroPhaseLowPass(const Eigen::MatrixXd& signal, double cutoff_hz,
                                           double sample_hz) {
  if (!(sample_hz > 0.0) || !(cutoff_hz > 0.0) || !(cutoff_hz < 0.5 * sample_hz)) {
    return InvalidArgumentError("low-pass cutoff " + std::to_string(cutoff_hz) +
                                " Hz must be in (0, " + std::to_string(0.5 * sample_hz) +
                                ") Hz for " + std::to_string(sample_hz) + " fps");
  }
  const int frame_count = static_cast<int>(signal.cols());
  if (frame_count == 0) return signal;
  const int pad = static_cast<int>(std::ceil(2.0 * sample_hz / cutoff_hz));
  // Padded copy: first and last frames replicated `pad` times (end policy).
  Eigen::MatrixXd padded(signal.rows(), frame_count + 2 * pad);
  for (int i = 0; i < padded.cols(); ++i) padded.col(i) = signal.col(ClampFrame(i - pad, frame_count));
  const Biquad filter = ButterworthLowPass(cutoff_hz, sample_hz);
  Eigen::VectorXd z1(signal.rows()), z2(signal.rows()), y(signal.rows());
  const int length = static_cast<int>(padded.cols());
  BiquadPass(filter, &padded, length, [](int i) { return i; }, &z1, &z2, &y);
  BiquadPass(filter, &padded, length, [length](int i) { return length - 1 - i; }, &z1, &z2, &y);
  return Eigen::MatrixXd(padded.middleCols(pad, frame_count));
}

StatusOr<PointCache> LowPassBaseline(const Take& take, double cutoff_hz) {
  const int frame_count = take.frame_count();
  const int vertex_count = take.positions.vertex_count;
  if (frame_count == 0) return FailedPreconditionError("take has no frames");
  if (static_cast<int>(take.world_from_skull.size()) != frame_count) {
    return FailedPreconditionError("take has " + std::to_string(frame_count) + " frames but " +
                                   std::to_string(take.world_from_skull.size()) + " skull poses");
  }
  Eigen::MatrixXd in_skull(3 * static_cast<Eigen::Index>(vertex_count), frame_count);
  for (int t = 0; t < frame_count; ++t) {
    const Eigen::Matrix3d rotation = take.world_from_skull[t].RotationMatrix().transpose();
    Eigen::Map<Eigen::Matrix3Xd> out(in_skull.col(t).data(), 3, vertex_count);
    out.noalias() = rotation * take.positions.Frame(t).cast<double>();
    out.colwise() -= rotation * take.world_from_skull[t].translation();
  }
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd filtered,
                           ZeroPhaseLowPass(in_skull, cutoff_hz, take.info.fps));
  PointCache result = take.positions;
  for (int t = 0; t < frame_count; ++t) {
    const Rigid3& pose = take.world_from_skull[t];
    const Eigen::Map<const Eigen::Matrix3Xd> frame(filtered.col(t).data(), 3, vertex_count);
    result.Frame(t) = ((pose.RotationMatrix() * frame).colwise() + pose.translation()).cast<float>();
  }
  return result;
}

double DominantHeadMotionHz(const Take& take) {
  if (take.info.platform_hz && *take.info.platform_hz > 0) return *take.info.platform_hz;
  const int frames = static_cast<int>(take.world_from_skull.size());
  const double fps = take.info.fps;
  if (frames < 8 || !(fps > 0)) return 0.0;
  // Detrended skull origin (a walk's forward speed is a linear trend, not an oscillation).
  Eigen::MatrixXd origin(3, frames);
  for (int t = 0; t < frames; ++t) origin.col(t) = take.world_from_skull[t].translation();
  const Eigen::VectorXd time = Eigen::VectorXd::LinSpaced(frames, 0.0, frames - 1.0);
  const double t_mean = time.mean();
  const double t_var = (time.array() - t_mean).square().sum();
  for (int axis = 0; axis < 3; ++axis) {
    const double mean = origin.row(axis).mean();
    const double slope = ((time.array() - t_mean) * (origin.row(axis).transpose().array() - mean)).sum() / t_var;
    for (int t = 0; t < frames; ++t) origin(axis, t) -= mean + slope * (t - t_mean);
  }
  // Hann window (a take is a few periods long; without it the leakage of the strongest
  // oscillation, weighted by f^2 below, outgrows the peak at high frequencies).
  for (int t = 0; t < frames; ++t) {
    origin.col(t) *= 0.5 - 0.5 * std::cos(2 * M_PI * t / (frames - 1));
  }
  // Direct DFT on a 0.1 Hz grid (takes are seconds long; this runs once per take).
  double best_hz = 0.0, best_power = 0.0;
  for (double hz = 0.5; hz <= 0.5 * fps; hz += 0.1) {
    double power = 0.0;
    for (int axis = 0; axis < 3; ++axis) {
      double re = 0, im = 0;
      for (int t = 0; t < frames; ++t) {
        const double phase = 2 * M_PI * hz * t / fps;
        re += origin(axis, t) * std::cos(phase);
        im -= origin(axis, t) * std::sin(phase);
      }
      power += (re * re + im * im) * hz * hz;  // velocity: |X| f, squared
    }
    if (power > best_power) {
      best_power = power;
      best_hz = hz;
    }
  }
  return best_power > 1e-12 ? best_hz : 0.0;
}

double LowPassCutoffByRule(const Take& take) {
  const double nyquist_cap = 0.45 * take.info.fps;
  const double dominant = DominantHeadMotionHz(take);
  if (!(dominant > 0)) return nyquist_cap;
  return std::clamp(dominant / 3.0, 0.25, nyquist_cap);
}

double LowPassCutoffAfterRemoval(const Take& take, double residual_fraction) {
  const double nyquist_cap = 0.45 * take.info.fps;
  const double rule = LowPassCutoffByRule(take);
  const double dominant = DominantHeadMotionHz(take);
  if (!(dominant > 0) || !std::isfinite(residual_fraction)) return rule;
  constexpr double kBudget = 1.0 + 3.0 * 3.0 * 3.0 * 3.0;  // 82: the rule's 1 / (1 + 3^4)
  const double excess = kBudget * std::max(residual_fraction, 0.0) - 1.0;
  if (excess <= 0.0) return nyquist_cap;  // the removal alone meets the budget
  return std::clamp(dominant / std::pow(excess, 0.25), rule, nyquist_cap);
}

StatusOr<PointCache> ComputeBaseline(const Take& take, BaselineKind kind,
                                     const BaselineOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  switch (kind) {
    case BaselineKind::kNoRemoval:
      return take.positions;
    case BaselineKind::kLowPass:
      return LowPassBaseline(take, options.lowpass_cutoff_hz > 0 ? options.lowpass_cutoff_hz
                                                                 : LowPassCutoffByRule(take));
    case BaselineKind::kMovingAverage:
      if (!(take.info.fps > 0.0)) return FailedPreconditionError("take has no valid fps");
      return MovingAverageInSkull(take.positions, take.world_from_skull,
                                  WindowFrames(options.window_s, take.info.fps));
  }
  return InternalError("unknown baseline");
}

}  // namespace facedyn::dynamics
