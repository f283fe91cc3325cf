// The marker fit's residual blocks: analytic Jacobians against central finite differences
// (STYLE.md section 6).
#include "solve/marker_costs.h"

#include <gtest/gtest.h>

#include <vector>

namespace facedyn::solve::internal {
namespace {

// Max |J_analytic - J_numeric| over every parameter block of `cost` at `parameters`.
double JacobianError(const ceres::CostFunction& cost, std::vector<std::vector<double>> parameters) {
  const int residuals = cost.num_residuals();
  std::vector<const double*> blocks;
  for (const auto& p : parameters) blocks.push_back(p.data());
  std::vector<std::vector<double>> jacobians;
  std::vector<double*> jacobian_ptrs;
  for (size_t b = 0; b < parameters.size(); ++b) {
    jacobians.emplace_back(residuals * parameters[b].size());
    jacobian_ptrs.push_back(jacobians.back().data());
  }
  std::vector<double> r(residuals), plus(residuals), minus(residuals);
  EXPECT_TRUE(cost.Evaluate(blocks.data(), r.data(), jacobian_ptrs.data()));
  double worst = 0.0;
  const double h = 1e-6;
  for (size_t b = 0; b < parameters.size(); ++b) {
    const int size = static_cast<int>(parameters[b].size());
    for (int i = 0; i < size; ++i) {
      const double saved = parameters[b][i];
      parameters[b][i] = saved + h;
      EXPECT_TRUE(cost.Evaluate(blocks.data(), plus.data(), nullptr));
      parameters[b][i] = saved - h;
      EXPECT_TRUE(cost.Evaluate(blocks.data(), minus.data(), nullptr));
      parameters[b][i] = saved;
      for (int k = 0; k < residuals; ++k) {
        const double numeric = (plus[k] - minus[k]) / (2 * h);
        worst = std::max(worst, std::abs(numeric - jacobians[b][k * size + i]));  // row-major
      }
    }
  }
  return worst;
}

TEST(LinearMarkerCost, JacobianMatchesFiniteDifferences) {
  const Eigen::MatrixXd a = Eigen::MatrixXd::Random(9, 4) * 10.0;
  const Eigen::VectorXd b = Eigen::VectorXd::Random(9);
  const LinearMarkerCost cost(a, b);
  EXPECT_LT(JacobianError(cost, {{0.1, 0.7, 0.0, 1.0}}), 1e-6);
  // Residual: A w - b.
  const double w[4] = {1, 0, 0, 0};
  const double* blocks[1] = {w};
  std::vector<double> r(9);
  ASSERT_TRUE(cost.Evaluate(blocks, r.data(), nullptr));
  for (int k = 0; k < 9; ++k) EXPECT_NEAR(r[k], a(k, 0) - b[k], 1e-12);
}

TEST(SmoothnessCost, JacobianMatchesFiniteDifferences) {
  const SmoothnessCost cost(3, 4.0);
  EXPECT_LT(JacobianError(cost, {{0.1, 0.2, 0.3}, {0.5, 0.0, 1.0}}), 1e-6);
  const double previous[3] = {0, 0, 0}, next[3] = {1, 2, 3};
  const double* blocks[2] = {previous, next};
  double r[3];
  ASSERT_TRUE(cost.Evaluate(blocks, r, nullptr));
  EXPECT_DOUBLE_EQ(r[2], 2.0 * 3.0);  // sqrt(lambda) (w_t - w_{t-1})
}

}  // namespace
}  // namespace facedyn::solve::internal
