#include "physics/soft_tissue.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <random>

#include <Eigen/CholmodSupport>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <fmt/format.h>

#include "core/check.h"

namespace facedyn::physics {
namespace {

using SparseMatrix = Eigen::SparseMatrix<double>;
using Matrix12d = Eigen::Matrix<double, 12, 12>;
// CHOLMOD's supernodal Cholesky (SuiteSparse): the factorisation is reused for every step.
using Solver = Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower>;

// Linear-tetrahedron stiffness for E = 1 (Zienkiewicz & Taylor, The Finite Element Method,
// vol. 1, ch. 6): K = V B^T D B with B the 6x12 strain-displacement matrix.
using Vector12d = Eigen::Matrix<double, 12, 1>;
using StrainMatrix = Eigen::Matrix<double, 6, 12>;

// B from the gradients of the four barycentric shape functions (columns); linear in them.
StrainMatrix StrainDisplacement(const Eigen::Matrix<double, 3, 4>& grad) {
  StrainMatrix b = StrainMatrix::Zero();
  for (int n = 0; n < 4; ++n) {
    const double gx = grad(0, n), gy = grad(1, n), gz = grad(2, n);
    b(0, 3 * n) = gx;
    b(1, 3 * n + 1) = gy;
    b(2, 3 * n + 2) = gz;
    b(3, 3 * n) = gy, b(3, 3 * n + 1) = gx;
    b(4, 3 * n + 1) = gz, b(4, 3 * n + 2) = gy;
    b(5, 3 * n) = gz, b(5, 3 * n + 2) = gx;
  }
  return b;
}

// Isotropic elasticity for E = 1 in Voigt order (xx yy zz xy yz zx, engineering shear).
Eigen::Matrix<double, 6, 6> UnitElasticity(double poisson) {
  const double nu = poisson;
  const double scale = 1.0 / ((1 + nu) * (1 - 2 * nu));
  Eigen::Matrix<double, 6, 6> d = Eigen::Matrix<double, 6, 6>::Zero();
  d.topLeftCorner<3, 3>().setConstant(nu * scale);
  for (int i = 0; i < 3; ++i) d(i, i) = (1 - nu) * scale;
  for (int i = 3; i < 6; ++i) d(i, i) = (1 - 2 * nu) / 2 * scale;
  return d;
}

// Shape-function gradients from the inverse edge matrix: node n >= 1 is row n-1 of dm^-1.
Eigen::Matrix<double, 3, 4> ShapeGradients(const Eigen::Matrix3d& dm_inverse) {
  Eigen::Matrix<double, 3, 4> grad;
  grad.rightCols<3>() = dm_inverse.transpose();
  grad.col(0) = -grad.rightCols<3>().rowwise().sum();
  return grad;
}

Matrix12d UnitTetStiffness(const Eigen::Matrix3d& dm, double poisson) {
  const double volume = std::abs(dm.determinant()) / 6.0;
  const StrainMatrix b = StrainDisplacement(ShapeGradients(dm.inverse()));
  return volume * b.transpose() * UnitElasticity(poisson) * b;
}

// One element about its rest geometry dm and a fixed displacement u, for the derivatives of its
// nodal forces K(dm) u as the rest geometry moves (E = 1).
struct TetLinearisation {
  Eigen::Matrix3d g;    // dm^-1
  double volume = 0.0;  // |V|
  StrainMatrix b;
  Eigen::Matrix<double, 6, 1> stress;  // D B u
  TetLinearisation(const Eigen::Matrix3d& dm, const Vector12d& u,
                   const Eigen::Matrix<double, 6, 6>& d)
      : g(dm.inverse()),
        volume(std::abs(dm.determinant()) / 6.0),
        b(StrainDisplacement(ShapeGradients(g))),
        stress(d * (b * u)) {}
  // d/dt [K(dm + t d_dm) u] at t = 0. With G = dm^-1: dG = -G d_dm G, d|V| = |V| tr(G d_dm),
  // and B is linear in the shape-function gradients.
  Vector12d ForceDerivative(const Eigen::Matrix3d& d_dm, const Vector12d& u,
                            const Eigen::Matrix<double, 6, 6>& d) const {
    const double d_volume = volume * (g * d_dm).trace();
    const StrainMatrix db = StrainDisplacement(ShapeGradients(-g * d_dm * g));
    return d_volume * b.transpose() * stress +
           volume * (db.transpose() * stress + b.transpose() * (d * (db * u)));
  }
};

// Lowest `count` eigenpairs of K phi = lambda M phi (lumped, diagonal M) by subspace iteration
// (Bathe, Finite Element Procedures, 11.6) with count + 2 vectors, using a factorised K.
void LowestModes(const Solver& solver, const SparseMatrix& k, const Eigen::VectorXd& mass, int count,
                 Eigen::VectorXd* eigenvalues, Eigen::MatrixXd* modes) {
  const int p = std::min(count + 2, static_cast<int>(k.rows()));
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  Eigen::MatrixXd x(k.rows(), p);
  for (Eigen::Index i = 0; i < x.size(); ++i) x.data()[i] = normal(rng);
  Eigen::VectorXd previous = Eigen::VectorXd::Constant(p, -1.0);
  for (int iteration = 0; iteration < 60; ++iteration) {
    const Eigen::MatrixXd y = solver.solve(mass.asDiagonal() * x);
    const Eigen::MatrixXd kr = y.transpose() * (k * y);
    const Eigen::MatrixXd mr = y.transpose() * mass.asDiagonal() * y;
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> ritz(kr, mr);
    *eigenvalues = ritz.eigenvalues();
    x = y * ritz.eigenvectors();
    if (((*eigenvalues - previous).cwiseAbs().array() <= 1e-7 * eigenvalues->cwiseAbs().array()).head(count).all()) {
      break;
    }
    previous = *eigenvalues;
  }
  *modes = x.leftCols(count);
  eigenvalues->conservativeResize(count);
}
}  // namespace

namespace {
using Complex = std::complex<double>;

// The two poles s = -zeta omega +- omega sqrt(zeta^2 - 1) of a mode (a conjugate pair when
// underdamped, two negative reals when overdamped).
std::pair<Complex, Complex> Poles(const DampedMode& mode) {
  const double omega = mode.omega_rad_s, zeta = mode.damping_ratio;
  const Complex root = omega * std::sqrt(Complex(zeta * zeta - 1.0, 0.0));
  return {-zeta * omega + root, -zeta * omega - root};
}

// The mode with poles s1, s2: omega^2 = s1 s2 and 2 zeta omega = -(s1 + s2), which holds for
// both a conjugate pair and two real poles.
DampedMode FromPoles(Complex s1, Complex s2) {
  const double omega = std::sqrt((s1 * s2).real());
  return {omega, -(s1 + s2).real() / (2 * omega)};
}
}  // namespace

DampedMode NewmarkApparentMode(const DampedMode& continuous, double dt_s) {
  FACEDYN_CHECK(dt_s > 0 && continuous.omega_rad_s > 0, "dt and omega must be positive");
  const auto [s1, s2] = Poles(continuous);
  const double h = dt_s / 2;
  auto apparent = [&](Complex s) { return std::log((1.0 + s * h) / (1.0 - s * h)) / dt_s; };
  return FromPoles(apparent(s1), apparent(s2));
}

DampedMode NewmarkCompensatedMode(const DampedMode& apparent, double dt_s) {
  FACEDYN_CHECK(dt_s > 0 && apparent.omega_rad_s > 0, "dt and omega must be positive");
  const auto [s1, s2] = Poles(apparent);
  FACEDYN_CHECK(std::abs(s1.imag()) * dt_s < M_PI,
                "the damped period must span more than two steps");
  // z = exp(s_apparent dt) and s = (2 / dt) (z - 1) / (z + 1) = (2 / dt) tanh(s_apparent dt / 2).
  auto continuous = [&](Complex s) { return (2.0 / dt_s) * std::tanh(s * (dt_s / 2)); };
  return FromPoles(continuous(s1), continuous(s2));
}

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
  if (!(muscle_hz >= 0 && muscle_hz < 200)) {
    return InvalidArgumentError(fmt::format("tissue.muscle_hz must be in [0, 200), got {}", muscle_hz));
  }
  if (!(activation_full_mm > 0)) return InvalidArgumentError("tissue.activation_full_mm must be positive");
  if (!(max_step_s > 0 && max_step_s <= 0.05)) return InvalidArgumentError("tissue.max_step_s must be in (0, 0.05]");
  // The step's compensation (NewmarkCompensatedMode) needs the period to span more than two
  // steps; four keep the simulated motion a fair sampling of it.
  if (fundamental_hz * max_step_s > 0.25) {
    return InvalidArgumentError(
        fmt::format("tissue.max_step_s ({} s) must give at least 4 steps per period of "
                    "tissue.fundamental_hz ({} Hz)",
                    max_step_s, fundamental_hz));
  }
  return Status::Ok();
}

struct SoftTissueModel::Impl {
  // Rig data.
  int vertex_count = 0;
  int layers = 0;
  int k_shapes = 0;
  std::vector<Eigen::Matrix3Xd> deltas;
  Eigen::Vector3d jaw_pivot = Eigen::Vector3d::Zero();
  Eigen::Vector3d jaw_axis = Eigen::Vector3d::UnitX();
  std::vector<bool> in_jaw;

  // Discretisation.
  Eigen::Matrix4Xi tets;
  Eigen::Matrix3Xd rest;            // 3 x N, neutral
  Eigen::VectorXd mass;             // per node, kg (from the neutral volume; mass is conserved)
  std::vector<int> free_index;      // node -> free node index or -1 (bone-attached)
  std::vector<int> free_nodes;
  Eigen::VectorXd mass_dofs;        // per free DOF
  SparseMatrix kff;                 // stiffness on free DOFs
  std::vector<int> entry_map;       // 144 per tet: index into kff values, or -1
  double youngs = 1.0;
  double unit_eigenvalue = 0.0;  // w^2 of the calibrated mode for E = 1 (w^2 scales with E)
  bool explicit_material = false;     // SetMaterial: no calibration from the options
  Eigen::VectorXd tet_scale;          // per tet stiffness scale (empty = 1)
  std::vector<int> cheek_vertices;    // the rig's "cheeks" region (mode selection)

  // Reference expression (linearisation point) and prefactored systems.
  bool has_reference = false;
  bool has_dynamics = false;  // the Newmark system is factorised (SetReference, not static)
  Eigen::VectorXd w_ref;
  double jaw_ref = 0.0;
  Eigen::Matrix3Xd x_ref;           // 3 x N targets of the reference expression
  Eigen::VectorXd spring;           // per node, kg s^-2
  double dt = 0.0;
  double alpha = 0.0, beta = 0.0;
  double c_k = 1.0, c_m = 0.0;      // K_eff = c_k K + c_m M
  std::unique_ptr<Solver> static_solver, dynamic_solver;

  // Forcing fields on free DOFs; every force is fields * coefficients (see Step):
  //   [0,3)            m e_k          gravity change and frame acceleration
  //   [3,6)            m (e_k x p)    angular acceleration
  //   [6,15)           m p_j e_i      centripetal, coefficient |w|^2 delta_ij - w_i w_j
  //   [15,15+K)        m s delta_k    acceleration of blendshape k's targets
  //   15+K, 16+K       m (1-s) A1, A2 acceleration of the mandible's targets, where by
  //                    Rodrigues' formula the mandible moves a point by
  //                    sin(th) A1 + (1 - cos(th)) A2, A1 = a x v, A2 = a x (a x v).
  static constexpr int kColW = 3, kColC = 6, kColE = 15;
  int field_columns() const { return kColE + k_shapes + 2; }
  Eigen::MatrixXd fields;            // 3nf x field_columns()
  Eigen::MatrixXd gravity_response;  // 3V (skin rows) x 3: K^-1 m e_k

  // Dynamic state: displacement u of free nodes from their (moving) targets, with K u and
  // K v kept alongside so a step needs no sparse matrix-vector product.
  Eigen::VectorXd u, v, a, ku, kv;
  Eigen::Matrix3Xd skin_targets;     // skin targets at the last Reset/Step

  int nf() const { return static_cast<int>(free_nodes.size()); }

  // E and the Rayleigh coefficients for steps of step_s: the calibrated mode's continuous
  // frequency and damping are those that Newmark's rule at step_s turns into the configured ones,
  // and alpha + beta w^2 = 2 zeta w splits its damping between mass and stiffness at that w.
  void Calibrate(const TissueOptions& options, double step_s) {
    if (explicit_material) return;
    const DampedMode continuous =
        NewmarkCompensatedMode({2 * M_PI * options.fundamental_hz, options.damping_ratio}, step_s);
    const double omega = continuous.omega_rad_s, zeta = continuous.damping_ratio;
    youngs = omega * omega / unit_eigenvalue;
    alpha = 2 * options.mass_damping_share * zeta * omega;
    beta = 2 * (1 - options.mass_damping_share) * zeta / omega;
  }

  // Targets of every node for an expression: depth s = l / layers blends the skin's delta
  // (s = 1) with the mandible's motion at the bone (s = 0).
  Eigen::Matrix3Xd Targets(const Eigen::VectorXd& weights, double jaw_angle) const {
    Eigen::Matrix3Xd skin_delta = Eigen::Matrix3Xd::Zero(3, vertex_count);
    for (int k = 0; k < k_shapes; ++k) {
      if (weights[k] != 0.0) skin_delta += weights[k] * deltas[k];
    }
    const Eigen::Matrix3d jaw_rotation = Eigen::AngleAxisd(jaw_angle, jaw_axis).toRotationMatrix();
    Eigen::Matrix3Xd targets = rest;
    for (int l = 0; l <= layers; ++l) {
      const double s = double(l) / layers;
      for (int i = 0; i < vertex_count; ++i) {
        Eigen::Vector3d jaw_delta = Eigen::Vector3d::Zero();
        if (in_jaw[i] && s < 1) jaw_delta = jaw_rotation * (rest.col(i) - jaw_pivot) + jaw_pivot - rest.col(i);
        targets.col(l * vertex_count + i) += s * skin_delta.col(i) + (1 - s) * jaw_delta;
      }
    }
    return targets;
  }

  // Skin targets (the skin's share of Targets, s = 1): neutral plus blendshape deltas.
  Eigen::Matrix3Xd SkinTargets(const Eigen::VectorXd& weights) const {
    Eigen::Matrix3Xd skin = rest.rightCols(vertex_count);
    for (int k = 0; k < k_shapes; ++k) {
      if (weights[k] != 0.0) skin += weights[k] * deltas[k];
    }
    return skin;
  }

  void BuildPattern() {
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(tets.cols() * 144 + 3 * nf());
    for (int e = 0; e < tets.cols(); ++e) {
      for (int i = 0; i < 4; ++i) {
        const int fi = free_index[tets(i, e)];
        if (fi < 0) continue;
        for (int j = 0; j < 4; ++j) {
          const int fj = free_index[tets(j, e)];
          if (fj < 0) continue;
          for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c) triplets.emplace_back(3 * fi + r, 3 * fj + c, 0.0);
          }
        }
      }
    }
    for (int d = 0; d < 3 * nf(); ++d) triplets.emplace_back(d, d, 0.0);  // springs
    kff.resize(3 * nf(), 3 * nf());
    kff.setFromTriplets(triplets.begin(), triplets.end());
    kff.makeCompressed();
    entry_map.assign(size_t(tets.cols()) * 144, -1);
    for (int e = 0; e < tets.cols(); ++e) {
      for (int i = 0; i < 12; ++i) {
        const int fi = free_index[tets(i / 3, e)];
        if (fi < 0) continue;
        for (int j = 0; j < 12; ++j) {
          const int fj = free_index[tets(j / 3, e)];
          if (fj < 0) continue;
          const int row = 3 * fi + i % 3, col = 3 * fj + j % 3;
          const int* begin = kff.innerIndexPtr() + kff.outerIndexPtr()[col];
          const int* end = kff.innerIndexPtr() + kff.outerIndexPtr()[col + 1];
          const int* it = std::lower_bound(begin, end, row);
          FACEDYN_CHECK(it != end && *it == row, "sparse pattern misses an element entry");
          entry_map[size_t(e) * 144 + i * 12 + j] = static_cast<int>(it - kff.innerIndexPtr());
        }
      }
    }
  }

  // K = E * sum of element stiffnesses on `geometry` + springs. Returns the number of
  // tetrahedra that `geometry` turns inside out.
  int Assemble(const Eigen::Matrix3Xd& geometry, double poisson) {
    std::fill(kff.valuePtr(), kff.valuePtr() + kff.nonZeros(), 0.0);
    int inverted = 0;
    for (int e = 0; e < tets.cols(); ++e) {
      Eigen::Matrix3d dm;
      for (int c = 0; c < 3; ++c) dm.col(c) = geometry.col(tets(c + 1, e)) - geometry.col(tets(0, e));
      if (dm.determinant() <= 0) ++inverted;
      const double scale = tet_scale.size() == tets.cols() ? tet_scale[e] : 1.0;
      const Matrix12d k = youngs * scale * UnitTetStiffness(dm, poisson);
      const int* map = entry_map.data() + size_t(e) * 144;
      for (int i = 0; i < 144; ++i) {
        if (map[i] >= 0) kff.valuePtr()[map[i]] += k(i / 12, i % 12);
      }
    }
    if (spring.size() == rest.cols()) {
      for (int f = 0; f < nf(); ++f) {
        for (int c = 0; c < 3; ++c) kff.coeffRef(3 * f + c, 3 * f + c) += spring[free_nodes[f]];
      }
    }
    return inverted;
  }

  void BuildFields() {
    fields.setZero(3 * nf(), field_columns());
    for (int f = 0; f < nf(); ++f) {
      const int node = free_nodes[f];
      const int vertex = node % vertex_count;
      const double s = double(node / vertex_count) / layers;
      const double m = mass[node];
      const Eigen::Vector3d p = x_ref.col(node);
      for (int k = 0; k < 3; ++k) {
        fields(3 * f + k, k) = m;
        fields.block<3, 1>(3 * f, kColW + k) = m * Eigen::Vector3d::Unit(k).cross(p);
        for (int j = 0; j < 3; ++j) fields(3 * f + k, kColC + 3 * k + j) = m * p[j];
      }
      for (int k = 0; k < k_shapes; ++k) fields.block<3, 1>(3 * f, kColE + k) = m * s * deltas[k].col(vertex);
      if (in_jaw[vertex] && s < 1) {
        const Eigen::Vector3d lever = rest.col(vertex) - jaw_pivot;
        fields.block<3, 1>(3 * f, kColE + k_shapes) = m * (1 - s) * jaw_axis.cross(lever);
        fields.block<3, 1>(3 * f, kColE + k_shapes + 1) = m * (1 - s) * jaw_axis.cross(jaw_axis.cross(lever));
      }
    }
    const Eigen::MatrixXd response = static_solver->solve(fields.leftCols<3>());
    gravity_response.setZero(3 * vertex_count, 3);
    for (int i = 0; i < vertex_count; ++i) {
      const int f = free_index[layers * vertex_count + i];
      if (f >= 0) gravity_response.middleRows<3>(3 * i) = response.middleRows<3>(3 * f);
    }
  }

  // The calibrated mode is the one that dominates the cheeks' vertical response to vertical
  // head motion (largest |participation x cheek amplitude| / omega^2 among the lowest six),
  // i.e. the frequency at which the cheeks ring after a jolt; without a "cheeks" region, the
  // lowest mode. Uses the factorised static system; fills the lowest six eigenpairs.
  int CheekModeIndex(Eigen::VectorXd* eigenvalues, Eigen::MatrixXd* modes) const {
    constexpr int kCalibrationModes = 6;
    LowestModes(*static_solver, kff, mass_dofs, kCalibrationModes, eigenvalues, modes);
    int calibrated_mode = 0;
    if (cheek_vertices.empty()) return calibrated_mode;
    double best = -1;
    for (int i = 0; i < kCalibrationModes; ++i) {
      double participation = 0, modal_mass = 0;
      for (int f = 0; f < nf(); ++f) {
        participation += mass_dofs[3 * f + 1] * (*modes)(3 * f + 1, i);
        modal_mass += mass_dofs.segment<3>(3 * f).dot(modes->col(i).segment<3>(3 * f).cwiseAbs2());
      }
      double cheek_y = 0;
      for (int vertex : cheek_vertices) {
        const int f = free_index[layers * vertex_count + vertex];
        if (f >= 0) cheek_y += (*modes)(3 * f + 1, i);
      }
      const double score = std::abs(participation / modal_mass * cheek_y) / (*eigenvalues)[i];
      if (score > best) {
        best = score;
        calibrated_mode = i;
      }
    }
    return calibrated_mode;
  }

  // Skin positions for targets plus a displacement field on free DOFs.
  Eigen::Matrix3Xd Skin(const Eigen::Matrix3Xd& targets, const Eigen::VectorXd& displacement) const {
    Eigen::Matrix3Xd skin = targets;
    const int first = layers * vertex_count;
    for (int i = 0; i < vertex_count; ++i) {
      const int f = free_index[first + i];
      if (f >= 0) skin.col(i) += displacement.segment<3>(3 * f);
    }
    return skin;
  }
};

SoftTissueModel::~SoftTissueModel() = default;

StatusOr<std::unique_ptr<SoftTissueModel>> SoftTissueModel::Create(const FaceRig& rig,
                                                                   const TissueOptions& options) {
  return CreateWith(rig, options, nullptr);
}

StatusOr<std::unique_ptr<SoftTissueModel>> SoftTissueModel::Create(const FaceRig& rig,
                                                                   const TissueOptions& options,
                                                                   const TissueMaterial& material) {
  return CreateWith(rig, options, &material);
}

StatusOr<std::unique_ptr<SoftTissueModel>> SoftTissueModel::CreateWith(
    const FaceRig& rig, const TissueOptions& options, const TissueMaterial* material) {
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
  m.k_shapes = static_cast<int>(m.deltas.size());
  m.jaw_pivot = rig.jaw.pivot_in_skull;
  m.jaw_axis = rig.jaw.axis_in_skull.normalized();
  m.in_jaw.assign(m.vertex_count, false);
  if (!rig.jaw.region.empty()) {
    for (int v : rig.regions.at(rig.jaw.region)) m.in_jaw[v] = true;
  }
  m.tets = shell.tets;
  m.rest = shell.rest_positions_mm;
  const int n = shell.node_count();

  // Lumped mass; layer-0 nodes are attached to bone, nodes no tetrahedron touches are held.
  m.mass.setZero(n);
  std::vector<bool> used(n, false);
  for (int e = 0; e < m.tets.cols(); ++e) {
    Eigen::Matrix3d dm;
    for (int c = 0; c < 3; ++c) dm.col(c) = m.rest.col(m.tets(c + 1, e)) - m.rest.col(m.tets(0, e));
    const double volume = dm.determinant() / 6.0;
    for (int k = 0; k < 4; ++k) {
      m.mass[m.tets(k, e)] += options.density_kg_per_mm3 * volume / 4.0;
      used[m.tets(k, e)] = true;
    }
  }
  m.free_index.assign(n, -1);
  for (int node = m.vertex_count; node < n; ++node) {
    if (!used[node]) continue;
    m.free_index[node] = static_cast<int>(m.free_nodes.size());
    m.free_nodes.push_back(node);
  }
  model->free_dofs_.resize(3 * m.nf());
  m.mass_dofs.resize(3 * m.nf());
  for (int f = 0; f < m.nf(); ++f) m.mass_dofs.segment<3>(3 * f).setConstant(m.mass[m.free_nodes[f]]);
  m.BuildPattern();

  // Calibrate E so that the neutral face's fundamental frequency is options.fundamental_hz:
  // natural frequencies scale with sqrt(E) at fixed Poisson ratio and mass.
  // The static and dynamic matrices share one sparsity pattern: each solver orders and
  // analyses it once (METIS, the costly symbolic step) and only refactorises numerically.
  m.youngs = 1.0;
  m.Assemble(m.rest, options.poisson_ratio);
  m.static_solver = std::make_unique<Solver>();
  m.static_solver->analyzePattern(m.kff);
  m.dynamic_solver = std::make_unique<Solver>();
  m.dynamic_solver->analyzePattern(m.kff);
  const auto cheeks = rig.regions.find("cheeks");
  if (cheeks != rig.regions.end()) m.cheek_vertices = cheeks->second;
  if (material != nullptr) {
    // The material replaces the calibration: no eigensolve (SetMaterial assembles, factorises).
    FACEDYN_RETURN_IF_ERROR(model->SetMaterial(*material));
    return model;
  }
  m.static_solver->factorize(m.kff);
  if (m.static_solver->info() != Eigen::Success) return InternalError("tissue stiffness is not positive definite");
  Eigen::VectorXd eigenvalues;
  Eigen::MatrixXd modes;
  const int calibrated_mode = m.CheekModeIndex(&eigenvalues, &modes);
  // Until SetReference names the step, calibrate for the largest one the options allow.
  m.unit_eigenvalue = eigenvalues[calibrated_mode];
  m.Calibrate(options, options.max_step_s);
  model->calibrated_mode_ = modes.col(calibrated_mode);
  model->youngs_modulus_kpa_ = m.youngs;
  model->rayleigh_mass_ = m.alpha;
  model->rayleigh_stiffness_ = m.beta;
  m.Assemble(m.rest, options.poisson_ratio);
  m.static_solver->factorize(m.kff);
  if (m.static_solver->info() != Eigen::Success) return InternalError("tissue stiffness is not positive definite");
  return model;
}


StatusOr<std::vector<double>> SoftTissueModel::NaturalFrequenciesHz(int count) const {
  const Impl& m = *impl_;
  FACEDYN_CHECK(count >= 1, "count must be positive");
  Eigen::VectorXd eigenvalues;
  Eigen::MatrixXd modes;
  LowestModes(*m.static_solver, m.kff, m.mass_dofs, count, &eigenvalues, &modes);
  std::vector<double> hz(count);
  for (int i = 0; i < count; ++i) hz[i] = std::sqrt(std::max(0.0, eigenvalues[i])) / (2 * M_PI);
  return hz;
}

StatusOr<ReferenceSummary> SoftTissueModel::SetReference(const Eigen::VectorXd& weights,
                                                         double jaw_angle_rad, double dt_s) {
  return SetReferenceWith(weights, jaw_angle_rad, dt_s, true);
}

StatusOr<ReferenceSummary> SoftTissueModel::SetStaticReference(const Eigen::VectorXd& weights,
                                                               double jaw_angle_rad) {
  return SetReferenceWith(weights, jaw_angle_rad, options_.max_step_s, false);
}

StatusOr<ReferenceSummary> SoftTissueModel::SetReferenceWith(const Eigen::VectorXd& weights,
                                                             double jaw_angle_rad, double dt_s,
                                                             bool dynamics) {
  Impl& m = *impl_;
  FACEDYN_CHECK(weights.size() == m.k_shapes, "one weight per blendshape");
  FACEDYN_CHECK(dt_s > 0, "dt must be positive");
  if (options_.fundamental_hz * dt_s > 0.25) {
    return InvalidArgumentError(
        fmt::format("a tissue step of {} s gives fewer than 4 steps per period of {} Hz", dt_s,
                    options_.fundamental_hz));
  }
  m.has_reference = false;
  m.has_dynamics = false;
  // The material is calibrated for the step actually taken (see "Material" in the header).
  m.Calibrate(options_, dt_s);
  youngs_modulus_kpa_ = m.youngs;
  rayleigh_mass_ = m.alpha;
  rayleigh_stiffness_ = m.beta;
  m.w_ref = weights;
  m.jaw_ref = jaw_angle_rad;
  m.dt = dt_s;
  m.x_ref = m.Targets(weights, jaw_angle_rad);
  ReferenceSummary summary;
  summary.max_target_move_mm = (m.x_ref - m.rest).colwise().norm().maxCoeff();

  // Muscle springs: activation from the expression's displacement at the skin; stiffness
  // proportional to the node's mass, so the stiffening is a frequency, resolution-independent.
  const Eigen::Matrix3Xd skin_delta = m.SkinTargets(weights) - m.rest.rightCols(m.vertex_count);
  m.spring.setZero(m.rest.cols());
  const double muscle_omega = 2 * M_PI * options_.muscle_hz;
  for (int f = 0; f < m.nf(); ++f) {
    const int node = m.free_nodes[f];
    const double activation =
        std::min(1.0, skin_delta.col(node % m.vertex_count).norm() / options_.activation_full_mm);
    m.spring[node] = activation * m.mass[node] * muscle_omega * muscle_omega;
  }
  // Elasticity about the expression's shape (its active rest shape).
  summary.inverted_elements = m.Assemble(m.x_ref, options_.poisson_ratio);
  m.static_solver->factorize(m.kff);
  if (m.static_solver->info() != Eigen::Success) return InternalError("tissue stiffness is not positive definite");
  if (dynamics) {
    // Newmark average acceleration (beta = 1/4, gamma = 1/2): K_eff = K + 2/dt C + 4/dt^2 M.
    m.c_k = 1.0 + 2.0 * m.beta / dt_s;
    m.c_m = 4.0 / (dt_s * dt_s) + 2.0 * m.alpha / dt_s;
    SparseMatrix effective = m.c_k * m.kff;
    for (int d = 0; d < effective.rows(); ++d) effective.coeffRef(d, d) += m.c_m * m.mass_dofs[d];
    m.dynamic_solver->factorize(effective);
    if (m.dynamic_solver->info() != Eigen::Success)
      return InternalError("Newmark matrix is not positive definite");
  }
  m.BuildFields();
  m.has_reference = true;
  m.has_dynamics = dynamics;
  const int dofs = 3 * m.nf();
  m.u.setZero(dofs);
  m.v.setZero(dofs);
  m.a.setZero(dofs);
  m.ku.setZero(dofs);
  m.kv.setZero(dofs);
  m.skin_targets = m.SkinTargets(weights);
  return summary;
}

namespace {
// Coefficients of the forcing fields (Impl's field layout) for one instant.
Eigen::VectorXd ForceCoefficients(const TissueForcing& forcing, int k_shapes, bool dynamic) {
  constexpr int kColW = 3, kColC = 6, kColE = 15;
  Eigen::VectorXd c = Eigen::VectorXd::Zero(kColE + k_shapes + 2);
  const SkullKinematics& k = forcing.kinematics;
  c.head<3>() = k.GravityInSkull() - kGravityInWorld;
  if (!dynamic) return c;
  // Fictitious forces of the skull frame: -m (a0 + alpha x p + w x (w x p)).
  c.head<3>() -= k.origin_acceleration_in_skull;
  c.segment<3>(kColW) = -k.angular_acceleration_in_skull;
  const Eigen::Vector3d& w = k.angular_velocity_in_skull;
  const Eigen::Matrix3d centripetal = w.squaredNorm() * Eigen::Matrix3d::Identity() - w * w.transpose();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) c[kColC + 3 * i + j] = centripetal(i, j);
  }
  // The targets' acceleration: -m d^2/dt^2 (targets).
  if (forcing.weight_accelerations.size() == k_shapes) c.segment(kColE, k_shapes) = -forcing.weight_accelerations;
  const double th = forcing.jaw_angle_rad, th_d = forcing.jaw_angle_velocity, th_dd = forcing.jaw_angle_acceleration;
  c[kColE + k_shapes] = -(std::cos(th) * th_dd - std::sin(th) * th_d * th_d);      // d2/dt2 sin(th)
  c[kColE + k_shapes + 1] = -(std::sin(th) * th_dd + std::cos(th) * th_d * th_d);  // d2/dt2 (1 - cos(th))
  return c;
}
}  // namespace

void SoftTissueModel::Reset(const TissueForcing& forcing) {
  Impl& m = *impl_;
  FACEDYN_CHECK(m.has_dynamics, "SetReference before Reset");
  m.u = m.static_solver->solve(m.fields * ForceCoefficients(forcing, m.k_shapes, false));
  m.v.setZero(3 * m.nf());
  m.ku = m.kff * m.u;
  m.kv.setZero(3 * m.nf());
  // a(0) from the equation of motion at rest: M a = F_dyn - K u (the inertial terms).
  const Eigen::VectorXd c = ForceCoefficients(forcing, m.k_shapes, true) - ForceCoefficients(forcing, m.k_shapes, false);
  m.a = (m.fields * c).cwiseQuotient(m.mass_dofs);
  m.skin_targets = m.SkinTargets(forcing.weights);
}

void SoftTissueModel::Step(const TissueForcing& forcing) {
  Impl& m = *impl_;
  FACEDYN_CHECK(m.has_dynamics, "SetReference before Step");
  const double dt = m.dt;
  Eigen::VectorXd force = m.fields * ForceCoefficients(forcing, m.k_shapes, true);
  const Eigen::Vector3d& w = forcing.kinematics.angular_velocity_in_skull;
  if (w.squaredNorm() > 0) {
    // Coriolis from the current velocity (explicit: tiny next to the other terms for heads).
    for (int f = 0; f < m.nf(); ++f) {
      force.segment<3>(3 * f) -= 2.0 * m.mass[m.free_nodes[f]] * w.cross(Eigen::Vector3d(m.v.segment<3>(3 * f)));
    }
  }
  // Newmark, beta = 1/4, gamma = 1/2 (Bathe, Finite Element Procedures, 9.2.4):
  // K_eff u' = F + M (4/dt^2 u + 4/dt v + a) + C (2/dt u + v), with C = alpha M + beta K.
  const Eigen::VectorXd damp_part = (2 / dt) * m.u + m.v;
  Eigen::VectorXd rhs = force + m.mass_dofs.cwiseProduct((4 / (dt * dt)) * m.u + (4 / dt) * m.v + m.a);
  if (m.alpha > 0) rhs += m.alpha * m.mass_dofs.cwiseProduct(damp_part);
  if (m.beta > 0) rhs += m.beta * ((2 / dt) * m.ku + m.kv);
  const Eigen::VectorXd u_new = m.dynamic_solver->solve(rhs);
  // K u' follows from the solved system itself: c_k K u' + c_m M u' = rhs.
  const Eigen::VectorXd ku_new = (rhs - m.c_m * m.mass_dofs.cwiseProduct(u_new)) / m.c_k;
  m.a = (4 / (dt * dt)) * (u_new - m.u) - (4 / dt) * m.v - m.a;
  const Eigen::VectorXd v_new = (2 / dt) * (u_new - m.u) - m.v;  // = v + dt/2 (a + a')
  m.kv = (2 / dt) * (ku_new - m.ku) - m.kv;
  m.ku = ku_new;
  m.v = v_new;
  m.u = u_new;
  m.skin_targets = m.SkinTargets(forcing.weights);
}

Eigen::Matrix3Xd SoftTissueModel::ReferenceSkin() const {
  const Impl& m = *impl_;
  FACEDYN_CHECK(m.has_reference, "SetReference first");
  return m.x_ref.rightCols(m.vertex_count);
}

Eigen::Matrix3Xd SoftTissueModel::DynamicSkin() const {
  const Impl& m = *impl_;
  FACEDYN_CHECK(m.has_reference, "SetReference first");
  return m.Skin(m.skin_targets, m.u);
}

Eigen::Matrix3Xd SoftTissueModel::QuasistaticSkin(const TissueForcing& forcing) const {
  const Impl& m = *impl_;
  FACEDYN_CHECK(m.has_reference, "SetReference first");
  const Eigen::Vector3d dg = forcing.kinematics.GravityInSkull() - kGravityInWorld;
  const Eigen::VectorXd offset = m.gravity_response * dg;
  return m.SkinTargets(forcing.weights) + Eigen::Map<const Eigen::Matrix3Xd>(offset.data(), 3, m.vertex_count);
}

int SoftTissueModel::blendshape_count() const { return impl_->k_shapes; }
int SoftTissueModel::skin_vertex_count() const { return impl_->vertex_count; }

Eigen::Matrix3Xd SoftTissueModel::NodeTargets(const Eigen::VectorXd& weights,
                                              double jaw_angle_rad) const {
  FACEDYN_CHECK(weights.size() == impl_->k_shapes, "one weight per blendshape");
  return impl_->Targets(weights, jaw_angle_rad);
}

double SoftTissueModel::FleshVolumeMm3(const Eigen::Matrix3Xd& nodes) const {
  const Impl& m = *impl_;
  FACEDYN_CHECK(nodes.cols() == m.rest.cols(), "one position per tissue node");
  double volume = 0;
  for (int e = 0; e < m.tets.cols(); ++e) {
    Eigen::Matrix3d dm;
    for (int c = 0; c < 3; ++c) dm.col(c) = nodes.col(m.tets(c + 1, e)) - nodes.col(m.tets(0, e));
    volume += std::abs(dm.determinant()) / 6.0;
  }
  return volume;
}

StatusOr<HeldExpressionSkin> SoftTissueModel::HeldSkinWithJacobian(
    const Eigen::Vector3d& gravity_change_in_skull, const std::vector<int>& vertices,
    bool with_jacobian) const {
  const Impl& m = *impl_;
  if (!m.has_reference) return FailedPreconditionError("held expression skin: SetReference first");
  if (!gravity_change_in_skull.allFinite())
    return InvalidArgumentError("held expression skin: non-finite gravity");
  std::vector<int> skin_vertices = vertices;
  if (skin_vertices.empty()) {
    skin_vertices.resize(m.vertex_count);
    for (int v = 0; v < m.vertex_count; ++v) skin_vertices[v] = v;
  }
  for (int v : skin_vertices) {
    if (v < 0 || v >= m.vertex_count) {
      return InvalidArgumentError(fmt::format(
          "held expression skin: vertex {} is not on the skin's {} vertices", v, m.vertex_count));
    }
  }
  const int params = m.k_shapes + 1, jaw = m.k_shapes, n = m.rest.cols(), dofs = 3 * m.nf();
  // The equilibrium's displacement from the targets.
  const Eigen::VectorXd u =
      m.static_solver->solve(m.fields.leftCols<3>() * gravity_change_in_skull);

  Eigen::MatrixXd du;  // d(u at the skin)/dp
  if (with_jacobian) {
    // Each parameter's motion of every node's target (Impl::Targets differentiated).
    std::vector<Eigen::Matrix3Xd> target_rate(params, Eigen::Matrix3Xd::Zero(3, n));
    const Eigen::Matrix3d jaw_rotation =
        Eigen::AngleAxisd(m.jaw_ref, m.jaw_axis).toRotationMatrix();
    for (int node = 0; node < n; ++node) {
      const int vertex = node % m.vertex_count;
      const double s = double(node / m.vertex_count) / m.layers;
      if (s > 0) {
        for (int k = 0; k < m.k_shapes; ++k) target_rate[k].col(node) = s * m.deltas[k].col(vertex);
      }
      if (m.in_jaw[vertex] && s < 1) {
        target_rate[jaw].col(node) =
            (1 - s) * m.jaw_axis.cross(jaw_rotation * (m.rest.col(vertex) - m.jaw_pivot));
      }
    }
    // dK/dp u: the elements' rest geometry ...
    const Eigen::Matrix<double, 6, 6> d = UnitElasticity(options_.poisson_ratio);
    Eigen::MatrixXd dk_u = Eigen::MatrixXd::Zero(dofs, params);
    for (int e = 0; e < m.tets.cols(); ++e) {
      Vector12d u_e = Vector12d::Zero();
      for (int i = 0; i < 4; ++i) {
        const int f = m.free_index[m.tets(i, e)];
        if (f >= 0) u_e.segment<3>(3 * i) = u.segment<3>(3 * f);
      }
      if (u_e.isZero(0.0)) continue;
      Eigen::Matrix3d dm;
      for (int c = 0; c < 3; ++c)
        dm.col(c) = m.x_ref.col(m.tets(c + 1, e)) - m.x_ref.col(m.tets(0, e));
      const double scale = m.youngs * (m.tet_scale.size() == m.tets.cols() ? m.tet_scale[e] : 1.0);
      const TetLinearisation element(dm, u_e, d);
      for (int p = 0; p < params; ++p) {
        Eigen::Matrix3d d_dm;
        for (int c = 0; c < 3; ++c)
          d_dm.col(c) = target_rate[p].col(m.tets(c + 1, e)) - target_rate[p].col(m.tets(0, e));
        if (d_dm.isZero(0.0)) continue;
        const Vector12d force = scale * element.ForceDerivative(d_dm, u_e, d);
        for (int i = 0; i < 4; ++i) {
          const int f = m.free_index[m.tets(i, e)];
          if (f >= 0) dk_u.block<3, 1>(3 * f, p) += force.segment<3>(3 * i);
        }
      }
    }
    // ... and the muscle springs' activation (see SetReference).
    const Eigen::Matrix3Xd skin_delta = m.SkinTargets(m.w_ref) - m.rest.rightCols(m.vertex_count);
    const double muscle_omega = 2 * M_PI * options_.muscle_hz;
    for (int f = 0; f < m.nf(); ++f) {
      const int node = m.free_nodes[f];
      const int vertex = node % m.vertex_count;
      const double norm = skin_delta.col(vertex).norm();
      if (norm >= options_.activation_full_mm) continue;  // saturated
      const double per_activation =
          m.mass[node] * muscle_omega * muscle_omega / options_.activation_full_mm;
      for (int k = 0; k < m.k_shapes; ++k) {
        // d|delta|/dw_k; where the delta is zero, the rate as w_k grows from there.
        const double rate = norm > 0 ? skin_delta.col(vertex).dot(m.deltas[k].col(vertex)) / norm
                                     : m.deltas[k].col(vertex).norm();
        if (rate != 0.0) dk_u.block<3, 1>(3 * f, k) += per_activation * rate * u.segment<3>(3 * f);
      }
    }
    du = -m.static_solver->solve(dk_u);
  }

  HeldExpressionSkin result;
  const int count = static_cast<int>(skin_vertices.size());
  result.skin_mm.resize(3 * count);
  if (with_jacobian) result.jacobian.setZero(3 * count, params);
  const Eigen::Matrix3Xd skin_targets = m.SkinTargets(m.w_ref);
  for (int i = 0; i < count; ++i) {
    const int v = skin_vertices[i];
    result.skin_mm.segment<3>(3 * i) = skin_targets.col(v);
    if (with_jacobian) {
      for (int k = 0; k < m.k_shapes; ++k)
        result.jacobian.block<3, 1>(3 * i, k) = m.deltas[k].col(v);
    }
    const int f = m.free_index[m.layers * m.vertex_count + v];
    if (f < 0) continue;
    result.skin_mm.segment<3>(3 * i) += u.segment<3>(3 * f);
    if (with_jacobian) result.jacobian.middleRows<3>(3 * i) += du.middleRows<3>(3 * f);
  }
  Eigen::Matrix3Xd nodes = m.x_ref;
  for (int f = 0; f < m.nf(); ++f) nodes.col(m.free_nodes[f]) += u.segment<3>(3 * f);
  result.flesh_volume_mm3 = FleshVolumeMm3(nodes);
  return result;
}

Status SoftTissueModel::SetMaterial(const TissueMaterial& material) {
  Impl& m = *impl_;
  if (!(material.youngs_modulus_kpa > 0) || !std::isfinite(material.youngs_modulus_kpa)) {
    return InvalidArgumentError(
        fmt::format("tissue material: youngs_modulus_kpa must be positive, got {}", material.youngs_modulus_kpa));
  }
  if (!(material.rayleigh_mass >= 0) || !(material.rayleigh_stiffness >= 0) ||
      !std::isfinite(material.rayleigh_mass) || !std::isfinite(material.rayleigh_stiffness)) {
    return InvalidArgumentError(fmt::format("tissue material: Rayleigh damping must be >= 0, got alpha {} beta {}",
                                            material.rayleigh_mass, material.rayleigh_stiffness));
  }
  if (material.tet_stiffness_scale.size() != 0) {
    if (material.tet_stiffness_scale.size() != m.tets.cols()) {
      return InvalidArgumentError(fmt::format("tissue material: {} stiffness scales for {} tetrahedra",
                                              material.tet_stiffness_scale.size(), m.tets.cols()));
    }
    if (!(material.tet_stiffness_scale.array() > 0).all() || !material.tet_stiffness_scale.allFinite()) {
      return InvalidArgumentError("tissue material: every tetrahedron's stiffness scale must be positive");
    }
  }
  m.explicit_material = true;
  m.youngs = material.youngs_modulus_kpa;
  m.tet_scale = material.tet_stiffness_scale;
  m.alpha = material.rayleigh_mass;
  m.beta = material.rayleigh_stiffness;
  youngs_modulus_kpa_ = m.youngs;
  rayleigh_mass_ = m.alpha;
  rayleigh_stiffness_ = m.beta;
  // Back to the neutral face, unstressed by any expression, until SetReference.
  m.has_reference = false;
  m.has_dynamics = false;
  m.spring.resize(0);
  m.Assemble(m.rest, options_.poisson_ratio);
  m.static_solver->factorize(m.kff);
  if (m.static_solver->info() != Eigen::Success) return InternalError("tissue stiffness is not positive definite");
  return Status::Ok();
}

TissueMaterial SoftTissueModel::material() const {
  const Impl& m = *impl_;
  TissueMaterial material;
  material.youngs_modulus_kpa = m.youngs;
  material.tet_stiffness_scale = m.tet_scale;
  material.rayleigh_mass = m.alpha;
  material.rayleigh_stiffness = m.beta;
  return material;
}

StatusOr<DampedMode> SoftTissueModel::CheekMode() const {
  const Impl& m = *impl_;
  Eigen::VectorXd eigenvalues;
  Eigen::MatrixXd modes;
  const int index = m.CheekModeIndex(&eigenvalues, &modes);
  if (!(eigenvalues[index] > 0)) return InternalError("the tissue's cheek mode has no positive stiffness");
  const double omega = std::sqrt(eigenvalues[index]);
  return DampedMode{omega, m.alpha / (2 * omega) + m.beta * omega / 2};
}

StatusOr<TissueSystemParts> SoftTissueModel::SystemParts(const Eigen::VectorXi& tet_group, int group_count) const {
  const Impl& m = *impl_;
  if (!m.has_reference) return FailedPreconditionError("tissue system parts: SetReference first");
  if (tet_group.size() != m.tets.cols() || group_count < 1) {
    return InvalidArgumentError(
        fmt::format("tissue system parts: {} group labels for {} tetrahedra", tet_group.size(), m.tets.cols()));
  }
  if (tet_group.minCoeff() < 0 || tet_group.maxCoeff() >= group_count) {
    return InvalidArgumentError(fmt::format("tissue system parts: group labels must be in [0, {})", group_count));
  }
  TissueSystemParts parts;
  parts.stiffness_by_group.assign(group_count, m.kff);
  for (SparseMatrix& k : parts.stiffness_by_group) std::fill(k.valuePtr(), k.valuePtr() + k.nonZeros(), 0.0);
  for (int e = 0; e < m.tets.cols(); ++e) {
    Eigen::Matrix3d dm;
    for (int c = 0; c < 3; ++c) dm.col(c) = m.x_ref.col(m.tets(c + 1, e)) - m.x_ref.col(m.tets(0, e));
    const double scale = m.tet_scale.size() == m.tets.cols() ? m.tet_scale[e] : 1.0;
    const Matrix12d k = m.youngs * scale * UnitTetStiffness(dm, options_.poisson_ratio);
    const int* map = m.entry_map.data() + size_t(e) * 144;
    double* values = parts.stiffness_by_group[tet_group[e]].valuePtr();
    for (int i = 0; i < 144; ++i) {
      if (map[i] >= 0) values[map[i]] += k(i / 12, i % 12);
    }
  }
  parts.spring_dofs.setZero(3 * m.nf());
  if (m.spring.size() == m.rest.cols()) {
    for (int f = 0; f < m.nf(); ++f) parts.spring_dofs.segment<3>(3 * f).setConstant(m.spring[m.free_nodes[f]]);
  }
  parts.mass_dofs = m.mass_dofs;
  parts.load_fields = m.fields.leftCols<6>();
  parts.skin_dof.assign(m.vertex_count, -1);
  for (int i = 0; i < m.vertex_count; ++i) {
    const int f = m.free_index[m.layers * m.vertex_count + i];
    if (f >= 0) parts.skin_dof[i] = 3 * f;
  }
  parts.rayleigh_mass = m.alpha;
  parts.rayleigh_stiffness = m.beta;
  return parts;
}

double SoftTissueModel::Energy() const {
  const Impl& m = *impl_;
  return 0.5 * m.v.dot(m.mass_dofs.cwiseProduct(m.v)) + 0.5 * m.u.dot(m.kff * m.u);
}

void SoftTissueModel::SetVelocity(const Eigen::VectorXd& velocity) {
  Impl& m = *impl_;
  FACEDYN_CHECK(velocity.size() == m.v.size(), "one velocity per free DOF");
  m.v = velocity;
  m.kv = m.kff * m.v;
  // Keep the acceleration consistent with the unforced equation of motion.
  m.a = -(m.ku + m.alpha * m.mass_dofs.cwiseProduct(m.v) + m.beta * m.kv).cwiseQuotient(m.mass_dofs);
}

}  // namespace facedyn::physics
