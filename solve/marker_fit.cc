#include "solve/marker_fit.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <set>

#include "solve/marker_costs.h"

namespace facedyn::solve {

Status MarkerFitOptions::Check(int channel_count) const {
  std::set<int> seen;
  for (int c : free_channels) {
    if (c < 0 || c >= channel_count) {
      return InvalidArgumentError(
          fmt::format("free_channels: {} is not a channel index (0..{})", c, channel_count - 1));
    }
    if (!seen.insert(c).second)
      return InvalidArgumentError(fmt::format("free_channels: {} appears twice", c));
  }
  if (!(smoothness >= 0.0) || !std::isfinite(smoothness)) {
    return InvalidArgumentError(fmt::format("smoothness: {} is not >= 0", smoothness));
  }
  if (max_iterations < 1)
    return InvalidArgumentError(fmt::format("max_iterations: {} < 1", max_iterations));
  if (num_threads < 1) return InvalidArgumentError(fmt::format("num_threads: {} < 1", num_threads));
  return Status::Ok();
}

double MarkerRmseMm(const Puppet& puppet, const Eigen::MatrixXd& weights,
                    const Eigen::MatrixXd& markers, const MarkerPresence* present) {
  const Eigen::MatrixXd predicted =
      (puppet.marker_basis_mm * weights).colwise() + puppet.StackedNeutral();
  double sum = 0.0;
  long count = 0;
  for (Eigen::Index f = 0; f < markers.cols(); ++f) {
    for (int m = 0; m < puppet.marker_count(); ++m) {
      if (present != nullptr && !(*present)(m, f)) continue;
      sum += (predicted.col(f).segment<3>(3 * m) - markers.col(f).segment<3>(3 * m)).squaredNorm();
      ++count;
    }
  }
  return count > 0 ? std::sqrt(sum / count) : 0.0;
}

StatusOr<Eigen::MatrixXd> FitWeightsToMarkers(const Puppet& puppet, const Eigen::MatrixXd& markers,
                                              const Eigen::MatrixXd& initial,
                                              const MarkerPresence* present,
                                              const MarkerFitOptions& options,
                                              MarkerFitSummary* summary) {
  const auto start_time = std::chrono::steady_clock::now();
  const int c_count = puppet.channel_count();
  const int m_count = puppet.marker_count();
  FACEDYN_RETURN_IF_ERROR(options.Check(c_count).WithContext("marker fit options"));
  const Eigen::Index n = markers.cols();
  if (markers.rows() != 3 * m_count || initial.rows() != c_count || initial.cols() != n || n == 0) {
    return InvalidArgumentError(fmt::format(
        "marker fit: {} x {} markers and {} x {} initial weights for a puppet of {} markers and {} "
        "channels",
        markers.rows(), markers.cols(), initial.rows(), initial.cols(), m_count, c_count));
  }
  if (present != nullptr && (present->rows() != m_count || present->cols() != n)) {
    return InvalidArgumentError(
        fmt::format("marker fit: presence flags are {} x {}, expected {} x {}", present->rows(),
                    present->cols(), m_count, n));
  }
  if (!markers.allFinite())
    return InvalidArgumentError("marker fit: a marker coordinate is not finite");

  std::vector<int> free = options.free_channels;
  if (free.empty()) {
    for (int c = 0; c < c_count; ++c) free.push_back(c);
  }
  std::vector<bool> is_free(c_count, false);
  for (int c : free) is_free[c] = true;
  const int k = static_cast<int>(free.size());

  Eigen::MatrixXd weights = initial;
  for (int c = 0; c < c_count; ++c) {
    weights.row(c) =
        weights.row(c).cwiseMax(puppet.lower_bounds[c]).cwiseMin(puppet.upper_bounds[c]);
  }
  MarkerFitSummary local;
  local.initial_rmse_mm = MarkerRmseMm(puppet, weights, markers, present);

  // Per-frame free parameters, contiguous per frame (Ceres holds pointers into them).
  Eigen::MatrixXd free_weights(k, n);
  for (int i = 0; i < k; ++i) free_weights.row(i) = weights.row(free[i]);
  const Eigen::VectorXd neutral = puppet.StackedNeutral();

  auto frame_cost = [&](Eigen::Index f) -> StatusOr<ceres::CostFunction*> {
    std::vector<int> rows;
    for (int m = 0; m < m_count; ++m) {
      if (present == nullptr || (*present)(m, f)) {
        for (int a = 0; a < 3; ++a) rows.push_back(3 * m + a);
      }
    }
    if (rows.empty())
      return InvalidArgumentError(fmt::format("marker fit: frame {} has no marker", f));
    Eigen::MatrixXd a(rows.size(), k);
    Eigen::VectorXd b(rows.size());
    for (size_t r = 0; r < rows.size(); ++r) {
      const int row = rows[r];
      double frozen = 0.0;
      for (int c = 0; c < c_count; ++c) {
        if (!is_free[c]) frozen += puppet.marker_basis_mm(row, c) * weights(c, f);
      }
      b[static_cast<Eigen::Index>(r)] = markers(row, f) - neutral[row] - frozen;
      for (int i = 0; i < k; ++i)
        a(static_cast<Eigen::Index>(r), i) = puppet.marker_basis_mm(row, free[i]);
    }
    return new internal::LinearMarkerCost(std::move(a), std::move(b));
  };

  ceres::Solver::Options solver_options;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.num_threads = options.num_threads;
  // Tight enough that clean puppet markers give the weights back to ~1e-9 (marker_fit_test),
  // loose enough that noisy markers, whose optimum sits on the bounds, end on a criterion
  // rather than the iteration limit.
  solver_options.function_tolerance = 1e-12;
  solver_options.gradient_tolerance = 1e-10;
  solver_options.parameter_tolerance = 1e-10;
  solver_options.logging_type = ceres::SILENT;

  auto add_bounds = [&](ceres::Problem* problem, double* block) {
    for (int i = 0; i < k; ++i) {
      problem->SetParameterLowerBound(block, i, puppet.lower_bounds[free[i]]);
      problem->SetParameterUpperBound(block, i, puppet.upper_bounds[free[i]]);
    }
  };
  auto run = [&](ceres::Problem* problem) -> Status {
    ceres::Solver::Summary ceres_summary;
    ceres::Solve(solver_options, problem, &ceres_summary);
    if (!ceres_summary.IsSolutionUsable()) {
      return InternalError("marker fit: Ceres failed: " + ceres_summary.message);
    }
    local.converged &= ceres_summary.termination_type == ceres::CONVERGENCE;
    local.iterations += static_cast<int>(ceres_summary.iterations.size());
    ++local.problems;
    return Status::Ok();
  };

  if (k > 0) {
    if (options.smoothness > 0.0 && n > 1) {
      solver_options.linear_solver_type =
          ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE)
              ? ceres::SPARSE_NORMAL_CHOLESKY
              : ceres::CGNR;
      ceres::Problem problem;
      for (Eigen::Index f = 0; f < n; ++f) {
        FACEDYN_ASSIGN_OR_RETURN(ceres::CostFunction * cost, frame_cost(f));
        problem.AddResidualBlock(cost, nullptr, free_weights.col(f).data());
        add_bounds(&problem, free_weights.col(f).data());
      }
      for (Eigen::Index f = 1; f < n; ++f) {
        problem.AddResidualBlock(new internal::SmoothnessCost(k, options.smoothness), nullptr,
                                 free_weights.col(f - 1).data(), free_weights.col(f).data());
      }
      FACEDYN_RETURN_IF_ERROR(run(&problem));
    } else {
      solver_options.linear_solver_type = ceres::DENSE_QR;
      for (Eigen::Index f = 0; f < n; ++f) {
        ceres::Problem problem;
        FACEDYN_ASSIGN_OR_RETURN(ceres::CostFunction * cost, frame_cost(f));
        problem.AddResidualBlock(cost, nullptr, free_weights.col(f).data());
        add_bounds(&problem, free_weights.col(f).data());
        FACEDYN_RETURN_IF_ERROR(run(&problem));
      }
    }
  }
  for (int i = 0; i < k; ++i) {
    // Ceres keeps iterates inside the bounds; the clamp only removes last-bit round-off.
    weights.row(free[i]) = free_weights.row(i)
                               .cwiseMax(puppet.lower_bounds[free[i]])
                               .cwiseMin(puppet.upper_bounds[free[i]]);
  }
  local.final_rmse_mm = MarkerRmseMm(puppet, weights, markers, present);
  local.solve_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_time).count();
  if (summary != nullptr) *summary = local;
  return weights;
}

StatusOr<Eigen::MatrixXd> SolveMarkersQp(const Puppet& puppet, const Eigen::MatrixXd& markers,
                                         const MarkerPresence* present, MarkerFitSummary* summary) {
  return FitWeightsToMarkers(puppet, markers,
                             Eigen::MatrixXd::Zero(puppet.channel_count(), markers.cols()), present,
                             MarkerFitOptions{}, summary);
}

}  // namespace facedyn::solve
