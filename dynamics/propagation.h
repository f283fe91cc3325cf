// Propagation of sparse sample offsets to every vertex of the mesh (Zoss et al. 2020, section
// 5.2: "propagate the deformation over the entire surface"; the paper uses the Anatomical Local
// Model of Wu et al. 2016 and names Laplacian mesh deformation [Sorkine et al. 2004] as the
// alternative).
//
// facedyn uses a prefactorised smooth interpolation on the neutral mesh in the skull frame: the
// per-vertex offsets d (V x 3) minimise
//
//   E(d) = ||L d||^2 + lambda ||C d - dx||^2 + epsilon ||d||^2
//
// with L the edge-length-weighted graph Laplacian of the neutral (rows normalised, so constant
// fields have zero energy), C the S x V barycentric matrix of the skin samples, dx the S x 3
// sample offsets, lambda = constraint_weight (near-interpolation) and a tiny epsilon that keeps
// parts of the mesh without samples (e.g. a separate eyeball component) at zero. The minimiser is
// linear in dx: d = W dx with W = lambda (L^T L + lambda C^T C + epsilon I)^-1 C^T, a dense V x S
// matrix computed once per rig (one sparse LDL^T factorisation and S solves). Applying it is one
// GEMM per frame, which is what makes removal run at hundreds of frames per second.
//
// Why not a k-nearest-sample blend in space: it ignores the surface, so an offset of the upper
// lip leaks into the lower lip across the mouth slit, and the cheek into the eyelid. The
// Laplacian couples vertices only through mesh edges, so the mouth and eye holes separate what
// should be separate. Why not the ALM: it needs per-subject anatomical subspaces that the
// procedural and imported rigs do not have; this is the documented alternative.
#pragma once

#include <Eigen/Core>

#include "core/face_rig.h"
#include "core/pc2.h"
#include "core/status.h"

namespace facedyn::dynamics {

struct PropagationOptions {
  double constraint_weight = 100.0;  // lambda
  double regularisation = 1e-6;      // epsilon
  // Both > 0. The message names the field.
  Status Check() const;
};

class SamplePropagation {
 public:
  // Builds W for the rig's neutral mesh and skin samples. Errors: no samples, no faces,
  // a failed factorisation.
  static StatusOr<SamplePropagation> Build(const FaceRig& rig,
                                           const PropagationOptions& options = {});

  int vertex_count() const { return static_cast<int>(weights_.rows()); }
  int sample_count() const { return static_cast<int>(weights_.cols()); }
  // W (V x S): vertex offsets = W * sample offsets.
  const Eigen::MatrixXf& weights() const { return weights_; }

  // Offsets of every vertex (3 x V) from the sample offsets of one frame (3 x S).
  // No allocation when `vertex_offsets` already has the right size.
  void Apply(const Eigen::Ref<const Eigen::Matrix3Xf>& sample_offsets,
             Eigen::Ref<Eigen::Matrix3Xf> vertex_offsets) const;

 private:
  Eigen::MatrixXf weights_;
  Eigen::MatrixXf weights_transposed_;  // S x V, for the 3 x S times S x V product
};

}  // namespace facedyn::dynamics
