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
//
// Learned propagation (PropagationLearner, what the networks use by default). The Laplacian
// interpolant is only smooth, not physical: between samples it misses the shape of the tissue's
// vibration (measured on simulated 11 Hz takes: propagating the EXACT sample offsets with it
// leaves 2.8% of the dynamic offset, more than a 4 Hz low-pass of the whole take leaves). The
// dynamic offsets of one subject live in a low-dimensional space (the tissue's vibration modes,
// which is what the ALM's anatomical subspaces capture too), and the training takes of either
// network already hold per-vertex offsets (the moving-average, exact or decomposed targets). So
// W is fitted to them by ridge regression towards the Laplacian W0, shared by x, y and z:
//
//   W = argmin sum_{t,c} ||W dx_c(t) - d_c(t)||^2 + mu ||W - W0||_F^2
//     = (sum d dx^T + mu W0) (sum dx dx^T + mu I)^-1,   mu = prior_weight * trace(G) / S
//
// with dx_c(t) the S sample offsets and d_c(t) the V vertex offsets of component c in frame t,
// G = sum dx dx^T. Without data it is W0; directions of sample space the data never excites fall
// back to W0. Measured the same way, the learned W leaves 0.2% (exact targets) and 0.2-0.4%
// (moving-average targets). Cost: one V x S and one S x S accumulation per training frame.
#pragma once

#include <string>
#include <vector>

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

  // A propagation with the given W (V x S), e.g. one loaded from a model file.
  // Errors: an empty or non-finite matrix.
  static StatusOr<SamplePropagation> FromWeights(Eigen::MatrixXf weights, std::string method);

  // "laplacian" (Build) or "learned" (PropagationLearner), or what FromWeights was given.
  const std::string& method() const { return method_; }
  int vertex_count() const { return static_cast<int>(weights_.rows()); }
  int sample_count() const { return static_cast<int>(weights_.cols()); }
  // W (V x S): vertex offsets = W * sample offsets.
  const Eigen::MatrixXf& weights() const { return weights_; }

  // Offsets of every vertex (3 x V) from the sample offsets of one frame (3 x S).
  // No allocation when `vertex_offsets` already has the right size.
  void Apply(const Eigen::Ref<const Eigen::Matrix3Xf>& sample_offsets,
             Eigen::Ref<Eigen::Matrix3Xf> vertex_offsets) const;

 private:
  std::string method_ = "laplacian";
  Eigen::MatrixXf weights_;
  Eigen::MatrixXf weights_transposed_;  // S x V, for the 3 x S times S x V product
};

struct PropagationLearnOptions {
  // mu relative to the mean diagonal of G (the mean squared sample offset times the number of
  // frame-components): small, so the data decides wherever it has excited the samples.
  double prior_weight = 1e-3;
  // In (0, 1e3]. The message names the field.
  Status Check() const;
};

// Accumulates training offsets and fits the learned W (see the top of this file).
class PropagationLearner {
 public:
  // `prior` is W0 (usually SamplePropagation::Build of the rig); `samples` the rig's skin
  // samples (the same count as prior's columns).
  PropagationLearner(SamplePropagation prior, std::vector<SurfacePoint> samples,
                     PropagationLearnOptions options = {});
  // With the rig's Laplacian (SamplePropagation::Build) as W0 and its skin samples.
  static StatusOr<PropagationLearner> ForRig(const FaceRig& rig,
                                             PropagationLearnOptions options = {});

  // Adds frames [first_frame, last_frame) of per-vertex offsets (skull frame, mm). Errors: a
  // cache with another vertex count, a frame range outside it.
  Status Add(const PointCache& vertex_offsets, int first_frame, int last_frame);
  long frame_count() const { return frames_; }

  // The fitted W ("learned"). Errors: no frames added, bad options, a failed solve.
  StatusOr<SamplePropagation> Fit() const;

 private:
  SamplePropagation prior_;
  std::vector<SurfacePoint> samples_;
  PropagationLearnOptions options_;
  Eigen::MatrixXd sample_gram_;    // G = sum dx dx^T (S x S, lower triangle accumulated)
  Eigen::MatrixXd vertex_sample_;  // sum d dx^T (V x S)
  long frames_ = 0;
};

}  // namespace facedyn::dynamics
