#include "reconstruct/dense_fit.h"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>

namespace facedyn::reconstruct {

class MarkerFitCost : public ceres::CostFunction {
 public:
  MarkerFitCost(const Eigen::Vector3d& base, const Eigen::Matrix3Xd& blendshapes,
                std::vector<double> coefficients, const Eigen::Vector3d& target, double scale)
      : base_(base),
        blendshapes_(blendshapes),
        coefficients_(std::move(coefficients)),
        target_(target),
        scale_(scale) {
    set_num_residuals(3);
    mutable_parameter_block_sizes()->push_back(static_cast<int>(blendshapes.cols()));
    for (size_t l = 0; l < coefficients_.size(); ++l) mutable_parameter_block_sizes()->push_back(3);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int k = static_cast<int>(blendshapes_.cols());
    Eigen::Vector3d x = base_ - target_;
    if (k > 0) x += blendshapes_ * Eigen::Map<const Eigen::VectorXd>(parameters[0], k);
    for (size_t l = 0; l < coefficients_.size(); ++l) {
      x += coefficients_[l] * Eigen::Map<const Eigen::Vector3d>(parameters[1 + l]);
    }
    Eigen::Map<Eigen::Vector3d> r(residuals);
    r = scale_ * x;
    if (jacobians) {
      if (jacobians[0] && k > 0) {
        Eigen::Map<Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor>> j(jacobians[0], 3, k);
        j = scale_ * blendshapes_;
      }
      for (size_t l = 0; l < coefficients_.size(); ++l) {
        if (!jacobians[1 + l]) continue;
        Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> j(jacobians[1 + l]);
        j = scale_ * coefficients_[l] * Eigen::Matrix3d::Identity();
      }
    }
    return true;
  }

 private:
  Eigen::Vector3d base_;
  Eigen::Matrix3Xd blendshapes_;
  std::vector<double> coefficients_;
  Eigen::Vector3d target_;
  double scale_;
};

ceres::CostFunction* NewMarkerFitCost(const Eigen::Vector3d& base,
                                      const Eigen::Matrix3Xd& blendshapes,
                                      const std::vector<double>& coefficients,
                                      const Eigen::Vector3d& target, double scale) {
  return new MarkerFitCost(base, blendshapes, coefficients, target, scale);
}

namespace {

struct DifferenceCost {
  explicit DifferenceCost(double scale) : scale_(scale) {}
  template <typename T>
  bool operator()(const T* a, const T* b, T* residual) const {
    for (int i = 0; i < 3; ++i) residual[i] = T(scale_) * (a[i] - b[i]);
    return true;
  }
  double scale_;
};

struct MagnitudeCost {
  explicit MagnitudeCost(double scale) : scale_(scale) {}
  template <typename T>
  bool operator()(const T* a, T* residual) const {
    for (int i = 0; i < 3; ++i) residual[i] = T(scale_) * a[i];
    return true;
  }
  double scale_;
};

// Residual scale * (w - w_prev), K residuals.
class TemporalCost : public ceres::CostFunction {
 public:
  TemporalCost(const Eigen::VectorXd& previous, double scale) : previous_(previous), scale_(scale) {
    set_num_residuals(static_cast<int>(previous.size()));
    mutable_parameter_block_sizes()->push_back(static_cast<int>(previous.size()));
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int k = static_cast<int>(previous_.size());
    for (int i = 0; i < k; ++i) residuals[i] = scale_ * (parameters[0][i] - previous_[i]);
    if (jacobians && jacobians[0]) {
      std::fill(jacobians[0], jacobians[0] + k * k, 0.0);
      for (int i = 0; i < k; ++i) jacobians[0][i * k + i] = scale_;
    }
    return true;
  }

 private:
  Eigen::VectorXd previous_;
  double scale_;
};

// scale * (min(w_k, 0) + max(w_k - 1, 0)) per weight: zero inside [0, 1].
class BoundPenaltyCost : public ceres::CostFunction {
 public:
  BoundPenaltyCost(int size, double scale) : size_(size), scale_(scale) {
    set_num_residuals(size);
    mutable_parameter_block_sizes()->push_back(size);
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    for (int i = 0; i < size_; ++i) {
      const double w = parameters[0][i];
      const double outside = w < 0.0 ? w : (w > 1.0 ? w - 1.0 : 0.0);
      residuals[i] = scale_ * outside;
      if (jacobians && jacobians[0]) {
        for (int j = 0; j < size_; ++j) {
          jacobians[0][i * size_ + j] = (i == j && outside != 0.0) ? scale_ : 0.0;
        }
      }
    }
    return true;
  }

 private:
  int size_;
  double scale_;
};

std::vector<int> FarthestPoints(const Eigen::Matrix3Xd& points, int count) {
  const int n = static_cast<int>(points.cols());
  count = std::min(count, n);
  std::vector<int> chosen;
  Eigen::VectorXd distance = Eigen::VectorXd::Constant(n, std::numeric_limits<double>::infinity());
  // Start from the point nearest the centroid (deterministic).
  Eigen::Index first;
  (points.colwise() - points.rowwise().mean()).colwise().squaredNorm().minCoeff(&first);
  int next = static_cast<int>(first);
  for (int k = 0; k < count; ++k) {
    chosen.push_back(next);
    distance = distance.cwiseMin(
        (points.colwise() - points.col(next)).colwise().squaredNorm().transpose());
    Eigen::Index far;
    distance.maxCoeff(&far);
    next = static_cast<int>(far);
  }
  return chosen;
}

}  // namespace

Status DenseFitOptions::Check() const {
  if (node_count < 4) return InvalidArgumentError("node_count must be >= 4");
  if (!(marker_noise_mm > 0)) return InvalidArgumentError("marker_noise_mm must be > 0");
  if (!(lambda_smooth >= 0) || !(lambda_magnitude >= 0) || !(lambda_temporal >= 0)) {
    return InvalidArgumentError("regularisation weights must be >= 0");
  }
  if (max_iterations < 1) return InvalidArgumentError("max_iterations must be >= 1");
  return Status::Ok();
}

DenseFitter::DenseFitter(const FaceRig& rig, const DenseFitOptions& options)
    : rig_(rig), options_(options) {
  status_ = options.Check().WithContext("dense fit options");
  if (!status_.ok()) return;
  if (rig.markers.empty()) {
    status_ = FailedPreconditionError("the face rig has no markers to fit");
    return;
  }
  const Eigen::Matrix3Xd& rest = rig.neutral.positions_mm;
  const int v_count = static_cast<int>(rest.cols());
  node_vertices_ = FarthestPoints(rest, options.node_count);
  const int n = static_cast<int>(node_vertices_.size());
  Eigen::Matrix3Xd node_rest(3, n);
  for (int k = 0; k < n; ++k) node_rest.col(k) = rest.col(node_vertices_[k]);
  double spacing = 0.0;
  for (int k = 0; k < n; ++k) {
    double nearest = std::numeric_limits<double>::infinity();
    for (int l = 0; l < n; ++l) {
      if (l != k) nearest = std::min(nearest, (node_rest.col(k) - node_rest.col(l)).norm());
    }
    spacing += nearest / n;
  }
  const double sigma = spacing;
  std::vector<Eigen::Triplet<double>> triplets;
  for (int v = 0; v < v_count; ++v) {
    const Eigen::VectorXd d2 = (node_rest.colwise() - rest.col(v)).colwise().squaredNorm();
    std::vector<std::pair<int, double>> entries;
    double total = 0.0;
    for (int k = 0; k < n; ++k) {
      if (d2[k] > 9.0 * sigma * sigma) continue;
      const double value = std::exp(-0.5 * d2[k] / (sigma * sigma));
      entries.emplace_back(k, value);
      total += value;
    }
    if (entries.empty()) {  // farther than 3 sigma from every node: the nearest one
      Eigen::Index k;
      d2.minCoeff(&k);
      entries.emplace_back(static_cast<int>(k), 1.0);
      total = 1.0;
    }
    for (const auto& [k, value] : entries) triplets.emplace_back(v, k, value / total);
  }
  phi_.resize(v_count, n);
  phi_.setFromTriplets(triplets.begin(), triplets.end());
  for (int k = 0; k < n; ++k) {
    for (int l = k + 1; l < n; ++l) {
      const double d = (node_rest.col(k) - node_rest.col(l)).norm();
      if (d < 2.5 * sigma) {
        node_pairs_.emplace_back(k, l);
        node_pair_distance_mm_.push_back(d);
      }
    }
  }
  node_regulariser_ = options.lambda_magnitude * Eigen::MatrixXd::Identity(n, n);
  for (size_t p = 0; p < node_pairs_.size(); ++p) {
    const auto [k, l] = node_pairs_[p];
    const double stiffness =
        options.lambda_smooth / (node_pair_distance_mm_[p] * node_pair_distance_mm_[p]);
    node_regulariser_(k, k) += stiffness;
    node_regulariser_(l, l) += stiffness;
    node_regulariser_(k, l) -= stiffness;
    node_regulariser_(l, k) -= stiffness;
  }
  const int k_count = static_cast<int>(rig.blendshape_deltas_mm.size());
  for (const Marker& marker : rig.markers) {
    marker_neutral_.push_back(marker.point.Evaluate(rest));
    Eigen::Matrix3Xd b(3, k_count);
    for (int k = 0; k < k_count; ++k) b.col(k) = marker.point.Evaluate(rig.blendshape_deltas_mm[k]);
    marker_blendshapes_.push_back(b);
    std::map<int, double> coefficients;
    for (int c = 0; c < 3; ++c) {
      if (marker.point.weights[c] == 0.0) continue;
      for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(phi_,
                                                                          marker.point.vertices[c]);
           it; ++it) {
        coefficients[static_cast<int>(it.col())] += marker.point.weights[c] * it.value();
      }
    }
    marker_nodes_.emplace_back(coefficients.begin(), coefficients.end());
  }
  Reset();
}

void DenseFitter::Reset() {
  weights_ = Eigen::VectorXd::Zero(rig_.blendshape_deltas_mm.size());
  nodes_ = Eigen::Matrix3Xd::Zero(3, node_vertices_.size());
}

Eigen::Matrix3Xd DenseFitter::Evaluate(const Eigen::VectorXd& weights,
                                       const Eigen::Matrix3Xd& node_displacements) const {
  Eigen::Matrix3Xd x = rig_.neutral.positions_mm;
  for (int k = 0; k < weights.size(); ++k) {
    if (weights[k] != 0.0) x += weights[k] * rig_.blendshape_deltas_mm[k];
  }
  x += (phi_ * node_displacements.transpose()).transpose();
  return x;
}

StatusOr<Eigen::Matrix3Xd> DenseFitter::Fit(const TrackedFrame& frame,
                                            const Rigid3& world_from_skull,
                                            DenseFitSummary* summary_out) {
  FACEDYN_RETURN_IF_ERROR(status_);
  DenseFitSummary local;
  DenseFitSummary& summary = summary_out ? *summary_out : local;
  summary = DenseFitSummary();
  const int m_count = static_cast<int>(rig_.markers.size());
  if (frame.positions_in_world.cols() != m_count ||
      static_cast<int>(frame.states.size()) != m_count ||
      static_cast<int>(frame.confidence.size()) != m_count) {
    return InvalidArgumentError("tracked frame has " +
                                std::to_string(frame.positions_in_world.cols()) +
                                " markers, the rig " + std::to_string(m_count));
  }
  const Rigid3 skull_from_world = world_from_skull.Inverse();
  const Eigen::VectorXd previous_weights = weights_;
  std::vector<UsedMarker> used;
  for (int m = 0; m < m_count; ++m) {
    if (frame.states[m] == MarkerState::kMissing || !(frame.confidence[m] > 0)) continue;
    const Eigen::Vector3d target =
        skull_from_world * Eigen::Vector3d(frame.positions_in_world.col(m));
    used.push_back({m, frame.confidence[m] / (options_.marker_noise_mm * options_.marker_noise_mm),
                    marker_neutral_[m] - target});
  }
  if (used.size() < 3) {
    return FailedPreconditionError("only " + std::to_string(used.size()) +
                                   " markers to fit the mesh to");
  }
  summary.markers_used = static_cast<int>(used.size());
  const Eigen::Matrix3Xd previous_nodes = nodes_;
  bool solved = false;
  if (options_.solver == DenseFitSolver::kNormalEquations) {
    summary.initial_cost = Energy(used, previous_weights);
    solved = SolveNormalEquations(used, previous_weights, &summary.iterations);
    if (solved) {
      summary.converged = true;
      summary.final_cost = Energy(used, previous_weights);
      summary.message = "normal equations, bound active set settled";
    } else {
      weights_ = previous_weights;  // the warm start for Ceres
      nodes_ = previous_nodes;
    }
  }
  if (!solved && !SolveCeres(used, previous_weights, &summary)) {
    weights_ = previous_weights;
    nodes_ = previous_nodes;
    return InternalError("dense fit failed: " + summary.message);
  }
  const Eigen::Matrix3Xd in_skull = Evaluate(weights_, nodes_);
  double sq = 0.0;
  for (const UsedMarker& u : used) {
    sq += (rig_.markers[u.marker].point.Evaluate(in_skull) - marker_neutral_[u.marker] + u.offset)
              .squaredNorm();
  }
  summary.marker_rms_mm = std::sqrt(sq / used.size());
  return world_from_skull.Apply(in_skull);
}

namespace {
// The [0, 1] bound on w as a stiff one-sided penalty, residual kBoundPenalty * (distance
// outside): see SolveCeres.
constexpr double kBoundPenalty = 100.0;
}  // namespace

double DenseFitter::Energy(const std::vector<UsedMarker>& used,
                           const Eigen::VectorXd& previous_weights) const {
  double energy = 0.0;
  for (const UsedMarker& u : used) {
    Eigen::Vector3d r = u.offset + marker_blendshapes_[u.marker] * weights_;
    for (const auto& [node, c] : marker_nodes_[u.marker]) r += c * nodes_.col(node);
    energy += u.weight * r.squaredNorm();
  }
  for (size_t p = 0; p < node_pairs_.size(); ++p) {
    energy += options_.lambda_smooth *
              (nodes_.col(node_pairs_[p].first) - nodes_.col(node_pairs_[p].second)).squaredNorm() /
              (node_pair_distance_mm_[p] * node_pair_distance_mm_[p]);
  }
  energy += options_.lambda_magnitude * nodes_.squaredNorm();
  energy += options_.lambda_temporal * (weights_ - previous_weights).squaredNorm();
  for (int k = 0; k < weights_.size(); ++k) {
    const double outside = std::min(weights_[k], 0.0) + std::max(weights_[k] - 1.0, 0.0);
    energy += kBoundPenalty * kBoundPenalty * outside * outside;
  }
  return 0.5 * energy;
}

bool DenseFitter::SolveNormalEquations(const std::vector<UsedMarker>& used,
                                       const Eigen::VectorXd& previous_weights, int* iterations) {
  // Unknowns: w (K) and u (N per coordinate). E = sum of squared residuals; its normal
  // equations split as [S (x) I3, U; U^T, A_ww] with S = node_regulariser_ + the markers'
  // c c^T (the same for x, y and z, since a node moves a marker by c_l u_l in every coordinate).
  const int n = static_cast<int>(node_vertices_.size());
  const int k_count = static_cast<int>(weights_.size());
  Eigen::MatrixXd s = node_regulariser_;
  std::array<Eigen::MatrixXd, 3> u_w;  // U per coordinate: N x K
  for (Eigen::MatrixXd& block : u_w) block = Eigen::MatrixXd::Zero(n, k_count);
  Eigen::MatrixXd a_ww = options_.lambda_temporal * Eigen::MatrixXd::Identity(k_count, k_count);
  Eigen::Matrix3Xd b_u = Eigen::Matrix3Xd::Zero(3, n);
  Eigen::VectorXd b_w = options_.lambda_temporal * previous_weights;
  for (const UsedMarker& u : used) {
    const Eigen::Matrix3Xd& blendshapes = marker_blendshapes_[u.marker];
    const auto& coefficients = marker_nodes_[u.marker];
    for (const auto& [node_i, c_i] : coefficients) {
      for (const auto& [node_j, c_j] : coefficients) s(node_i, node_j) += u.weight * c_i * c_j;
      for (int d = 0; d < 3; ++d) u_w[d].row(node_i) += (u.weight * c_i) * blendshapes.row(d);
      b_u.col(node_i) -= (u.weight * c_i) * u.offset;
    }
    if (k_count > 0) {
      a_ww.noalias() += u.weight * blendshapes.transpose() * blendshapes;
      b_w.noalias() -= u.weight * blendshapes.transpose() * u.offset;
    }
  }
  const Eigen::LLT<Eigen::MatrixXd> factor(s);
  if (factor.info() != Eigen::Success) return false;
  const Eigen::MatrixXd z = factor.solve(Eigen::MatrixXd(b_u.transpose()));  // N x 3
  std::array<Eigen::MatrixXd, 3> solved_u_w;
  Eigen::MatrixXd schur = a_ww;
  Eigen::VectorXd rhs = b_w;
  for (int d = 0; d < 3; ++d) {
    solved_u_w[d] = factor.solve(u_w[d]);
    schur.noalias() -= u_w[d].transpose() * solved_u_w[d];
    rhs.noalias() -= u_w[d].transpose() * z.col(d);
  }
  // The bound penalty is active on a weight exactly when that weight lies outside [0, 1]:
  // iterate the active set to its fixed point (semi-smooth Newton on a convex piecewise
  // quadratic; a few iterations from the unconstrained solution).
  std::vector<int> active(k_count, 0), next(k_count, 0);  // -1 below 0, +1 above 1
  constexpr double kPenalty = kBoundPenalty * kBoundPenalty;
  Eigen::VectorXd w = Eigen::VectorXd::Zero(k_count);
  bool settled = k_count == 0;
  for (*iterations = 1; !settled && *iterations <= 30; ++*iterations) {
    Eigen::MatrixXd h = schur;
    Eigen::VectorXd g = rhs;
    for (int k = 0; k < k_count; ++k) {
      if (active[k] != 0) {
        h(k, k) += kPenalty;
        g[k] += active[k] > 0 ? kPenalty : 0.0;
      }
    }
    const Eigen::LDLT<Eigen::MatrixXd> solver(h);
    if (solver.info() != Eigen::Success) return false;
    w = solver.solve(g);
    if (!w.allFinite()) return false;
    for (int k = 0; k < k_count; ++k) next[k] = w[k] < 0.0 ? -1 : (w[k] > 1.0 ? 1 : 0);
    settled = next == active;
    active.swap(next);
  }
  if (!settled) return false;
  weights_ = w;
  for (int d = 0; d < 3; ++d) {
    nodes_.row(d) = (z.col(d) - solved_u_w[d] * w).transpose();
  }
  return nodes_.allFinite();
}

bool DenseFitter::SolveCeres(const std::vector<UsedMarker>& used,
                             const Eigen::VectorXd& previous_weights, DenseFitSummary* summary) {
  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  const int k_count = static_cast<int>(weights_.size());
  std::vector<double*> node_blocks(node_vertices_.size());
  for (size_t n = 0; n < node_vertices_.size(); ++n) node_blocks[n] = nodes_.col(n).data();
  for (const UsedMarker& u : used) {
    std::vector<double*> blocks = {weights_.data()};
    std::vector<double> coefficients;
    for (const auto& [node, c] : marker_nodes_[u.marker]) {
      blocks.push_back(node_blocks[node]);
      coefficients.push_back(c);
    }
    // base - target = offset: the cost's target is the neutral position less the offset.
    problem.AddResidualBlock(
        NewMarkerFitCost(marker_neutral_[u.marker], marker_blendshapes_[u.marker], coefficients,
                         marker_neutral_[u.marker] - u.offset, std::sqrt(u.weight)),
        nullptr, blocks);
  }
  for (size_t p = 0; p < node_pairs_.size(); ++p) {
    const double scale = std::sqrt(options_.lambda_smooth) / node_pair_distance_mm_[p];
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<DifferenceCost, 3, 3, 3>(new DifferenceCost(scale)),
        nullptr, node_blocks[node_pairs_[p].first], node_blocks[node_pairs_[p].second]);
  }
  for (double* block : node_blocks) {
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<MagnitudeCost, 3, 3>(
                                 new MagnitudeCost(std::sqrt(options_.lambda_magnitude))),
                             nullptr, block);
  }
  if (k_count > 0) {
    problem.AddResidualBlock(
        new TemporalCost(previous_weights, std::sqrt(options_.lambda_temporal)), nullptr,
        weights_.data());
    // [0, 1] as a stiff one-sided penalty rather than Ceres bounds: with a bound active the
    // projected step vanishes and the solver stops short of the constrained optimum.
    problem.AddResidualBlock(new BoundPenaltyCost(k_count, kBoundPenalty), nullptr,
                             weights_.data());
  }
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  solver_options.max_num_iterations = options_.max_iterations;
  solver_options.num_threads = 1;
  solver_options.function_tolerance = 1e-10;
  // The energy is quadratic (only the bounds on w make it not quite linear least squares):
  // start with a trust region wide enough for the Gauss-Newton step, which then solves it in
  // one or two iterations instead of creeping towards it.
  solver_options.initial_trust_region_radius = 1e12;
  solver_options.max_trust_region_radius = 1e16;
  ceres::Solver::Summary solver_summary;
  ceres::Solve(solver_options, &problem, &solver_summary);
  summary->converged = solver_summary.termination_type == ceres::CONVERGENCE;
  summary->iterations = static_cast<int>(solver_summary.iterations.size());
  summary->initial_cost = solver_summary.initial_cost;
  summary->final_cost = solver_summary.final_cost;
  summary->message = solver_summary.message;
  return solver_summary.IsSolutionUsable();
}

}  // namespace facedyn::reconstruct
