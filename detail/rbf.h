// Scattered-data interpolation with the biharmonic radial basis phi(r) = r plus a polynomial
// (Bickel et al. 2008, section 4.2; Masquerade keeps this kernel), and greedy selection of the
// training frames (Bickel et al. 2008; Bermano et al. 2014; Masquerade: 80 of 320 frames).
//
// For centres f_1..f_N (D-dimensional) and values y_j (K-dimensional rows) the interpolant is
//   s(f) = sum_j a_j |f - f_j| + b_0 + b^T f      (b only with the linear part)
// with [Phi P; P^T 0] [a; b] = [Y; 0], Phi_ij = |f_i - f_j|, P the rows [1 f_j^T]. The kernel is
// conditionally positive definite of order 1, so with the constant part alone the system is
// non-singular for any distinct centres; the linear part needs the centres to span D
// dimensions affinely (>= D + 1 of them), so kAuto uses it only with at least 2 (D + 1)
// centres and falls back to the constant part when the system is singular. Centres closer than
// 1e-12 of the data's extent to an earlier one are dropped (a pose met twice; interpolating
// both would make Phi singular).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/status.h"

namespace facedyn::detail {

enum class RbfPolynomial { kAuto, kConstant, kLinear };

class BiharmonicRbf {
 public:
  // centres: D x N; values: N x K (row j is the value at centre j).
  static StatusOr<BiharmonicRbf> Fit(const Eigen::MatrixXd& centres, const Eigen::MatrixXd& values,
                                     RbfPolynomial polynomial = RbfPolynomial::kAuto);
  // From stored parts (a loaded model); coefficients (N + P) x K, P = 1 or 1 + D; with an
  // output basis (k x K, orthonormal rows) the coefficients are (N + P) x k.
  static StatusOr<BiharmonicRbf> FromParts(Eigen::MatrixXd centres, Eigen::MatrixXd coefficients,
                                           bool linear, Eigen::MatrixXd output_basis = {});

  // Keeps the outputs' leading principal directions: the fewest k whose singular values of the
  // training values hold at least `energy` (0..1] of their squared sum. The interpolant becomes
  // s(f) B^T B with B the k x K basis (the values' top right singular vectors), so the RBF
  // stores (N + P) x k coefficients and k x K basis numbers instead of (N + P) x K: the
  // output's size is paid once, not once per centre. energy 1 keeps every direction with a
  // non-zero singular value (exact at the centres). `values` are the fit's (N x K).
  Status CompressOutputs(const Eigen::MatrixXd& values, double energy);

  // s(f) into out (K). Precondition (CHECK): f.size() == dimension(), out->size() == outputs().
  void Evaluate(const Eigen::Ref<const Eigen::VectorXd>& f, Eigen::Ref<Eigen::VectorXd> out) const;

  int dimension() const { return static_cast<int>(centres_.rows()); }
  int centre_count() const { return static_cast<int>(centres_.cols()); }
  int outputs() const {
    return static_cast<int>(output_basis_.size() ? output_basis_.cols() : coefficients_.cols());
  }
  bool linear() const { return linear_; }
  const Eigen::MatrixXd& centres() const { return centres_; }
  const Eigen::MatrixXd& coefficients() const { return coefficients_; }
  // k x K with orthonormal rows after CompressOutputs; empty (0 x 0) when uncompressed.
  const Eigen::MatrixXd& output_basis() const { return output_basis_; }
  // Bytes of the stored numbers (centres, coefficients and output basis, doubles).
  size_t MemoryBytes() const {
    return sizeof(double) * (centres_.size() + coefficients_.size() + output_basis_.size());
  }

 private:
  Eigen::MatrixXd centres_;
  Eigen::MatrixXd coefficients_;
  Eigen::MatrixXd output_basis_;
  bool linear_ = false;
};

// Solves [kernel P; P^T 0] [a; b] = [values; 0] (kernel N x N, poly N x P, values N x K) and
// checks the residual; an error when the system is singular. Shared by per-region and
// per-vertex (Bickel) interpolants, whose kernels differ only in the distance.
StatusOr<Eigen::MatrixXd> SolveRbfSystem(const Eigen::MatrixXd& kernel, const Eigen::MatrixXd& poly,
                                         const Eigen::MatrixXd& values);

// Greedy frame selection: start with the frame of largest |y| (what a model with no frame gets
// most wrong), then repeatedly add the frame the current interpolant (biharmonic, constant
// part: defined from one frame on) reconstructs worst, until `count` frames or every frame is
// reproduced. Works on the Gram matrix gram(i, j) = <y_i, y_j> of the training values so one
// step costs O(N k^2), independent of the output size: the prediction of frame j is
// sum_i m_ji y_i over the selected i, so its squared error is
//   m_j^T G_SS m_j - 2 m_j^T G_Sj + G_jj.
// features: D x N; gram: N x N. Returns frame indices in pick order.
std::vector<int> GreedySelectFrames(const Eigen::MatrixXd& features, const Eigen::MatrixXd& gram,
                                    int count);

}  // namespace facedyn::detail
