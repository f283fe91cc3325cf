// Large-scale deformation of the high-resolution neutral mesh from sparse markers, and the
// per-vertex frames in which fine detail is stored (Masquerade, Moser et al. 2017, section 3;
// the split into large and fine scale follows Bickel et al. 2008).
//
// LaplacianDeformer minimises, over the displacement d (3 x V, mm) of the neutral skin x0,
//   E(d) = sum_xyz d^T Q d + w sum_m |c_m^T d - (p_m - c_m^T x0)|^2,   Q = L^T M^-1 L,
// a bi-Laplacian (thin-plate) energy with L the clamped-cotangent stiffness of the neutral's
// fan triangulation, M its lumped (barycentric) vertex areas, c_m the barycentric row of marker
// m (a SurfacePoint) and p_m its observed position. The normal equations
//   (Q + w C^T C) d = w C^T (p - C x0)
// have one matrix for every frame, so it is factorised once (sparse LDL^T). The right-hand side
// is linear in the M marker residuals r = p - C x0, so Create also back-substitutes the M
// columns of w C^T once, giving the marker response K = (Q + w C^T C)^-1 w C^T (V x M, dense):
// a frame is then d = K r, V x M x 3 multiply-adds (about 2 M for 9,409 vertices and 80
// markers), several times cheaper than three sparse back-substitutions (DeformBySolve, kept
// for checking and for marker sets too large for a dense K). What is exactly true of this energy,
// and tested: neutral markers give the neutral (d = 0), and markers translated by t give x0 + t (L
// 1 = 0). An affine map is not reproduced exactly on a curved, bounded mesh (L x0 != 0), so it is
// not claimed.
//
// TangentFrames gives every vertex an orthonormal frame [t b n] that follows the surface: n
// the area-weighted vertex normal, t the edge to a fixed neighbour projected into the tangent
// plane, b = n x t. Fine detail stored as offsets in these frames follows the large-scale
// rotation of the skin (Masquerade: "local vertex offsets ... adapt to the large-scale
// deformations", unlike world-space offsets).
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <memory>
#include <vector>

#include "core/face_rig.h"
#include "core/mesh.h"
#include "core/status.h"

namespace facedyn::detail {

struct LaplacianDeformerOptions {
  // Marker weight w relative to the mean diagonal of Q: large values make the markers nearly
  // interpolated (the residual at a marker falls as 1/w).
  double marker_weight = 1000.0;
  Status Check() const;
};

class LaplacianDeformer {
 public:
  // Builds and factorises the system for `neutral` (its positions are x0, mm) and markers on
  // it. Errors name a marker whose vertex is out of range or a mesh the factorisation rejects
  // (e.g. fewer markers than connected components).
  static StatusOr<LaplacianDeformer> Create(const Mesh& neutral,
                                            const std::vector<SurfacePoint>& markers,
                                            const LaplacianDeformerOptions& options);

  // Large-scale skin (3 x V, same frame as the markers, mm) for marker positions (3 x M).
  // Precondition (CHECK): markers_mm.cols() == marker_count().
  void Deform(const Eigen::Matrix3Xd& markers_mm, Eigen::Matrix3Xd* skin_mm) const;
  // The same by three back-substitutions (no marker response).
  void DeformBySolve(const Eigen::Matrix3Xd& markers_mm, Eigen::Matrix3Xd* skin_mm) const;

  int vertex_count() const { return static_cast<int>(neutral_mm_.cols()); }
  int marker_count() const { return static_cast<int>(markers_.size()); }
  const Eigen::Matrix3Xd& neutral_mm() const { return neutral_mm_; }

 private:
  Eigen::Matrix3Xd neutral_mm_;
  std::vector<SurfacePoint> markers_;
  Eigen::Matrix3Xd neutral_markers_mm_;  // C x0
  double weight_ = 0.0;                  // w (absolute)
  Eigen::MatrixXd response_;             // K, V x M
  // shared_ptr: Eigen's factorisation is not copyable, and the model is immutable after Create.
  std::shared_ptr<Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>> solver_;
};

// Per-vertex frames [t b n] (columns) of a surface in a fixed topology.
class TangentFrames {
 public:
  // Chooses each vertex's reference neighbour on the neutral (the neighbour whose edge is
  // farthest from the normal) so frames are well defined. Vertices on no triangle get the
  // identity frame.
  explicit TangentFrames(const Mesh& neutral);
  TangentFrames() = default;

  // frames: 9 x V, column v = vec([t b n]) (column-major 3x3) of `positions_mm` (3 x V).
  void Compute(const Eigen::Matrix3Xd& positions_mm,
               Eigen::Matrix<double, 9, Eigen::Dynamic>* frames) const;

  // Local offsets: frames^T (x - base) per vertex (3 x V, mm).
  static void ToLocal(const Eigen::Matrix<double, 9, Eigen::Dynamic>& frames,
                      const Eigen::Matrix3Xd& base_mm, const Eigen::Matrix3Xd& x_mm,
                      Eigen::Matrix3Xd* local_mm);
  // x = base + frames * local per vertex.
  static void FromLocal(const Eigen::Matrix<double, 9, Eigen::Dynamic>& frames,
                        const Eigen::Matrix3Xd& base_mm, const Eigen::Matrix3Xd& local_mm,
                        Eigen::Matrix3Xd* x_mm);

 private:
  Eigen::Matrix3Xi triangles_;
  std::vector<int> reference_neighbour_;  // -1: no triangle
};

}  // namespace facedyn::detail
