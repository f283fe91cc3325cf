// The residual blocks of the marker fit (solve/marker_fit.h), in a header of their own so their
// analytic Jacobians can be checked against finite differences (tests/solve/marker_costs_test).
// Not part of solve/'s interface.
#pragma once

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <utility>

namespace facedyn::solve::internal {

// r = A w - b for one frame's free weights: A the present markers' rows of B over the free
// channels, b the observed markers minus neutral minus the frozen channels' contribution.
class LinearMarkerCost final : public ceres::CostFunction {
 public:
  LinearMarkerCost(Eigen::MatrixXd a, Eigen::VectorXd b) : a_(std::move(a)), b_(std::move(b)) {
    set_num_residuals(static_cast<int>(a_.rows()));
    mutable_parameter_block_sizes()->push_back(static_cast<int>(a_.cols()));
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const Eigen::Map<const Eigen::VectorXd> w(parameters[0], a_.cols());
    Eigen::Map<Eigen::VectorXd>(residuals, a_.rows()) = a_ * w - b_;
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          jacobians[0], a_.rows(), a_.cols()) = a_;
    }
    return true;
  }

 private:
  Eigen::MatrixXd a_;
  Eigen::VectorXd b_;
};

// sqrt(lambda) (w_t - w_{t-1}) over the free channels.
class SmoothnessCost final : public ceres::CostFunction {
 public:
  SmoothnessCost(int size, double lambda) : size_(size), scale_(std::sqrt(lambda)) {
    set_num_residuals(size);
    mutable_parameter_block_sizes()->push_back(size);
    mutable_parameter_block_sizes()->push_back(size);
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    for (int i = 0; i < size_; ++i) residuals[i] = scale_ * (parameters[1][i] - parameters[0][i]);
    for (int block = 0; block < 2; ++block) {
      if (jacobians == nullptr || jacobians[block] == nullptr) continue;
      std::fill(jacobians[block], jacobians[block] + size_ * size_, 0.0);
      for (int i = 0; i < size_; ++i)
        jacobians[block][i * size_ + i] = block == 0 ? -scale_ : scale_;
    }
    return true;
  }

 private:
  int size_;
  double scale_;
};

}  // namespace facedyn::solve::internal
