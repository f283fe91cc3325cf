#include "physics/material_fit.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <memory>
#include <set>

namespace facedyn::physics {
namespace {

// Residuals of one observation: real and imaginary parts of (model - observed), per coordinate.
class PhasorResidual : public ceres::CostFunction {
 public:
  explicit PhasorResidual(const PlatformObservation* observation) : observation_(observation) {
    set_num_residuals(static_cast<int>(6 * observation->skin_phasors_mm.cols()));
    mutable_parameter_block_sizes()->push_back(observation->model->parameter_count());
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int p = observation_->model->parameter_count();
    const Eigen::VectorXd theta = Eigen::Map<const Eigen::VectorXd>(parameters[0], p);
    Eigen::Matrix3Xcd response;
    std::vector<Eigen::Matrix3Xcd> jacobian;
    const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
    if (!observation_->model
             ->Evaluate(theta, observation_->motion, &response, want_jacobian ? &jacobian : nullptr)
             .ok()) {
      return false;  // Ceres shrinks the step
    }
    const Eigen::Index n = response.size();
    const Eigen::Matrix3Xcd difference = response - observation_->skin_phasors_mm;
    for (Eigen::Index i = 0; i < n; ++i) {
      residuals[2 * i] = difference.data()[i].real();
      residuals[2 * i + 1] = difference.data()[i].imag();
    }
    if (want_jacobian) {
      // Row-major: residual r, parameter j at jacobians[0][r * p + j].
      for (int j = 0; j < p; ++j) {
        for (Eigen::Index i = 0; i < n; ++i) {
          jacobians[0][(2 * i) * p + j] = jacobian[j].data()[i].real();
          jacobians[0][(2 * i + 1) * p + j] = jacobian[j].data()[i].imag();
        }
      }
    }
    return true;
  }

 private:
  const PlatformObservation* observation_;
};

double ResidualRms(const std::vector<PlatformObservation>& observations,
                   const Eigen::VectorXd& theta) {
  double sum = 0;
  Eigen::Index count = 0;
  for (const PlatformObservation& observation : observations) {
    Eigen::Matrix3Xcd response;
    if (!observation.model->Evaluate(theta, observation.motion, &response).ok()) {
      return std::numeric_limits<double>::quiet_NaN();
    }
    sum += (response - observation.skin_phasors_mm).cwiseAbs2().sum();
    count += response.size();
  }
  return count > 0 ? std::sqrt(sum / count) : 0.0;
}
}  // namespace

Status MaterialFitOptions::Check() const {
  if (max_iterations < 1)
    return InvalidArgumentError(fmt::format("max_iterations must be >= 1, got {}", max_iterations));
  if (!(max_scale > 1))
    return InvalidArgumentError(fmt::format("max_scale must be > 1, got {}", max_scale));
  if (!(damping_decades > 0)) return InvalidArgumentError("damping_decades must be positive");
  if (reduction_blocks < 0) return InvalidArgumentError("reduction_blocks must be >= 0");
  if (max_reductions < 1) return InvalidArgumentError("max_reductions must be >= 1");
  return Status::Ok();
}

StatusOr<MaterialFitResult> FitTissueMaterial(const std::vector<PlatformObservation>& observations,
                                              const MaterialFitOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  if (observations.empty()) return InvalidArgumentError("material fit: no platform observations");
  const HarmonicTissueResponse* first = observations.front().model;
  if (first == nullptr)
    return InvalidArgumentError("material fit: " + observations.front().name + " has no model");
  for (const PlatformObservation& observation : observations) {
    if (observation.model == nullptr)
      return InvalidArgumentError(fmt::format("material fit: {} has no model", observation.name));
    if (observation.model->parameter_count() != first->parameter_count()) {
      return InvalidArgumentError(fmt::format(
          "material fit: {} has {} parameters, the first observation {}", observation.name,
          observation.model->parameter_count(), first->parameter_count()));
    }
    if (observation.skin_phasors_mm.cols() !=
        static_cast<Eigen::Index>(observation.model->observed_vertices().size())) {
      return InvalidArgumentError(fmt::format(
          "material fit: {} has {} phasors for {} observed vertices", observation.name,
          observation.skin_phasors_mm.cols(), observation.model->observed_vertices().size()));
    }
    if (!observation.skin_phasors_mm.allFinite()) {
      return InvalidArgumentError(
          fmt::format("material fit: {} has non-finite phasors", observation.name));
    }
  }
  const int p = first->parameter_count();
  const int groups = first->group_count();
  const Eigen::VectorXd initial = first->InitialParameters();
  Eigen::VectorXd theta = initial;
  std::set<HarmonicTissueResponse*> models;
  for (const PlatformObservation& observation : observations) models.insert(observation.model);

  MaterialFitResult result;
  const double log_scale = std::log(options.max_scale);
  const double log_damping = options.damping_decades * std::log(10.0);
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.function_tolerance = 1e-10;
  solver_options.parameter_tolerance = 1e-10;
  solver_options.num_threads = 1;  // the models reuse their factorisations: not thread-safe
  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::TAKE_OWNERSHIP;
  std::unique_ptr<ceres::Problem> problem;
  ceres::Solver::Summary summary;
  int residual_count = 0;
  const int rounds = options.reduction_blocks > 0 ? options.max_reductions : 1;
  for (int round = 0; round < rounds; ++round) {
    if (options.reduction_blocks > 0) {
      for (HarmonicTissueResponse* model : models)
        FACEDYN_RETURN_IF_ERROR(model->ReduceAt(theta, options.reduction_blocks));
    }
    if (round == 0) result.rms_initial_mm = ResidualRms(observations, initial);
    const Eigen::VectorXd before = theta;
    problem = std::make_unique<ceres::Problem>(problem_options);
    residual_count = 0;
    for (const PlatformObservation& observation : observations) {
      auto* cost = new PhasorResidual(&observation);
      residual_count += cost->num_residuals();
      problem->AddResidualBlock(cost, nullptr, theta.data());
    }
    for (int j = 0; j < p; ++j) {
      const double half_width = j < groups ? log_scale : log_damping;
      problem->SetParameterLowerBound(theta.data(), j, initial[j] - half_width);
      problem->SetParameterUpperBound(theta.data(), j, initial[j] + half_width);
    }
    ceres::Solve(solver_options, problem.get(), &summary);
    if (!summary.IsSolutionUsable()) {
      return InternalError("material fit: the solver found no usable solution: " + summary.message);
    }
    result.iterations += static_cast<int>(summary.iterations.size());
    result.reductions = round + 1;
    if ((theta - before).cwiseAbs().maxCoeff() < options.reduction_tolerance) break;
  }
  result.theta = theta;
  result.rms_final_mm = ResidualRms(observations, theta);
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  result.message = summary.BriefReport();
  if (options.reduction_blocks > 0 && options.check_reduction) {
    for (const PlatformObservation& observation : observations) {
      FACEDYN_ASSIGN_OR_RETURN(const double error,
                               observation.model->ReductionError(theta, observation.motion));
      result.reduction_error = std::max(result.reduction_error, error);
    }
  }

  // One standard deviation per parameter: (J^T J)^-1 scaled by the residual variance.
  result.theta_stddev = Eigen::VectorXd::Constant(p, std::numeric_limits<double>::quiet_NaN());
  result.covariance = Eigen::MatrixXd::Constant(p, p, std::numeric_limits<double>::quiet_NaN());
  ceres::Covariance::Options covariance_options;
  covariance_options.algorithm_type = ceres::DENSE_SVD;
  covariance_options.null_space_rank = -1;
  ceres::Covariance covariance(covariance_options);
  std::vector<std::pair<const double*, const double*>> blocks = {{theta.data(), theta.data()}};
  if (residual_count > p && covariance.Compute(blocks, problem.get())) {
    Eigen::MatrixXd c(p, p);
    if (covariance.GetCovarianceBlock(theta.data(), theta.data(), c.data())) {
      const double variance = 2.0 * summary.final_cost / (residual_count - p);
      result.covariance = c * variance;
      result.theta_stddev = result.covariance.diagonal().cwiseSqrt();
    }
  }
  return result;
}

}  // namespace facedyn::physics
