#include "physics/body_transmissibility.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

#include "core/check.h"
#include "physics/harmonic_response.h"
#include "physics/skull_kinematics.h"

namespace facedyn::physics {
namespace {

// log |T(f)| for parameters theta = (log f_body, log zeta); templated for Ceres' automatic
// derivatives. |T|^2 = (1 + (2 zeta r)^2) / ((1 - r^2)^2 + (2 zeta r)^2).
template <typename T>
T LogTransmissibility(double hz, const T* theta) {
  const T r = hz / exp(theta[0]);
  const T d = 2.0 * exp(theta[1]) * r;
  const T one_minus = 1.0 - r * r;
  return 0.5 * (log(1.0 + d * d) - log(one_minus * one_minus + d * d));
}

struct LogMagnitudeResidual {
  double hz, log_measured;
  template <typename T>
  bool operator()(const T* theta, T* residual) const {
    residual[0] = LogTransmissibility(hz, theta) - log_measured;
    return true;
  }
};

double SumOfSquares(const std::vector<BodyTakeResponse>& takes, const double* theta) {
  double sum = 0;
  for (const BodyTakeResponse& take : takes) {
    const double r = LogTransmissibility(take.platform_hz, theta) - std::log(take.transmissibility);
    sum += r * r;
  }
  return sum;
}

}  // namespace

std::complex<double> BodyTransmissibility(double hz, double resonance_hz, double zeta) {
  FACEDYN_CHECK(resonance_hz > 0.0, "BodyTransmissibility needs a positive resonance");
  const double r = hz / resonance_hz;
  const std::complex<double> damping(0.0, 2.0 * zeta * r);
  return (1.0 + damping) / (1.0 - r * r + damping);
}

Status BodyFitOptions::Check() const {
  if (!(platform_amplitude_mm > 0 && platform_amplitude_mm <= 50)) {
    return InvalidArgumentError(
        fmt::format("body fit: platform amplitude {} mm is not in (0, 50] (the rig's amplitude_mm)",
                    platform_amplitude_mm));
  }
  if (!(min_resonance_hz > 0 && max_resonance_hz > min_resonance_hz)) {
    return InvalidArgumentError(
        fmt::format("body fit: resonance bounds {}..{} Hz are not > 0 and "
                    "increasing",
                    min_resonance_hz, max_resonance_hz));
  }
  if (!(min_damping_ratio > 0 && max_damping_ratio > min_damping_ratio)) {
    return InvalidArgumentError(
        fmt::format("body fit: damping bounds {}..{} are not > 0 and increasing", min_damping_ratio,
                    max_damping_ratio));
  }
  return Status::Ok();
}

StatusOr<BodyTakeResponse> MeasureBodyResponse(const std::string& name, const Take& take,
                                               double platform_amplitude_mm) {
  if (!(platform_amplitude_mm > 0)) {
    return InvalidArgumentError(
        fmt::format("body fit: platform amplitude {} mm is not > 0", platform_amplitude_mm));
  }
  if (!take.info.platform_hz || !(*take.info.platform_hz > 0)) {
    return InvalidArgumentError(
        fmt::format("body fit: {} has no platform frequency (platform_hz)", name));
  }
  if (static_cast<int>(take.world_from_skull.size()) != take.frame_count() ||
      static_cast<int>(take.time_s.size()) != take.frame_count()) {
    return InvalidArgumentError(
        fmt::format("body fit: {} lacks a skull pose or a time per frame", name));
  }
  const double hz = *take.info.platform_hz;
  const int first = FirstHeldFrame(take);
  const int frames = take.frame_count() - first;
  const double span = frames > 1 ? take.time_s.back() - take.time_s[first] : 0.0;
  if (frames < 8 || span * hz < 2.0) {
    return InvalidArgumentError(
        fmt::format("body fit: {} has {} held frames ({:.2f} s), need 8 frames over two periods "
                    "of {} Hz",
                    name, frames, span, hz));
  }
  const std::vector<double> times(take.time_s.begin() + first, take.time_s.end());
  const std::vector<Rigid3> poses(take.world_from_skull.begin() + first,
                                  take.world_from_skull.end());
  FACEDYN_ASSIGN_OR_RETURN(const HarmonicSkullMotion motion,
                           FitHarmonicSkullMotion(times, poses, hz));
  // Vertical: along gravity. Pitch: about the skull's x axis (left-right).
  const Eigen::Vector3d up = -kGravityInWorld.normalized();
  const std::complex<double> vertical =
      up.cast<std::complex<double>>().dot(motion.translation_in_world);
  BodyTakeResponse response;
  response.name = name;
  response.platform_hz = hz;
  response.frames = frames;
  response.head_vertical_mm = std::abs(vertical);
  response.transmissibility = response.head_vertical_mm / platform_amplitude_mm;
  if (!(response.head_vertical_mm > 1e-6 * platform_amplitude_mm)) {
    return FailedPreconditionError(
        fmt::format("body fit: {}'s skull does not move vertically at {} Hz (amplitude {:.3g} mm)",
                    name, hz, response.head_vertical_mm));
  }
  const double omega = 2 * M_PI * hz;
  const std::complex<double> acceleration_in_g = -omega * omega * vertical / kGravityInWorld.norm();
  response.pitch_rad_per_g =
      std::real(std::conj(acceleration_in_g) * motion.rotation_in_skull.x()) /
      std::norm(acceleration_in_g);
  return response;
}

StatusOr<BodyFit> FitBodyTransmissibility(
    const std::vector<std::pair<std::string, const Take*>>& takes, const BodyFitOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  BodyFit fit;
  for (const auto& [name, take] : takes) {
    if (take == nullptr) return InvalidArgumentError(fmt::format("body fit: {} is missing", name));
    FACEDYN_ASSIGN_OR_RETURN(BodyTakeResponse response,
                             MeasureBodyResponse(name, *take, options.platform_amplitude_mm));
    fit.takes.push_back(std::move(response));
  }
  std::vector<double> frequencies;
  for (const BodyTakeResponse& take : fit.takes) frequencies.push_back(take.platform_hz);
  std::sort(frequencies.begin(), frequencies.end());
  for (size_t i = 0; i < frequencies.size(); ++i) {
    if (i == 0 || frequencies[i] - frequencies[i - 1] > 0.05) ++fit.distinct_frequencies;
  }
  if (fit.distinct_frequencies < 3) {
    return FailedPreconditionError(fmt::format(
        "body fit: {} distinct platform frequencies among {} takes; the body's resonance and "
        "damping need at least 3",
        fit.distinct_frequencies, fit.takes.size()));
  }

  // Start: the best point of a log-spaced grid over the bounds.
  const double lo[2] = {std::log(options.min_resonance_hz), std::log(options.min_damping_ratio)};
  const double hi[2] = {std::log(options.max_resonance_hz), std::log(options.max_damping_ratio)};
  double theta[2] = {lo[0], lo[1]};
  double best = std::numeric_limits<double>::infinity();
  constexpr int kGrid = 60;
  for (int i = 0; i <= kGrid; ++i) {
    for (int j = 0; j <= kGrid; ++j) {
      const double candidate[2] = {lo[0] + (hi[0] - lo[0]) * i / kGrid,
                                   lo[1] + (hi[1] - lo[1]) * j / kGrid};
      const double sum = SumOfSquares(fit.takes, candidate);
      if (sum < best) {
        best = sum;
        theta[0] = candidate[0];
        theta[1] = candidate[1];
      }
    }
  }
  ceres::Problem problem;
  for (const BodyTakeResponse& take : fit.takes) {
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<LogMagnitudeResidual, 1, 2>(
            new LogMagnitudeResidual{take.platform_hz, std::log(take.transmissibility)}),
        nullptr, theta);
  }
  for (int k = 0; k < 2; ++k) {
    problem.SetParameterLowerBound(theta, k, lo[k]);
    problem.SetParameterUpperBound(theta, k, hi[k]);
  }
  ceres::Solver::Options solver_options;
  solver_options.max_num_iterations = 200;
  solver_options.function_tolerance = 1e-14;
  solver_options.parameter_tolerance = 1e-12;
  solver_options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  if (!summary.IsSolutionUsable()) {
    return InternalError("body fit: the solver failed: " + summary.BriefReport());
  }
  fit.resonance_hz = std::exp(theta[0]);
  fit.damping_ratio = std::exp(theta[1]);
  for (int k = 0; k < 2; ++k) {
    if (theta[k] - lo[k] < 1e-6 || hi[k] - theta[k] < 1e-6) fit.at_bound = true;
  }

  // Uncertainty: residual variance times (J^T J)^-1 in the log parameters, J by automatic
  // derivatives at the solution; none with exactly two takes' worth of degrees of freedom.
  const int n = static_cast<int>(fit.takes.size());
  Eigen::MatrixXd jacobian(n, 2);
  Eigen::VectorXd residuals(n);
  for (int i = 0; i < n; ++i) {
    using Jet = ceres::Jet<double, 2>;
    const Jet jet_theta[2] = {Jet(theta[0], 0), Jet(theta[1], 1)};
    const Jet value = LogTransmissibility(fit.takes[i].platform_hz, jet_theta);
    residuals(i) = value.a - std::log(fit.takes[i].transmissibility);
    jacobian.row(i) = value.v.transpose();
  }
  fit.rms_log_residual = std::sqrt(residuals.squaredNorm() / n);
  if (n > 2) {
    const double variance = residuals.squaredNorm() / (n - 2);
    const Eigen::Matrix2d information = jacobian.transpose() * jacobian;
    if (std::abs(information.determinant()) > 1e-12 * information.squaredNorm()) {
      const Eigen::Matrix2d covariance = variance * information.inverse();
      fit.resonance_hz_stddev = fit.resonance_hz * std::sqrt(std::max(0.0, covariance(0, 0)));
      fit.damping_ratio_stddev = fit.damping_ratio * std::sqrt(std::max(0.0, covariance(1, 1)));
    } else {
      fit.resonance_hz_stddev = fit.damping_ratio_stddev = std::numeric_limits<double>::infinity();
    }
  }
  // Pitch per g: the mean of the takes' k weighted by their acceleration squared is the least
  // squares k over all takes (each take's k already divides by its acceleration).
  double numerator = 0, denominator = 0;
  std::vector<double> ks;
  for (const BodyTakeResponse& take : fit.takes) {
    const double omega = 2 * M_PI * take.platform_hz;
    const double g = std::pow(omega * omega * take.head_vertical_mm / kGravityInWorld.norm(), 2);
    numerator += g * take.pitch_rad_per_g;
    denominator += g;
    ks.push_back(take.pitch_rad_per_g);
  }
  fit.pitch_rad_per_g = numerator / denominator;
  if (n > 1) {
    double spread = 0;
    for (double k : ks) spread += (k - fit.pitch_rad_per_g) * (k - fit.pitch_rad_per_g);
    fit.pitch_rad_per_g_stddev = std::sqrt(spread / (n - 1) / n);
  }
  return fit;
}

Json BodyFitToJson(const BodyFit& fit, double platform_amplitude_mm) {
  Json takes = Json::array();
  for (const BodyTakeResponse& take : fit.takes) {
    takes.push_back({{"name", take.name},
                     {"platform_hz", take.platform_hz},
                     {"frames", take.frames},
                     {"head_vertical_mm", take.head_vertical_mm},
                     {"transmissibility", take.transmissibility},
                     {"pitch_rad_per_g", take.pitch_rad_per_g}});
  }
  return {{"model",
           "base-excited single-DOF oscillator, |T| fitted (no platform phase in a capture); "
           "pitch = k a_y / g"},
          {"platform_amplitude_mm", platform_amplitude_mm},
          {"resonance_hz", fit.resonance_hz},
          {"resonance_hz_sd", fit.resonance_hz_stddev},
          {"damping_ratio", fit.damping_ratio},
          {"damping_ratio_sd", fit.damping_ratio_stddev},
          {"pitch_rad_per_g", fit.pitch_rad_per_g},
          {"pitch_rad_per_g_sd", fit.pitch_rad_per_g_stddev},
          {"rms_log_residual", fit.rms_log_residual},
          {"at_bound", fit.at_bound},
          {"distinct_frequencies", fit.distinct_frequencies},
          {"takes", takes}};
}

}  // namespace facedyn::physics
