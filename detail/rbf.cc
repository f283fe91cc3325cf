#include "detail/rbf.h"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

namespace facedyn::detail {
namespace {

Eigen::MatrixXd PolyRows(const Eigen::MatrixXd& centres, bool linear) {
  const int n = static_cast<int>(centres.cols());
  Eigen::MatrixXd p(n, linear ? 1 + centres.rows() : 1);
  p.col(0).setOnes();
  if (linear) p.rightCols(centres.rows()) = centres.transpose();
  return p;
}

Eigen::MatrixXd Kernel(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  Eigen::MatrixXd k(a.cols(), b.cols());
  for (int j = 0; j < b.cols(); ++j) {
    for (int i = 0; i < a.cols(); ++i) k(i, j) = (a.col(i) - b.col(j)).norm();
  }
  return k;
}

}  // namespace

StatusOr<Eigen::MatrixXd> SolveRbfSystem(const Eigen::MatrixXd& kernel, const Eigen::MatrixXd& poly,
                                         const Eigen::MatrixXd& values) {
  const int n = static_cast<int>(kernel.rows()), p = static_cast<int>(poly.cols());
  FACEDYN_CHECK(kernel.cols() == n && poly.rows() == n && values.rows() == n,
                "SolveRbfSystem: sizes");
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(n + p, n + p);
  a.topLeftCorner(n, n) = kernel;
  a.topRightCorner(n, p) = poly;
  a.bottomLeftCorner(p, n) = poly.transpose();
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(n + p, values.cols());
  rhs.topRows(n) = values;
  const Eigen::PartialPivLU<Eigen::MatrixXd> lu(a);
  Eigen::MatrixXd x = lu.solve(rhs);
  const double scale = std::max(rhs.norm(), std::numeric_limits<double>::min());
  const double residual = (a * x - rhs).norm() / scale;
  if (!x.allFinite() || residual > 1e-7) {
    return FailedPreconditionError(fmt::format(
        "RBF system with {} centres and {} polynomial terms is singular (relative residual {:.3g})",
        n, p, residual));
  }
  return x;
}

StatusOr<BiharmonicRbf> BiharmonicRbf::Fit(const Eigen::MatrixXd& centres,
                                           const Eigen::MatrixXd& values,
                                           RbfPolynomial polynomial) {
  if (centres.cols() == 0) return InvalidArgumentError("RBF fit: no centres");
  if (centres.cols() != values.rows()) {
    return InvalidArgumentError(
        fmt::format("RBF fit: {} centres but {} value rows", centres.cols(), values.rows()));
  }
  if (!centres.allFinite() || !values.allFinite())
    return InvalidArgumentError("RBF fit: non-finite centre or value");
  // Drop repeated centres (keep the first).
  const double extent =
      std::max((centres.rowwise().maxCoeff() - centres.rowwise().minCoeff()).norm(), 1e-300);
  std::vector<int> keep;
  for (int j = 0; j < centres.cols(); ++j) {
    bool repeated = false;
    for (int i : keep) {
      if ((centres.col(i) - centres.col(j)).norm() <= 1e-12 * extent) {
        repeated = true;
        break;
      }
    }
    if (!repeated) keep.push_back(j);
  }
  const int n = static_cast<int>(keep.size()), d = static_cast<int>(centres.rows());
  Eigen::MatrixXd c(d, n), y(n, values.cols());
  for (int k = 0; k < n; ++k) {
    c.col(k) = centres.col(keep[k]);
    y.row(k) = values.row(keep[k]);
  }
  bool linear = polynomial == RbfPolynomial::kLinear ||
                (polynomial == RbfPolynomial::kAuto && n >= 2 * (d + 1));
  const Eigen::MatrixXd kernel = Kernel(c, c);
  StatusOr<Eigen::MatrixXd> coefficients = SolveRbfSystem(kernel, PolyRows(c, linear), y);
  if (!coefficients.ok() && linear && polynomial == RbfPolynomial::kAuto) {
    linear = false;
    coefficients = SolveRbfSystem(kernel, PolyRows(c, false), y);
  }
  if (!coefficients.ok()) return coefficients.status();
  BiharmonicRbf rbf;
  rbf.centres_ = std::move(c);
  rbf.coefficients_ = std::move(coefficients).value();
  rbf.linear_ = linear;
  return rbf;
}

StatusOr<BiharmonicRbf> BiharmonicRbf::FromParts(Eigen::MatrixXd centres,
                                                 Eigen::MatrixXd coefficients, bool linear,
                                                 Eigen::MatrixXd output_basis) {
  const Eigen::Index expected = centres.cols() + (linear ? 1 + centres.rows() : 1);
  if (centres.cols() == 0 || coefficients.rows() != expected) {
    return DataLossError(
        fmt::format("RBF: {} coefficient rows for {} centres of dimension {} ({} expected)",
                    coefficients.rows(), centres.cols(), centres.rows(), expected));
  }
  if (output_basis.size() != 0 && output_basis.rows() != coefficients.cols()) {
    return DataLossError(fmt::format("RBF: an output basis of {} rows for {} coefficient columns",
                                     output_basis.rows(), coefficients.cols()));
  }
  BiharmonicRbf rbf;
  rbf.centres_ = std::move(centres);
  rbf.coefficients_ = std::move(coefficients);
  rbf.output_basis_ = std::move(output_basis);
  rbf.linear_ = linear;
  return rbf;
}

Status BiharmonicRbf::CompressOutputs(const Eigen::MatrixXd& values, double energy) {
  if (!(energy > 0.0 && energy <= 1.0))
    return InvalidArgumentError(fmt::format("RBF output energy must be in (0, 1], got {}", energy));
  if (output_basis_.size() != 0) return FailedPreconditionError("RBF outputs already compressed");
  if (values.cols() != coefficients_.cols()) {
    return InvalidArgumentError(fmt::format("RBF compression: {} value columns for {} outputs",
                                            values.cols(), coefficients_.cols()));
  }
  // Right singular vectors from the N x N Gram matrix (N centres << K outputs):
  // Y Y^T = U S^2 U^T, V = Y^T U S^-1.
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(values * values.transpose());
  const Eigen::VectorXd lambda = eigen.eigenvalues().reverse().cwiseMax(0.0);
  const double total = lambda.sum();
  if (!(total > 0.0)) {
    // Every training value is zero: one zero direction keeps the shapes consistent.
    output_basis_ = Eigen::MatrixXd::Zero(1, values.cols());
    output_basis_(0, 0) = 1.0;
    coefficients_ = Eigen::MatrixXd::Zero(coefficients_.rows(), 1);
    return Status::Ok();
  }
  const double floor = 1e-12 * lambda[0];
  int k = 0;
  double kept = 0.0;
  while (k < lambda.size() && lambda[k] > floor && (k == 0 || kept < energy * total)) {
    kept += lambda[k];
    ++k;
  }
  const Eigen::MatrixXd u = eigen.eigenvectors().rowwise().reverse().leftCols(k);
  Eigen::MatrixXd v = values.transpose() * u;  // K x k
  for (int i = 0; i < k; ++i) v.col(i) /= std::sqrt(lambda[i]);
  // Only a smaller basis saves anything.
  if (k >= values.cols()) return Status::Ok();
  coefficients_ = coefficients_ * v;  // the fit is linear in the values: A^-1 [Y V; 0]
  output_basis_ = v.transpose();
  return Status::Ok();
}

void BiharmonicRbf::Evaluate(const Eigen::Ref<const Eigen::VectorXd>& f,
                             Eigen::Ref<Eigen::VectorXd> out) const {
  FACEDYN_CHECK(f.size() == dimension() && out.size() == outputs(),
                "BiharmonicRbf::Evaluate: sizes");
  const int n = centre_count();
  Eigen::VectorXd h(coefficients_.rows());
  for (int j = 0; j < n; ++j) h[j] = (centres_.col(j) - f).norm();
  h[n] = 1.0;
  if (linear_) h.tail(dimension()) = f;
  if (output_basis_.size() == 0) {
    out.noalias() = coefficients_.transpose() * h;
  } else {
    const Eigen::VectorXd reduced = coefficients_.transpose() * h;
    out.noalias() = output_basis_.transpose() * reduced;
  }
}

std::vector<int> GreedySelectFrames(const Eigen::MatrixXd& features, const Eigen::MatrixXd& gram,
                                    int count) {
  const int n = static_cast<int>(features.cols());
  FACEDYN_CHECK(gram.rows() == n && gram.cols() == n, "GreedySelectFrames: gram size");
  count = std::clamp(count, 0, n);
  std::vector<int> selected;
  if (count == 0) return selected;
  std::vector<char> taken(n, 0);
  Eigen::VectorXd error = gram.diagonal();
  const double total = std::max(error.maxCoeff(), 1e-300);
  // Distances from every frame to each selected frame, grown one column per step.
  Eigen::MatrixXd dist(n, 0);
  while (static_cast<int>(selected.size()) < count) {
    int best = -1;
    for (int j = 0; j < n; ++j) {
      if (!taken[j] && (best < 0 || error[j] > error[best])) best = j;
    }
    if (best < 0 || (!selected.empty() && error[best] <= 1e-14 * total)) break;
    selected.push_back(best);
    taken[best] = 1;
    const int k = static_cast<int>(selected.size());
    dist.conservativeResize(n, k);
    for (int j = 0; j < n; ++j) dist(j, k - 1) = (features.col(j) - features.col(best)).norm();
    if (k == count) break;
    // Interpolation matrix on the selected frames (constant part), and its inverse's first k
    // columns: prediction rows m_j = [dist_j 1] C.
    Eigen::MatrixXd a = Eigen::MatrixXd::Zero(k + 1, k + 1);
    Eigen::MatrixXd g_ss(k, k), g_s_all(k, n);
    for (int i = 0; i < k; ++i) {
      for (int m = 0; m < k; ++m) {
        a(i, m) = dist(selected[i], m);
        g_ss(i, m) = gram(selected[i], selected[m]);
      }
      a(i, k) = a(k, i) = 1.0;
      g_s_all.row(i) = gram.row(selected[i]);
    }
    const Eigen::MatrixXd c = Eigen::PartialPivLU<Eigen::MatrixXd>(a).inverse().leftCols(k);
    Eigen::MatrixXd h(n, k + 1);
    h.leftCols(k) = dist;
    h.col(k).setOnes();
    const Eigen::MatrixXd m = h * c;  // n x k
    const Eigen::MatrixXd mg = m * g_ss;
    for (int j = 0; j < n; ++j) {
      error[j] = taken[j] ? 0.0
                          : std::max(0.0, mg.row(j).dot(m.row(j)) -
                                              2 * m.row(j).dot(g_s_all.col(j)) + gram(j, j));
    }
  }
  return selected;
}

}  // namespace facedyn::detail
