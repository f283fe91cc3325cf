// Dense fit: per frame, the FaceRig's mesh posed by the skull transform, with expression
// blendshape weights and a smooth corrective deformation that follows the markers (Ceres).
//
// Model, in the skull frame (mm): x(v) = neutral(v) + sum_k w_k B_k(v) + sum_n phi_vn u_n, with
// w the blendshape weights (bounded to [0, 1]) and u_n the displacements of N control nodes
// spread over the mesh by farthest-point sampling; phi_vn are normalised Gaussian radial basis
// weights (sigma = the mean nearest-node spacing, cut at 3 sigma, a partition of unity so a
// uniform displacement is reproduced exactly). World positions are world_from_skull * x.
//
// Energy (least squares, Ceres):
//   markers:    sum_m c_m / sigma_m^2 |marker_m(x) - skull_from_world p_m|^2, c_m the tracking
//               confidence, sigma_m = marker_noise_mm;
//   smoothness: lambda_smooth sum_{n~n'} |u_n - u_n'|^2 / |r_n - r_n'|^2 over node pairs within
//               2.5 sigma — a membrane energy on the corrective, so it bends smoothly between
//               markers instead of putting bumps at them;
//   magnitude:  lambda_magnitude sum_n |u_n|^2 — where no marker constrains the corrective it
//               decays to the blendshape fit instead of inventing motion;
//   temporal:   lambda_temporal |w - w_prev|^2 — warm start and tie-breaking between
//               blendshapes that explain the markers equally well.
// The energy is quadratic but for the [0, 1] penalty on w (see the .cc), so by default it is
// minimised directly (DenseFitSolver::kNormalEquations): the node block of the normal
// equations is the same N x N matrix for x, y and z, so it is factored once per frame and w
// is solved on the K x K Schur complement, with the bound penalty's active set iterated to
// its fixed point: the exact minimiser of the same energy, several times faster than building
// and solving it through Ceres (kCeres, kept as the reference the tests compare with, and the
// fallback when the active set does not settle). Each frame is warm-started from the previous
// one. Regularisation is weak against the marker term (markers
// are fitted to about their noise), so real jiggle seen by the markers is kept, and the
// membrane and magnitude terms decide what happens between and beyond them.
#pragma once

#include <ceres/cost_function.h>

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/rigid3.h"
#include "core/status.h"
#include "reconstruct/tracking.h"

namespace facedyn::reconstruct {

enum class DenseFitSolver { kNormalEquations, kCeres };

struct DenseFitOptions {
  DenseFitSolver solver = DenseFitSolver::kNormalEquations;
  int node_count = 300;
  double marker_noise_mm = 0.1;
  double lambda_smooth = 1.0;
  double lambda_magnitude = 0.01;
  double lambda_temporal = 0.1;
  int max_iterations = 10;
  Status Check() const;
};

struct DenseFitSummary {
  bool converged = false;
  int iterations = 0;
  double initial_cost = 0.0;
  double final_cost = 0.0;
  int markers_used = 0;
  double marker_rms_mm = 0.0;  // fitted markers against the observations
  std::string message;         // Ceres' termination message
};

class DenseFitter {
 public:
  // Precomputes the nodes, the RBF weights and the markers' rows. Check status().
  DenseFitter(const FaceRig& rig, const DenseFitOptions& options);
  Status status() const { return status_; }

  // Fits one frame (markers in world from the tracker, and the skull pose), warm-started from
  // the previous call. Returns world positions (3 x V).
  StatusOr<Eigen::Matrix3Xd> Fit(const TrackedFrame& frame, const Rigid3& world_from_skull,
                                 DenseFitSummary* summary = nullptr);

  const Eigen::VectorXd& blendshape_weights() const { return weights_; }
  int node_count() const { return static_cast<int>(node_vertices_.size()); }
  // Skull-frame positions for given weights and node displacements (3 x N).
  Eigen::Matrix3Xd Evaluate(const Eigen::VectorXd& weights,
                            const Eigen::Matrix3Xd& node_displacements) const;
  void Reset();

 private:
  // The markers used in a frame: index, squared residual scale c_m / sigma^2, and the
  // marker's offset from its target at w = 0, u = 0, in the skull frame.
  struct UsedMarker {
    int marker;
    double weight;
    Eigen::Vector3d offset;
  };
  // Solves for weights_ and nodes_ by the normal equations (see above); false when the active
  // set did not settle or the node block is not positive definite (the caller falls back to
  // Ceres), with the iterations taken.
  bool SolveNormalEquations(const std::vector<UsedMarker>& used,
                            const Eigen::VectorXd& previous_weights, int* iterations);
  bool SolveCeres(const std::vector<UsedMarker>& used, const Eigen::VectorXd& previous_weights,
                  DenseFitSummary* summary);
  // The energy at (weights_, nodes_), as Ceres counts it (half the sum of squared residuals).
  double Energy(const std::vector<UsedMarker>& used, const Eigen::VectorXd& previous_weights) const;

  const FaceRig& rig_;
  DenseFitOptions options_;
  Status status_;
  std::vector<int> node_vertices_;
  Eigen::SparseMatrix<double, Eigen::RowMajor> phi_;  // V x N
  std::vector<std::pair<int, int>> node_pairs_;
  std::vector<double> node_pair_distance_mm_;
  // Per marker: neutral position, 3 x K blendshape rows, and (node, coefficient) list.
  std::vector<Eigen::Vector3d> marker_neutral_;
  std::vector<Eigen::Matrix3Xd> marker_blendshapes_;
  std::vector<std::vector<std::pair<int, double>>> marker_nodes_;
  Eigen::VectorXd weights_;
  Eigen::Matrix3Xd nodes_;  // current u
  // lambda_smooth's membrane and lambda_magnitude on the node displacements, as the N x N
  // matrix each coordinate shares (the regularisers' part of the node block).
  Eigen::MatrixXd node_regulariser_;
};

// The marker residual as a Ceres cost function with parameter blocks (w [K], u_n1 [3], ...):
// r = s (base + Bm w + sum_l c_l u_l - target). Exposed for the gradient test.
ceres::CostFunction* NewMarkerFitCost(const Eigen::Vector3d& base,
                                      const Eigen::Matrix3Xd& blendshapes,
                                      const std::vector<double>& coefficients,
                                      const Eigen::Vector3d& target, double scale);

}  // namespace facedyn::reconstruct
