#include "sim/soft_tissue.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <set>

#include <Eigen/CholmodSupport>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <fmt/format.h>

#include "core/check.h"

namespace facedyn::sim {
namespace {

using SparseMatrix = Eigen::SparseMatrix<double>;
using Matrix12d = Eigen::Matrix<double, 12, 12>;
using Vector12d = Eigen::Matrix<double, 12, 1>;
using Solver = Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower>;

// Newmark average-acceleration constants.
constexpr double kNewmarkBeta = 0.25;
constexpr double kNewmarkGamma = 0.5;

// Linear-tetrahedron stiffness for E = 1 (Zienkiewicz & Taylor, The Finite Element Method,
// vol. 1, ch. 6): K = V B^T D B with B the 6x12 strain-displacement matrix.
Matrix12d UnitTetStiffness(const Eigen::Matrix3d& dm_inverse, double volume, double poisson) {
  Eigen::Matrix<double, 3, 4> grad;  // gradients of the barycentric shape functions
  grad.rightCols<3>() = dm_inverse.transpose();
  grad.col(0) = -grad.rightCols<3>().rowwise().sum();
  Eigen::Matrix<double, 6, 12> b = Eigen::Matrix<double, 6, 12>::Zero();
  for (int n = 0; n < 4; ++n) {
    const double gx = grad(0, n), gy = grad(1, n), gz = grad(2, n);
    b(0, 3 * n) = gx;
    b(1, 3 * n + 1) = gy;
    b(2, 3 * n + 2) = gz;
    b(3, 3 * n) = gy, b(3, 3 * n + 1) = gx;
    b(4, 3 * n + 1) = gz, b(4, 3 * n + 2) = gy;
    b(5, 3 * n) = gz, b(5, 3 * n + 2) = gx;
  }
  const double nu = poisson;
  const double scale = 1.0 / ((1 + nu) * (1 - 2 * nu));
  Eigen::Matrix<double, 6, 6> d = Eigen::Matrix<double, 6, 6>::Zero();
  d.topLeftCorner<3, 3>().setConstant(nu * scale);
  for (int i = 0; i < 3; ++i) d(i, i) = (1 - nu) * scale;
  for (int i = 3; i < 6; ++i) d(i, i) = (1 - 2 * nu) / 2 * scale;
  return volume * b.transpose() * d * b;
}

// Rotation of the polar decomposition F = R S, proper (det +1).
Eigen::Matrix3d PolarRotation(const Eigen::Matrix3d& f) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(f, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d u = svd.matrixU();
  const Eigen::Matrix3d v = svd.matrixV();
  if ((u * v.transpose()).determinant() < 0) u.col(2) = -u.col(2);
  return u * v.transpose();
}

}  // namespace

Status TissueOptions::Check() const {
  if (layers < 1 || layers > 8) return InvalidArgumentError(fmt::format("tissue.layers must be 1..8, got {}", layers));
  if (!(poisson_ratio > 0 && poisson_ratio < 0.49)) {
    return InvalidArgumentError(fmt::format("tissue.poisson_ratio must be in (0, 0.49), got {}", poisson_ratio));
  }
  if (!(density_kg_per_mm3 > 0)) return InvalidArgumentError("tissue.density_kg_per_mm3 must be positive");
  if (!(fundamental_hz > 0.5 && fundamental_hz < 200)) {
    return InvalidArgumentError(fmt::format("tissue.fundamental_hz must be in (0.5, 200), got {}", fundamental_hz));
  }
  if (!(damping_ratio >= 0 && damping_ratio < 2)) {
    return InvalidArgumentError(fmt::format("tissue.damping_ratio must be in [0, 2), got {}", damping_ratio));
  }
  if (!(mass_damping_share >= 0 && mass_damping_share <= 1)) {
    return InvalidArgumentError("tissue.mass_damping_share must be in [0, 1]");
  }
  if (!(muscle_stiffness_ratio >= 0)) return InvalidArgumentError("tissue.muscle_stiffness_ratio must be >= 0");
  if (!(activation_full_mm > 0)) return InvalidArgumentError("tissue.activation_full_mm must be positive");
  if (!(max_step_s > 0 && max_step_s <= 0.05)) return InvalidArgumentError("tissue.max_step_s must be in (0, 0.05]");
  return Status::Ok();
}

struct SoftTissueModel::Impl {
  // Rig data.
  int vertex_count = 0;
  int layers = 0;
  std::vector<Eigen::Matrix3Xd> deltas;
  Eigen::Vector3d jaw_pivot = Eigen::Vector3d::Zero();
  Eigen::Vector3d jaw_axis = Eigen::Vector3d::UnitX();
  std::vector<bool> in_jaw;

  // Discretisation.
  Eigen::Matrix3Xd rest;            // 3 x N
  Eigen::VectorXd mass;             // per node, kg
  std::vector<int> free_index;      // node -> free node index or -1
  std::vector<int> fixed_index;     // node -> constrained node index or -1
  std::vector<int> free_nodes, fixed_nodes;
  std::vector<Matrix12d> unit_stiffness;  // per tet, E = 1
  std::vector<Eigen::Matrix3d> dm_inverse;
  SparseMatrix kff, kfc;            // assembled stiffness, free-free and free-fixed
  std::vector<int> entry_map;       // 144 per tet: >=0 kff value, <=-2 kfc value -(i+2), -1 none
  double youngs = 1.0;

  // Reference (linearisation point).
  bool has_reference = false;
  Eigen::VectorXd w_ref;
  double jaw_ref = 0.0;
  Eigen::Matrix3Xd x_ref;           // 3 x N
  Eigen::VectorXd spring;           // per node, kg s^-2 (zero-length spring stiffness)
  Eigen::Matrix3Xd target_ref;      // muscle targets at the reference
  Eigen::VectorXd mass_dofs;        // per free DOF
  double dt = 0.0;
  double alpha = 0.0, beta = 0.0;
  std::unique_ptr<Solver> static_solver, dynamic_solver;

  // Dynamic state (free DOFs, displacement from x_ref).
  Eigen::VectorXd u, v, a;
  Eigen::VectorXd fixed_u_prev;  // constrained-node displacement at the previous step (3 * nc)

  int nf() const { return static_cast<int>(free_nodes.size()); }
  int nc() const { return static_cast<int>(fixed_nodes.size()); }

  Eigen::Vector3d JawPosition(const Eigen::Vector3d& p, double angle) const {
    return jaw_pivot + Eigen::AngleAxisd(angle, jaw_axis) * (p - jaw_pivot);
  }

  // Positions of the constrained (layer-0) nodes for a jaw angle: the cranium is fixed, the
  // mandible's attachment rotates about the jaw hinge.
  Eigen::Matrix3Xd FixedPositions(double jaw_angle) const {
    Eigen::Matrix3Xd p(3, nc());
    for (int c = 0; c < nc(); ++c) {
      const int node = fixed_nodes[c];
      const int vertex = node % vertex_count;
      p.col(c) = in_jaw[vertex] ? JawPosition(rest.col(node), jaw_angle) : Eigen::Vector3d(rest.col(node));
    }
    return p;
  }

  // Muscle targets of every node for the given weights and jaw angle (Bao et al. 2018: interior
  // targets linear in the blendshape weights). Depth s = l / layers blends the skin's delta
  // with the mandible's motion below it.
  Eigen::Matrix3Xd Targets(const Eigen::VectorXd& weights, double jaw_angle) const {
    Eigen::Matrix3Xd skin_delta = Eigen::Matrix3Xd::Zero(3, vertex_count);
    for (size_t k = 0; k < deltas.size(); ++k) {
      if (weights[k] != 0.0) skin_delta += weights[k] * deltas[k];
    }
    Eigen::Matrix3Xd targets = rest;
    for (int l = 0; l <= layers; ++l) {
      const double s = double(l) / layers;
      for (int i = 0; i < vertex_count; ++i) {
        const int node = l * vertex_count + i;
        Eigen::Vector3d jaw_delta = Eigen::Vector3d::Zero();
        if (in_jaw[i]) jaw_delta = JawPosition(rest.col(i), jaw_angle) - rest.col(i);
        targets.col(node) += s * skin_delta.col(i) + (1 - s) * jaw_delta;
      }
    }
    return targets;
  }

  Eigen::VectorXd StaticForce(const TissueForcing& forcing, Eigen::VectorXd* fixed_u) const;

  Eigen::VectorXd GatherFree(const Eigen::Matrix3Xd& per_node) const {
    Eigen::VectorXd out(3 * nf());
    for (int f = 0; f < nf(); ++f) out.segment<3>(3 * f) = per_node.col(free_nodes[f]);
    return out;
  }

  void BuildPattern(const Eigen::Matrix4Xi& tets) {
    std::vector<Eigen::Triplet<double>> ff, fc;
    ff.reserve(tets.cols() * 144);
    for (int e = 0; e < tets.cols(); ++e) {
      for (int i = 0; i < 4; ++i) {
        const int fi = free_index[tets(i, e)];
        if (fi < 0) continue;
        for (int j = 0; j < 4; ++j) {
          const int fj = free_index[tets(j, e)];
          const int cj = fixed_index[tets(j, e)];
          for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c) {
              if (fj >= 0) ff.emplace_back(3 * fi + r, 3 * fj + c, 0.0);
              else fc.emplace_back(3 * fi + r, 3 * cj + c, 0.0);
            }
          }
        }
      }
    }
    for (int d = 0; d < 3 * nf(); ++d) ff.emplace_back(d, d, 0.0);  // springs live on the diagonal
    kff.resize(3 * nf(), 3 * nf());
    kff.setFromTriplets(ff.begin(), ff.end());
    kfc.resize(3 * nf(), 3 * nc());
    kfc.setFromTriplets(fc.begin(), fc.end());
    kff.makeCompressed();
    kfc.makeCompressed();
    auto find = [](const SparseMatrix& m, int row, int col) {
      const int* begin = m.innerIndexPtr() + m.outerIndexPtr()[col];
      const int* end = m.innerIndexPtr() + m.outerIndexPtr()[col + 1];
      const int* it = std::lower_bound(begin, end, row);
      FACEDYN_CHECK(it != end && *it == row, "sparse pattern misses an element entry");
      return static_cast<int>(it - m.innerIndexPtr());
    };
    entry_map.assign(size_t(tets.cols()) * 144, -1);
    for (int e = 0; e < tets.cols(); ++e) {
      for (int i = 0; i < 12; ++i) {
        const int fi = free_index[tets(i / 3, e)];
        if (fi < 0) continue;
        for (int j = 0; j < 12; ++j) {
          const int node_j = tets(j / 3, e);
          const int row = 3 * fi + i % 3;
          int& slot = entry_map[size_t(e) * 144 + i * 12 + j];
          if (free_index[node_j] >= 0) slot = find(kff, row, 3 * free_index[node_j] + j % 3);
          else slot = -2 - find(kfc, row, 3 * fixed_index[node_j] + j % 3);
        }
      }
    }
  }

  // Assembles the corotational stiffness at `x` (rotations from x; identity when x is null)
  // plus the springs, and the internal force R K (R^T x - X) on free DOFs when requested.
  void Assemble(const Eigen::Matrix3Xd* x, const Eigen::Matrix4Xi& tets, Eigen::VectorXd* internal_force) {
    std::fill(kff.valuePtr(), kff.valuePtr() + kff.nonZeros(), 0.0);
    std::fill(kfc.valuePtr(), kfc.valuePtr() + kfc.nonZeros(), 0.0);
    if (internal_force) internal_force->setZero(3 * nf());
    for (int e = 0; e < tets.cols(); ++e) {
      Matrix12d k = youngs * unit_stiffness[e];
      if (x) {
        Eigen::Matrix3d ds;
        for (int c = 0; c < 3; ++c) ds.col(c) = x->col(tets(c + 1, e)) - x->col(tets(0, e));
        const Eigen::Matrix3d r = PolarRotation(ds * dm_inverse[e]);
        Matrix12d rot = Matrix12d::Zero();
        for (int n = 0; n < 4; ++n) rot.block<3, 3>(3 * n, 3 * n) = r;
        if (internal_force) {
          Vector12d local;
          for (int n = 0; n < 4; ++n) {
            local.segment<3>(3 * n) = r.transpose() * x->col(tets(n, e)) - rest.col(tets(n, e));
          }
          const Vector12d f = rot * (k * local);
          for (int n = 0; n < 4; ++n) {
            const int fi = free_index[tets(n, e)];
            if (fi >= 0) internal_force->segment<3>(3 * fi) += f.segment<3>(3 * n);
          }
        }
        k = rot * k * rot.transpose();
      }
      const int* map = entry_map.data() + size_t(e) * 144;
      for (int i = 0; i < 12; ++i) {
        for (int j = 0; j < 12; ++j) {
          const int slot = map[i * 12 + j];
          if (slot >= 0) kff.valuePtr()[slot] += k(i, j);
          else if (slot <= -2) kfc.valuePtr()[-2 - slot] += k(i, j);
        }
      }
    }
    if (spring.size() == static_cast<Eigen::Index>(rest.cols())) {
      for (int f = 0; f < nf(); ++f) {
        for (int c = 0; c < 3; ++c) kff.coeffRef(3 * f + c, 3 * f + c) += spring[free_nodes[f]];
      }
    }
  }
};

// Forces on free DOFs relative to the reference: gravity's change of direction in the skull
// frame, the muscle targets' change, and the mandible's prescribed motion (static part).
Eigen::VectorXd SoftTissueModel::Impl::StaticForce(const TissueForcing& forcing,
                                                   Eigen::VectorXd* fixed_u) const {
  const Impl& m = *this;
  const Eigen::Vector3d dg = forcing.kinematics.GravityInSkull() - kGravityInWorld;
  const Eigen::Matrix3Xd targets = m.Targets(forcing.weights, forcing.jaw_angle_rad);
  Eigen::VectorXd force(3 * m.nf());
  for (int f = 0; f < m.nf(); ++f) {
    const int node = m.free_nodes[f];
    force.segment<3>(3 * f) = m.mass[node] * dg + m.spring[node] * (targets.col(node) - m.target_ref.col(node));
  }
  const Eigen::Matrix3Xd fixed_now = m.FixedPositions(forcing.jaw_angle_rad);
  const Eigen::Matrix3Xd fixed_delta = fixed_now - m.FixedPositions(m.jaw_ref);
  *fixed_u = Eigen::Map<const Eigen::VectorXd>(fixed_delta.data(), 3 * m.nc());
  if (forcing.jaw_angle_rad != m.jaw_ref) force -= m.kfc * *fixed_u;
  return force;
}


SoftTissueModel::~SoftTissueModel() = default;

StatusOr<std::unique_ptr<SoftTissueModel>> SoftTissueModel::Create(const FaceRig& rig,
                                                                   const TissueOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  if (rig.skull.vertex_count() != rig.vertex_count()) {
    return FailedPreconditionError(fmt::format(
        "face rig '{}': the skull surface has {} vertices but the skin has {}; the tissue model "
        "needs a skull that shares the skin's topology (sim face generates one)",
        rig.name, rig.skull.vertex_count(), rig.vertex_count()));
  }
  std::unique_ptr<SoftTissueModel> model(new SoftTissueModel());
  model->options_ = options;
  model->impl_ = std::make_unique<Impl>();
  Impl& m = *model->impl_;
  model->shell_ = BuildTetShell(rig.neutral, rig.skull.positions_mm, options.layers);
  const TetShell& shell = model->shell_;
  if (shell.tets.cols() == 0) return FailedPreconditionError("face rig '" + rig.name + "': no tissue volume");
  m.vertex_count = rig.vertex_count();
  m.layers = options.layers;
  m.deltas = rig.blendshape_deltas_mm;
  m.jaw_pivot = rig.jaw.pivot_in_skull;
  m.jaw_axis = rig.jaw.axis_in_skull.normalized();
  m.in_jaw.assign(m.vertex_count, false);
  if (!rig.jaw.region.empty()) {
    for (int v : rig.regions.at(rig.jaw.region)) m.in_jaw[v] = true;
  }
  m.rest = shell.rest_positions_mm;
  const int n = shell.node_count();

  // Lumped mass and element data.
  m.mass.setZero(n);
  m.unit_stiffness.resize(shell.tets.cols());
  m.dm_inverse.resize(shell.tets.cols());
  std::vector<bool> used(n, false);
  for (int e = 0; e < shell.tets.cols(); ++e) {
    Eigen::Matrix3d dm;
    for (int c = 0; c < 3; ++c) dm.col(c) = m.rest.col(shell.tets(c + 1, e)) - m.rest.col(shell.tets(0, e));
    const double volume = dm.determinant() / 6.0;
    m.dm_inverse[e] = dm.inverse();
    m.unit_stiffness[e] = UnitTetStiffness(m.dm_inverse[e], volume, options.poisson_ratio);
    for (int k = 0; k < 4; ++k) {
      m.mass[shell.tets(k, e)] += options.density_kg_per_mm3 * volume / 4.0;
      used[shell.tets(k, e)] = true;
    }
  }
  // Layer-0 nodes are attached to bone; nodes no tetrahedron touches are held too.
  m.free_index.assign(n, -1);
  m.fixed_index.assign(n, -1);
  for (int node = 0; node < n; ++node) {
    if (node >= m.vertex_count && used[node]) {
      m.free_index[node] = static_cast<int>(m.free_nodes.size());
      m.free_nodes.push_back(node);
    } else {
      m.fixed_index[node] = static_cast<int>(m.fixed_nodes.size());
      m.fixed_nodes.push_back(node);
    }
  }
  model->free_dofs_.resize(3 * m.nf());
  m.mass_dofs.resize(3 * m.nf());
  for (int f = 0; f < m.nf(); ++f) m.mass_dofs.segment<3>(3 * f).setConstant(m.mass[m.free_nodes[f]]);
  m.BuildPattern(shell.tets);

  // Calibrate E so that the neutral face's fundamental frequency is options.fundamental_hz:
  // natural frequencies scale with sqrt(E) at fixed Poisson ratio and mass.
  m.youngs = 1.0;
  m.Assemble(nullptr, shell.tets, nullptr);
  FACEDYN_ASSIGN_OR_RETURN(const std::vector<double> unit_hz, model->NaturalFrequenciesHz(1));
  m.youngs = std::pow(options.fundamental_hz / unit_hz[0], 2);
  model->youngs_modulus_kpa_ = m.youngs;
  const double omega = 2 * M_PI * options.fundamental_hz;
  m.alpha = 2 * options.mass_damping_share * options.damping_ratio * omega;
  m.beta = 2 * (1 - options.mass_damping_share) * options.damping_ratio / omega;
  model->rayleigh_mass_ = m.alpha;
  model->rayleigh_stiffness_ = m.beta;
  m.Assemble(nullptr, shell.tets, nullptr);
  return model;
}

StatusOr<std::vector<double>> SoftTissueModel::NaturalFrequenciesHz(int count) const {
  const Impl& m = *impl_;
  FACEDYN_CHECK(count >= 1, "count must be positive");
  // Subspace iteration (Bathe, Finite Element Procedures, 11.6) with count + 4 vectors.
  Solver solver;
  solver.compute(m.kff);
  if (solver.info() != Eigen::Success) return InternalError("tissue stiffness is not positive definite");
  const int p = std::min(count + 4, static_cast<int>(m.kff.rows()));
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  Eigen::MatrixXd x(m.kff.rows(), p);
  for (Eigen::Index i = 0; i < x.size(); ++i) x.data()[i] = normal(rng);
  Eigen::VectorXd eigenvalues;
  Eigen::VectorXd previous = Eigen::VectorXd::Constant(p, -1.0);
  for (int iteration = 0; iteration < 60; ++iteration) {
    const Eigen::MatrixXd y = solver.solve(m.mass_dofs.asDiagonal() * x);
    const Eigen::MatrixXd ky = m.kff.selfadjointView<Eigen::Lower>() * y;
    const Eigen::MatrixXd kr = y.transpose() * ky;
    const Eigen::MatrixXd mr = y.transpose() * m.mass_dofs.asDiagonal() * y;
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> ritz(kr, mr);
    eigenvalues = ritz.eigenvalues();
    x = y * ritz.eigenvectors();
    if (((eigenvalues - previous).cwiseAbs().array() <= 1e-10 * eigenvalues.cwiseAbs().array()).head(count).all()) break;
    previous = eigenvalues;
  }
  std::vector<double> hz(count);
  for (int i = 0; i < count; ++i) hz[i] = std::sqrt(std::max(0.0, eigenvalues[i])) / (2 * M_PI);
  return hz;
}

StatusOr<ReferenceSummary> SoftTissueModel::SetReference(const Eigen::VectorXd& weights,
                                                         double jaw_angle_rad, double dt_s) {
  Impl& m = *impl_;
  FACEDYN_CHECK(weights.size() == static_cast<Eigen::Index>(m.deltas.size()), "one weight per blendshape");
  FACEDYN_CHECK(dt_s > 0, "dt must be positive");
  m.w_ref = weights;
  m.jaw_ref = jaw_angle_rad;
  m.dt = dt_s;

  // Activation per skin vertex from the expression's displacement; springs scale with the
  // node's own elastic stiffness so the stiffening is resolution-independent.
  Eigen::Matrix3Xd skin_delta = Eigen::Matrix3Xd::Zero(3, m.vertex_count);
  for (size_t k = 0; k < m.deltas.size(); ++k) skin_delta += weights[k] * m.deltas[k];
  m.spring.setZero(m.rest.cols());
  m.Assemble(nullptr, shell_.tets, nullptr);
  for (int f = 0; f < m.nf(); ++f) {
    const int node = m.free_nodes[f];
    const double activation = std::min(1.0, skin_delta.col(node % m.vertex_count).norm() / options_.activation_full_mm);
    const double diagonal = (m.kff.coeff(3 * f, 3 * f) + m.kff.coeff(3 * f + 1, 3 * f + 1) +
                             m.kff.coeff(3 * f + 2, 3 * f + 2)) / 3.0;
    m.spring[node] = options_.muscle_stiffness_ratio * activation * diagonal;
  }
  m.target_ref = m.Targets(weights, jaw_angle_rad);

  // Newton on the corotational equilibrium f_int(x) + k (x - t) = m g0 with bone nodes held.
  Eigen::Matrix3Xd x = m.target_ref;
  const Eigen::Matrix3Xd fixed = m.FixedPositions(jaw_angle_rad);
  for (int c = 0; c < m.nc(); ++c) x.col(m.fixed_nodes[c]) = fixed.col(c);
  const Eigen::Vector3d g0 = kGravityInWorld;
  ReferenceSummary summary;
  Solver solver;
  Eigen::VectorXd internal;
  for (int iteration = 1; iteration <= 25; ++iteration) {
    m.Assemble(&x, shell_.tets, &internal);
    Eigen::VectorXd residual = internal;
    for (int f = 0; f < m.nf(); ++f) {
      const int node = m.free_nodes[f];
      residual.segment<3>(3 * f) += m.spring[node] * (x.col(node) - m.target_ref.col(node)) - m.mass[node] * g0;
    }
    summary.iterations = iteration;
    summary.max_residual = residual.cwiseAbs().maxCoeff();
    if (iteration == 1) solver.analyzePattern(m.kff);
    solver.factorize(m.kff);
    if (solver.info() != Eigen::Success) return InternalError("expression equilibrium: stiffness is not positive definite");
    const Eigen::VectorXd step = solver.solve(-residual);
    for (int f = 0; f < m.nf(); ++f) x.col(m.free_nodes[f]) += step.segment<3>(3 * f);
    if (step.cwiseAbs().maxCoeff() < 1e-6) {
      summary.converged = true;
      break;
    }
  }
  m.x_ref = x;
  // Linearisation: stiffness at the equilibrium, Rayleigh damping, Newmark effective matrix.
  m.Assemble(&m.x_ref, shell_.tets, nullptr);
  m.static_solver = std::make_unique<Solver>();
  m.static_solver->compute(m.kff);
  if (m.static_solver->info() != Eigen::Success) return InternalError("linearised stiffness is not positive definite");
  const double c_k = 1.0 + m.beta * kNewmarkGamma / (kNewmarkBeta * dt_s);
  const double c_m = 1.0 / (kNewmarkBeta * dt_s * dt_s) + m.alpha * kNewmarkGamma / (kNewmarkBeta * dt_s);
  SparseMatrix effective = c_k * m.kff;
  for (int d = 0; d < effective.rows(); ++d) effective.coeffRef(d, d) += c_m * m.mass_dofs[d];
  m.dynamic_solver = std::make_unique<Solver>();
  m.dynamic_solver->compute(effective);
  if (m.dynamic_solver->info() != Eigen::Success) return InternalError("Newmark matrix is not positive definite");
  m.has_reference = true;
  m.u.setZero(3 * m.nf());
  m.v.setZero(3 * m.nf());
  m.a.setZero(3 * m.nf());
  m.fixed_u_prev.setZero(3 * m.nc());
  return summary;
}

void SoftTissueModel::Reset(const TissueForcing& forcing) {
  Impl& m = *impl_;
  FACEDYN_CHECK(m.has_reference, "SetReference before Reset");
  Eigen::VectorXd fixed_u;
  const Eigen::VectorXd f_static = m.StaticForce(forcing, &fixed_u);
  m.u = m.static_solver->solve(f_static);
  m.v.setZero(3 * m.nf());
  m.fixed_u_prev = fixed_u;
  // a(0) from the equation of motion at rest: M a = F_dyn - K u = fictitious forces.
  const SkullKinematics& k = forcing.kinematics;
  for (int f = 0; f < m.nf(); ++f) {
    const Eigen::Vector3d p = m.x_ref.col(m.free_nodes[f]);
    const Eigen::Vector3d& w = k.angular_velocity_in_skull;
    m.a.segment<3>(3 * f) =
        -(k.origin_acceleration_in_skull + k.angular_acceleration_in_skull.cross(p) + w.cross(w.cross(p)));
  }
}

void SoftTissueModel::Step(const TissueForcing& forcing) {
  Impl& m = *impl_;
  FACEDYN_CHECK(m.has_reference, "SetReference before Step");
  const double dt = m.dt;
  Eigen::VectorXd fixed_u;
  Eigen::VectorXd force = m.StaticForce(forcing, &fixed_u);
  // Fictitious forces of the skull frame, with the Coriolis term from the current velocity
  // (explicit: it is tiny next to the others for head motion).
  const SkullKinematics& k = forcing.kinematics;
  const Eigen::Vector3d& w = k.angular_velocity_in_skull;
  const bool rotating = w.squaredNorm() > 0 || k.angular_acceleration_in_skull.squaredNorm() > 0;
  for (int f = 0; f < m.nf(); ++f) {
    const int node = m.free_nodes[f];
    Eigen::Vector3d a_frame = k.origin_acceleration_in_skull;
    if (rotating) {
      const Eigen::Vector3d p = m.x_ref.col(node);
      a_frame += k.angular_acceleration_in_skull.cross(p) + w.cross(w.cross(p)) +
                 2.0 * w.cross(Eigen::Vector3d(m.v.segment<3>(3 * f)));
    }
    force.segment<3>(3 * f) -= m.mass[node] * a_frame;
  }
  if (m.beta > 0 && (fixed_u - m.fixed_u_prev).squaredNorm() > 0) {
    force -= m.beta * (m.kfc * ((fixed_u - m.fixed_u_prev) / dt));
  }
  m.fixed_u_prev = fixed_u;

  const double b = kNewmarkBeta, g = kNewmarkGamma;
  const Eigen::VectorXd mass_part = (1 / (b * dt * dt)) * m.u + (1 / (b * dt)) * m.v + (1 / (2 * b) - 1) * m.a;
  const Eigen::VectorXd damp_part = (g / (b * dt)) * m.u + (g / b - 1) * m.v + dt * (g / (2 * b) - 1) * m.a;
  Eigen::VectorXd rhs = force + m.mass_dofs.cwiseProduct(mass_part);
  if (m.alpha > 0) rhs += m.alpha * m.mass_dofs.cwiseProduct(damp_part);
  if (m.beta > 0) rhs += m.beta * (m.kff * damp_part);
  const Eigen::VectorXd u_new = m.dynamic_solver->solve(rhs);
  const Eigen::VectorXd a_new = (1 / (b * dt * dt)) * (u_new - m.u) - (1 / (b * dt)) * m.v - (1 / (2 * b) - 1) * m.a;
  m.v += dt * ((1 - g) * m.a + g * a_new);
  m.a = a_new;
  m.u = u_new;
}

Eigen::Matrix3Xd SoftTissueModel::ReferenceSkin() const {
  const Impl& m = *impl_;
  FACEDYN_CHECK(m.has_reference, "SetReference first");
  return m.x_ref.rightCols(m.vertex_count);
}

Eigen::Matrix3Xd SoftTissueModel::DynamicSkin() const {
  const Impl& m = *impl_;
  Eigen::Matrix3Xd skin = ReferenceSkin();
  const int first = m.layers * m.vertex_count;
  for (int i = 0; i < m.vertex_count; ++i) {
    const int f = m.free_index[first + i];
    if (f >= 0) skin.col(i) += m.u.segment<3>(3 * f);
  }
  return skin;
}

Eigen::Matrix3Xd SoftTissueModel::QuasistaticSkin(const TissueForcing& forcing) const {
  const Impl& m = *impl_;
  FACEDYN_CHECK(m.has_reference, "SetReference first");
  Eigen::VectorXd fixed_u;
  const Eigen::VectorXd u_qs = m.static_solver->solve(m.StaticForce(forcing, &fixed_u));
  Eigen::Matrix3Xd skin = ReferenceSkin();
  const int first = m.layers * m.vertex_count;
  for (int i = 0; i < m.vertex_count; ++i) {
    const int f = m.free_index[first + i];
    if (f >= 0) skin.col(i) += u_qs.segment<3>(3 * f);
  }
  return skin;
}

double SoftTissueModel::Energy() const {
  const Impl& m = *impl_;
  return 0.5 * m.v.dot(m.mass_dofs.cwiseProduct(m.v)) + 0.5 * m.u.dot(m.kff * m.u);
}

void SoftTissueModel::SetVelocity(const Eigen::VectorXd& velocity) {
  Impl& m = *impl_;
  FACEDYN_CHECK(velocity.size() == m.v.size(), "one velocity per free DOF");
  m.v = velocity;
  // Keep the acceleration consistent with the equation of motion (no forcing).
  m.a = -(m.kff * m.u + m.alpha * m.mass_dofs.cwiseProduct(m.v) + m.beta * (m.kff * m.v)).cwiseQuotient(m.mass_dofs);
}

}  // namespace facedyn::sim
