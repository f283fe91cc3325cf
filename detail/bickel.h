// The Bickel et al. 2008 baseline ("Pose-space animation and transfer of facial details",
// SCA '08), the per-vertex approach Masquerade compares itself with:
//   - the same large-scale deformation and local vertex offsets as MasqueradeModel (Masquerade
//     keeps both from Bickel), so the two differ only in the pose and in the interpolants;
//   - pose: the strain s_e = |p_a - p_b| / L_e - 1 of every edge of the marker graph (markers
//     whose nearest-marker cells share a mesh edge are joined), computed from the markers only;
//   - one biharmonic RBF PER VERTEX, in a pose space weighted for that vertex (weighted
//     pose-space deformation): |s - s_j|_v^2 = sum_e alpha_ve (s_e - s_je)^2, alpha_ve a
//     Gaussian of the vertex's edge-path distance to the edge (mean of its two markers'
//     distances) relative to its nearest edge, truncated at 3 sigma and normalised;
//   - greedy training frames on the strain pose and the whole face's offsets.
// The polynomial part is the constant only: the strain space (hundreds of edges) has more
// dimensions than there are training frames, so a linear part would be singular.
#pragma once

#include <Eigen/Core>
#include <utility>
#include <vector>

#include "core/progress.h"
#include "core/status.h"
#include "detail/large_scale.h"
#include "detail/training_set.h"

namespace facedyn::detail {

struct BickelOptions {
  LaplacianDeformerOptions large_scale;
  double edge_sigma_mm = 20.0;  // the lowest error of 5/6/10/20 in bench/detail_bench --quick
  int frames = 80;              // greedy; 0 or >= #frames: every frame
  Status Check() const;
};

class BickelModel {
 public:
  static StatusOr<BickelModel> Train(const DetailTrainingSet& set, const BickelOptions& options,
                                     std::vector<int>* selected_frames = nullptr);

  Status Apply(const Eigen::Matrix3Xd& markers_mm, Eigen::Matrix3Xd* skin_mm) const;
  // Every frame of a sequence on `threads` threads (0: the cores), as MasqueradeModel's.
  Status ApplyFrames(const std::vector<Eigen::Matrix3Xd>& markers_mm,
                     std::vector<Eigen::Matrix3Xd>* skins_mm, int threads = 0,
                     Progress* progress = nullptr) const;

  // Bytes of what was learned: per vertex its RBF coefficients ((N + 1) x 3) and its edge
  // weights (index + alpha), plus the training poses (E x N) and edge rest lengths.
  size_t MemoryBytes() const;
  int edge_count() const { return static_cast<int>(edges_.size()); }

  // The strain pose (E) of marker positions (3 x M).
  Eigen::VectorXd Strains(const Eigen::Matrix3Xd& markers_mm) const;

 private:
  std::vector<std::pair<int, int>> edges_;
  Eigen::VectorXd rest_length_mm_;
  Eigen::MatrixXd training_strains_;  // E x N
  // Per vertex: edge offsets into edge_index_/edge_alpha_ (CSR) and coefficients (N + 1) x 3.
  std::vector<int> vertex_offsets_;
  std::vector<int> edge_index_;
  std::vector<double> edge_alpha_;
  Eigen::MatrixXd coefficients_;  // (N + 1) x (3 V), vertex v in columns 3v..3v+2
  LaplacianDeformer deformer_;
  TangentFrames tangent_;
  int marker_count_ = 0;
};

}  // namespace facedyn::detail
