#include "physics/harmonic_response.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <Eigen/UmfPackSupport>
#include <algorithm>
#include <cmath>

#include "core/check.h"

namespace facedyn::physics {
namespace {

using Complex = std::complex<double>;
using ComplexSparse = Eigen::SparseMatrix<Complex>;

// Least-squares fit of c0 + c1 (t - mean t) + a cos(w t) + b sin(w t) to each row of `values`
// (rows: signals, columns: samples); returns the phasors a - i b (x = Re(X e^{i w t})).
StatusOr<Eigen::VectorXcd> SinusoidPhasors(const std::vector<double>& time_s,
                                           const Eigen::MatrixXd& values, double frequency_hz,
                                           const char* what) {
  const int n = static_cast<int>(time_s.size());
  if (!(frequency_hz > 0) || !std::isfinite(frequency_hz)) {
    return InvalidArgumentError(
        fmt::format("{}: the frequency must be positive, got {}", what, frequency_hz));
  }
  if (n < 8) return InvalidArgumentError(fmt::format("{}: {} samples, need at least 8", what, n));
  const double span = time_s.back() - time_s.front();
  if (!(span * frequency_hz >= 1.0)) {
    return InvalidArgumentError(fmt::format(
        "{}: {:.3f} s of samples is less than one period of {} Hz", what, span, frequency_hz));
  }
  double mean_t = 0;
  for (double t : time_s) mean_t += t / n;
  const double omega = 2 * M_PI * frequency_hz;
  Eigen::MatrixXd design(n, 4);
  for (int i = 0; i < n; ++i) {
    design(i, 0) = 1.0;
    design(i, 1) = time_s[i] - mean_t;
    design(i, 2) = std::cos(omega * time_s[i]);
    design(i, 3) = std::sin(omega * time_s[i]);
  }
  const Eigen::LDLT<Eigen::Matrix4d> normal(design.transpose() * design);
  if (normal.info() != Eigen::Success || !normal.isPositive()) {
    return InvalidArgumentError(
        fmt::format("{}: the sample times cannot separate the sinusoid", what));
  }
  const Eigen::MatrixXd coefficients =
      normal.solve(design.transpose() * values.transpose());  // 4 x signals
  Eigen::VectorXcd phasors(values.rows());
  for (Eigen::Index r = 0; r < values.rows(); ++r)
    phasors[r] = Complex(coefficients(2, r), -coefficients(3, r));
  return phasors;
}

// a x b without conjugation (Eigen's cross() conjugates the result for complex scalars).
Eigen::Vector3cd Cross(const Eigen::Vector3cd& a, const Eigen::Vector3cd& b) {
  return Eigen::Vector3cd(a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                          a[0] * b[1] - a[1] * b[0]);
}

// A = stiffness K + mass M at the motion's frequency for theta's damping:
// (1 + i w beta) K + (i w alpha - w^2) M.
struct Factors {
  double omega, alpha, beta;
  Complex stiffness, mass;
};
Factors FactorsOf(const Eigen::VectorXd& theta, int groups, const HarmonicSkullMotion& motion) {
  Factors f;
  f.omega = 2 * M_PI * motion.frequency_hz;
  f.alpha = std::exp(theta[groups]);
  f.beta = std::exp(theta[groups + 1]);
  f.stiffness = Complex(1.0, f.omega * f.beta);
  f.mass = Complex(-f.omega * f.omega, f.omega * f.alpha);
  return f;
}

// The load_fields' coefficients (physics/soft_tissue.h TissueSystemParts).
Eigen::Matrix<Complex, 6, 1> LoadOf(const HarmonicSkullMotion& motion) {
  Eigen::Matrix<Complex, 6, 1> load;
  load.head<3>() = motion.uniform_acceleration_in_skull;
  load.tail<3>() = -motion.angular_acceleration_in_skull;
  return load;
}

Eigen::Vector3d RotationVector(const Eigen::Quaterniond& q) {
  const Eigen::AngleAxisd angle_axis(q);
  return angle_axis.angle() * angle_axis.axis();
}
}  // namespace

StatusOr<Eigen::Matrix3Xcd> FitHarmonicPhasors(const std::vector<double>& time_s,
                                               const std::vector<Eigen::Matrix3Xd>& samples,
                                               double frequency_hz) {
  if (samples.size() != time_s.size()) {
    return InvalidArgumentError(fmt::format("harmonic phasors: {} sample sets for {} times",
                                            samples.size(), time_s.size()));
  }
  if (samples.empty()) return InvalidArgumentError("harmonic phasors: no samples");
  const Eigen::Index columns = samples.front().cols();
  Eigen::MatrixXd values(3 * columns, static_cast<Eigen::Index>(samples.size()));
  for (size_t f = 0; f < samples.size(); ++f) {
    if (samples[f].cols() != columns) {
      return InvalidArgumentError(
          fmt::format("harmonic phasors: sample {} has {} points, the first has {}", f,
                      samples[f].cols(), columns));
    }
    values.col(static_cast<Eigen::Index>(f)) =
        Eigen::Map<const Eigen::VectorXd>(samples[f].data(), 3 * columns);
  }
  StatusOr<Eigen::VectorXcd> phasors =
      SinusoidPhasors(time_s, values, frequency_hz, "harmonic phasors");
  if (!phasors.ok()) return phasors.status();
  return Eigen::Matrix3Xcd(Eigen::Map<const Eigen::Matrix3Xcd>(phasors->data(), 3, columns));
}

StatusOr<HarmonicSkullMotion> FitHarmonicSkullMotion(const std::vector<double>& time_s,
                                                     const std::vector<Rigid3>& world_from_skull,
                                                     double frequency_hz) {
  if (world_from_skull.size() != time_s.size()) {
    return InvalidArgumentError(fmt::format("harmonic skull motion: {} poses for {} times",
                                            world_from_skull.size(), time_s.size()));
  }
  if (world_from_skull.empty()) return InvalidArgumentError("harmonic skull motion: no poses");
  // Mean rotation: the first pose corrected by the mean rotation vector relative to it (the
  // motion is a few milliradians, so the mean of the vectors is the mean rotation to first order).
  const Eigen::Quaterniond first = world_from_skull.front().rotation();
  Eigen::Vector3d mean_vector = Eigen::Vector3d::Zero();
  for (const Rigid3& pose : world_from_skull) {
    mean_vector +=
        RotationVector(first.conjugate() * pose.rotation()) / double(world_from_skull.size());
  }
  const Eigen::Quaterniond mean_rotation =
      first *
      Eigen::Quaterniond(Eigen::AngleAxisd(
          mean_vector.norm(), mean_vector.norm() > 0 ? Eigen::Vector3d(mean_vector.normalized())
                                                     : Eigen::Vector3d::UnitX()));
  Eigen::MatrixXd values(6, static_cast<Eigen::Index>(time_s.size()));
  for (size_t f = 0; f < time_s.size(); ++f) {
    values.col(f).head<3>() = world_from_skull[f].translation();
    values.col(f).tail<3>() =
        RotationVector(mean_rotation.conjugate() * world_from_skull[f].rotation());
  }
  StatusOr<Eigen::VectorXcd> phasors =
      SinusoidPhasors(time_s, values, frequency_hz, "harmonic skull motion");
  if (!phasors.ok()) return phasors.status();
  const double omega = 2 * M_PI * frequency_hz;
  const Eigen::Matrix3d skull_from_world = mean_rotation.conjugate().toRotationMatrix();
  const Eigen::Vector3cd translation = phasors->head<3>();
  const Eigen::Vector3cd rotation = phasors->tail<3>();  // skull coordinates (body frame)
  const Eigen::Vector3cd gravity_in_skull = (skull_from_world * kGravityInWorld).cast<Complex>();
  HarmonicSkullMotion motion;
  motion.frequency_hz = frequency_hz;
  // R^T g = exp(-[phi]x) R0^T g ~ g0 - phi x g0; the origin accelerates by -w^2 T (world).
  motion.uniform_acceleration_in_skull =
      -Cross(rotation, gravity_in_skull) +
      omega * omega * skull_from_world.cast<Complex>() * translation;
  motion.angular_acceleration_in_skull = -omega * omega * rotation;
  motion.translation_in_world = translation;
  motion.rotation_in_skull = rotation;
  return motion;
}

struct HarmonicTissueResponse::Solver {
  ComplexSparse system;  // A, the pattern of the stiffness parts
  Eigen::UmfPackLU<ComplexSparse> lu;
};

HarmonicTissueResponse::~HarmonicTissueResponse() = default;

StatusOr<std::unique_ptr<HarmonicTissueResponse>> HarmonicTissueResponse::Create(
    TissueSystemParts parts, std::vector<int> observed) {
  if (parts.stiffness_by_group.empty())
    return InvalidArgumentError("harmonic response: no stiffness groups");
  const Eigen::Index dofs = parts.mass_dofs.size();
  for (size_t g = 0; g < parts.stiffness_by_group.size(); ++g) {
    const Eigen::SparseMatrix<double>& k = parts.stiffness_by_group[g];
    const Eigen::SparseMatrix<double>& first = parts.stiffness_by_group.front();
    if (k.rows() != dofs || k.cols() != dofs || k.nonZeros() != first.nonZeros() ||
        !k.isCompressed()) {
      return InvalidArgumentError(
          fmt::format("harmonic response: stiffness group {} does not share the pattern", g));
    }
  }
  if (parts.spring_dofs.size() != dofs || parts.load_fields.rows() != dofs ||
      parts.load_fields.cols() != 6) {
    return InvalidArgumentError(
        "harmonic response: springs, masses and load fields disagree in size");
  }
  for (int v : observed) {
    if (v < 0 || v >= static_cast<int>(parts.skin_dof.size()) || parts.skin_dof[v] < 0) {
      return InvalidArgumentError(
          fmt::format("harmonic response: observed vertex {} is not a free skin vertex", v));
    }
  }
  std::unique_ptr<HarmonicTissueResponse> response(new HarmonicTissueResponse());
  response->observed_ = std::move(observed);
  const Eigen::SparseMatrix<double>& pattern = parts.stiffness_by_group.front();
  response->diagonal_entry_.assign(dofs, -1);
  for (Eigen::Index col = 0; col < dofs; ++col) {
    for (Eigen::Index i = pattern.outerIndexPtr()[col]; i < pattern.outerIndexPtr()[col + 1]; ++i) {
      if (pattern.innerIndexPtr()[i] == col) response->diagonal_entry_[col] = static_cast<int>(i);
    }
    if (response->diagonal_entry_[col] < 0) {
      return InvalidArgumentError(
          fmt::format("harmonic response: DOF {} has no diagonal entry", col));
    }
  }
  response->solver_ = std::make_unique<Solver>();
  response->solver_->system = pattern.cast<Complex>();
  response->solver_->lu.analyzePattern(response->solver_->system);
  response->parts_ = std::move(parts);
  return response;
}

Eigen::VectorXd HarmonicTissueResponse::InitialParameters() const {
  Eigen::VectorXd theta = Eigen::VectorXd::Zero(parameter_count());
  // A zero coefficient has no logarithm: start from a negligible one (1e-9 of the other's scale
  // at 10 Hz, where alpha ~ w^2 beta).
  const double w2 = std::pow(2 * M_PI * 10.0, 2);
  const double alpha =
      parts_.rayleigh_mass > 0 ? parts_.rayleigh_mass : 1e-9 * parts_.rayleigh_stiffness * w2;
  const double beta =
      parts_.rayleigh_stiffness > 0 ? parts_.rayleigh_stiffness : 1e-9 * parts_.rayleigh_mass / w2;
  theta[group_count()] = std::log(std::max(alpha, 1e-300));
  theta[group_count() + 1] = std::log(std::max(beta, 1e-300));
  return theta;
}

Status HarmonicTissueResponse::Evaluate(const Eigen::VectorXd& theta,
                                        const HarmonicSkullMotion& motion,
                                        Eigen::Matrix3Xcd* response,
                                        std::vector<Eigen::Matrix3Xcd>* jacobian) const {
  FACEDYN_CHECK(response != nullptr, "response is required");
  if (theta.size() != parameter_count() || !theta.allFinite()) {
    return InvalidArgumentError(
        fmt::format("harmonic response: {} parameters, expected {} finite values", theta.size(),
                    parameter_count()));
  }
  if (!(motion.frequency_hz > 0))
    return InvalidArgumentError("harmonic response: the frequency must be positive");
  return reduced_ ? EvaluateReduced(theta, motion, response, jacobian)
                  : EvaluateFull(theta, motion, response, jacobian);
}

Status HarmonicTissueResponse::ReduceAt(const Eigen::VectorXd& theta, int blocks) {
  if (theta.size() != parameter_count() || !theta.allFinite()) {
    return InvalidArgumentError(
        fmt::format("harmonic reduction: {} parameters, expected {} finite values", theta.size(),
                    parameter_count()));
  }
  if (blocks < 1)
    return InvalidArgumentError(
        fmt::format("harmonic reduction: {} blocks, need at least 1", blocks));
  const int groups = group_count();
  Eigen::SparseMatrix<double> k = std::exp(theta[0]) * parts_.stiffness_by_group[0];
  for (int g = 1; g < groups; ++g) k += std::exp(theta[g]) * parts_.stiffness_by_group[g];
  for (Eigen::Index d = 0; d < k.rows(); ++d) k.coeffRef(d, d) += parts_.spring_dofs[d];
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> cholesky(k);
  if (cholesky.info() != Eigen::Success)
    return InternalError("harmonic reduction: the stiffness is not positive definite");
  const Eigen::VectorXd& mass = parts_.mass_dofs;
  // Block Krylov with M-orthonormalisation (modified Gram-Schmidt, twice), dropping columns that
  // are numerically dependent on the basis so far.
  std::vector<Eigen::VectorXd> vectors;
  auto add_block = [&](const Eigen::MatrixXd& block) {
    int added = 0;
    for (Eigen::Index c = 0; c < block.cols(); ++c) {
      Eigen::VectorXd x = block.col(c);
      const double before = std::sqrt(x.dot(mass.cwiseProduct(x)));
      if (!(before > 0)) continue;
      for (int pass = 0; pass < 2; ++pass) {
        for (const Eigen::VectorXd& v : vectors) x -= v.dot(mass.cwiseProduct(x)) * v;
      }
      const double after = std::sqrt(x.dot(mass.cwiseProduct(x)));
      if (!(after > 1e-8 * before)) continue;
      vectors.push_back(x / after);
      ++added;
    }
    return added;
  };
  Eigen::MatrixXd block = cholesky.solve(parts_.load_fields);
  int first = 0;
  for (int b = 0; b < blocks; ++b) {
    const int added = add_block(block);
    if (added == 0) break;
    Eigen::MatrixXd last(mass.size(), added);
    for (int c = 0; c < added; ++c) last.col(c) = vectors[first + c];
    first += added;
    block = cholesky.solve(mass.asDiagonal() * last);
  }
  basis_.resize(mass.size(), static_cast<Eigen::Index>(vectors.size()));
  for (size_t c = 0; c < vectors.size(); ++c) basis_.col(static_cast<Eigen::Index>(c)) = vectors[c];
  reduced_stiffness_.clear();
  for (int g = 0; g < groups; ++g)
    reduced_stiffness_.push_back(basis_.transpose() * (parts_.stiffness_by_group[g] * basis_));
  reduced_springs_ = basis_.transpose() * parts_.spring_dofs.asDiagonal() * basis_;
  reduced_mass_ = basis_.transpose() * mass.asDiagonal() * basis_;
  reduced_loads_ = basis_.transpose() * parts_.load_fields;
  observed_basis_.resize(3 * static_cast<Eigen::Index>(observed_.size()), basis_.cols());
  for (size_t i = 0; i < observed_.size(); ++i) {
    observed_basis_.middleRows<3>(3 * static_cast<Eigen::Index>(i)) =
        basis_.middleRows<3>(parts_.skin_dof[observed_[i]]);
  }
  reduced_ = true;
  return Status::Ok();
}

StatusOr<double> HarmonicTissueResponse::ReductionError(const Eigen::VectorXd& theta,
                                                        const HarmonicSkullMotion& motion) const {
  if (!reduced_) return FailedPreconditionError("harmonic response: not reduced");
  Eigen::Matrix3Xcd reduced, full;
  FACEDYN_RETURN_IF_ERROR(Evaluate(theta, motion, &reduced));
  FACEDYN_RETURN_IF_ERROR(EvaluateFull(theta, motion, &full, nullptr));
  if (!(full.norm() > 0)) return 0.0;
  return (reduced - full).norm() / full.norm();
}

Status HarmonicTissueResponse::EvaluateReduced(const Eigen::VectorXd& theta,
                                               const HarmonicSkullMotion& motion,
                                               Eigen::Matrix3Xcd* response,
                                               std::vector<Eigen::Matrix3Xcd>* jacobian) const {
  const int groups = group_count();
  const Factors f = FactorsOf(theta, groups, motion);
  Eigen::MatrixXd k = reduced_springs_;
  for (int g = 0; g < groups; ++g) k += std::exp(theta[g]) * reduced_stiffness_[g];
  const Eigen::MatrixXcd a =
      f.stiffness * k.cast<Complex>() + f.mass * reduced_mass_.cast<Complex>();
  const Eigen::Matrix<Complex, 6, 1> load = LoadOf(motion);
  const Eigen::PartialPivLU<Eigen::MatrixXcd> lu(a);
  const Eigen::VectorXcd q = lu.solve(reduced_loads_.cast<Complex>() * load);
  if (!q.allFinite()) {
    return InternalError(fmt::format("harmonic response: the reduced system at {} Hz is singular",
                                     motion.frequency_hz));
  }
  const Eigen::MatrixXcd observed = observed_basis_.cast<Complex>();
  const Eigen::Index n = static_cast<Eigen::Index>(observed_.size());
  const Eigen::VectorXcd u = observed * q;
  *response = Eigen::Map<const Eigen::Matrix3Xcd>(u.data(), 3, n);
  if (jacobian == nullptr) return Status::Ok();
  Eigen::MatrixXcd rhs(q.size(), parameter_count());
  for (int g = 0; g < groups; ++g) {
    rhs.col(g) = f.stiffness * std::exp(theta[g]) * (reduced_stiffness_[g].cast<Complex>() * q);
  }
  rhs.col(groups) = Complex(0, f.omega * f.alpha) * (reduced_mass_.cast<Complex>() * q);
  rhs.col(groups + 1) = Complex(0, f.omega * f.beta) * (k.cast<Complex>() * q);
  const Eigen::MatrixXcd dq = -lu.solve(rhs);
  jacobian->resize(parameter_count());
  for (int j = 0; j < parameter_count(); ++j) {
    const Eigen::VectorXcd du = observed * dq.col(j);
    (*jacobian)[j] = Eigen::Map<const Eigen::Matrix3Xcd>(du.data(), 3, n);
  }
  return Status::Ok();
}

Status HarmonicTissueResponse::EvaluateFull(const Eigen::VectorXd& theta,
                                            const HarmonicSkullMotion& motion,
                                            Eigen::Matrix3Xcd* response,
                                            std::vector<Eigen::Matrix3Xcd>* jacobian) const {
  const int groups = group_count();
  const Factors f = FactorsOf(theta, groups, motion);
  const Eigen::Index nnz = parts_.stiffness_by_group.front().nonZeros();
  const Eigen::Index dofs = parts_.mass_dofs.size();

  // K (real, the shared pattern's values) and A = (1 + i w beta) K + (i w alpha - w^2) M.
  Eigen::VectorXd k_values = Eigen::VectorXd::Zero(nnz);
  for (int g = 0; g < groups; ++g) {
    k_values += std::exp(theta[g]) *
                Eigen::Map<const Eigen::VectorXd>(parts_.stiffness_by_group[g].valuePtr(), nnz);
  }
  for (Eigen::Index d = 0; d < dofs; ++d) k_values[diagonal_entry_[d]] += parts_.spring_dofs[d];
  ComplexSparse& a = solver_->system;
  Eigen::Map<Eigen::VectorXcd> a_values(a.valuePtr(), nnz);
  a_values = f.stiffness * k_values.cast<Complex>();
  for (Eigen::Index d = 0; d < dofs; ++d)
    a_values[diagonal_entry_[d]] += f.mass * parts_.mass_dofs[d];
  solver_->lu.factorize(a);
  if (solver_->lu.info() != Eigen::Success) {
    return InternalError(
        fmt::format("harmonic response: the system at {} Hz is singular", motion.frequency_hz));
  }
  const Eigen::Matrix<Complex, 6, 1> load = LoadOf(motion);
  const Eigen::VectorXcd force = parts_.load_fields.cast<Complex>() * load;
  const Eigen::VectorXcd u = solver_->lu.solve(force);
  if (solver_->lu.info() != Eigen::Success)
    return InternalError("harmonic response: the solve failed");

  const int n = static_cast<int>(observed_.size());
  auto gather = [&](const Eigen::VectorXcd& field, Eigen::Matrix3Xcd* out) {
    out->resize(3, n);
    for (int i = 0; i < n; ++i) out->col(i) = field.segment<3>(parts_.skin_dof[observed_[i]]);
  };
  gather(u, response);
  if (jacobian == nullptr) return Status::Ok();

  // dA/dtheta_j u for every parameter, then one multi-right-hand-side solve.
  Eigen::MatrixXcd rhs(dofs, parameter_count());
  auto multiply = [&](const Eigen::SparseMatrix<double>& k, double scale) -> Eigen::VectorXcd {
    return scale * (k * u.real()) + Complex(0, 1) * (scale * (k * u.imag()));
  };
  Eigen::VectorXcd k_u = Eigen::VectorXcd::Zero(dofs);
  for (int g = 0; g < groups; ++g) {
    const Eigen::VectorXcd kg_u = multiply(parts_.stiffness_by_group[g], std::exp(theta[g]));
    rhs.col(g) = f.stiffness * kg_u;
    k_u += kg_u;
  }
  k_u += parts_.spring_dofs.cast<Complex>().cwiseProduct(u);
  rhs.col(groups) =
      Complex(0, f.omega * f.alpha) * parts_.mass_dofs.cast<Complex>().cwiseProduct(u);
  rhs.col(groups + 1) = Complex(0, f.omega * f.beta) * k_u;
  const Eigen::MatrixXcd du = -solver_->lu.solve(rhs);
  jacobian->resize(parameter_count());
  for (int j = 0; j < parameter_count(); ++j) gather(du.col(j), &(*jacobian)[j]);
  return Status::Ok();
}

}  // namespace facedyn::physics
