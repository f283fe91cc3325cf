// Deformation gradients of a triangle mesh (Sumner & Popovic 2004, section 3; Masquerade uses
// them as the pose of each marker's region because, unlike edge strains, they keep the
// surface's bending).
//
// A triangle (a, b, c) gets the frame V = [b - a, c - a, n] with n its UNIT normal, and its
// deformation gradient is F = V_deformed V_rest^-1. For a rigid motion x -> R x + t the edges
// and the unit normal all rotate by R, so F = R exactly (a rotation), whatever the triangle's
// shape; a uniform scale s gives diag-like s on the tangent plane and 1 along the normal.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/mesh.h"

namespace facedyn::detail {

// F for one triangle. Precondition: the rest triangle is not degenerate.
Eigen::Matrix3d DeformationGradient(const Eigen::Matrix3d& rest_abc_mm,
                                    const Eigen::Matrix3d& deformed_abc_mm);

// The rest frames of a mesh's fan triangles, inverted once.
class DeformationGradients {
 public:
  DeformationGradients() = default;
  // Degenerate rest triangles (zero area) get a zero inverse, hence F = 0; callers give them
  // no weight (their area is zero).
  explicit DeformationGradients(const Mesh& neutral);

  int triangle_count() const { return static_cast<int>(triangles_.cols()); }
  const Eigen::Matrix3Xi& triangles() const { return triangles_; }

  // 9 x T, column t = vec(F_t) (column-major) for `positions_mm` (3 x V).
  void Compute(const Eigen::Matrix3Xd& positions_mm,
               Eigen::Matrix<double, 9, Eigen::Dynamic>* f) const;
  // Only the listed triangles: column k = vec(F) of triangle `subset[k]` (each in range).
  void Compute(const Eigen::Matrix3Xd& positions_mm, const std::vector<int>& subset,
               Eigen::Matrix<double, 9, Eigen::Dynamic>* f) const;

 private:
  Eigen::Matrix3d GradientOf(const Eigen::Matrix3Xd& positions_mm, int t) const;

  Eigen::Matrix3Xi triangles_;
  Eigen::Matrix<double, 9, Eigen::Dynamic> rest_inverse_;
};

// A coarser quadrature for the integral of a smooth field over a mesh's triangles: triangles are
// grouped into patches of those whose rest centroids share a cubic cell of side `cell_mm` AND
// that are connected through shared edges inside it (so the two lips, or an eyelid and the cheek
// under it, never share a patch even where one cell holds both). Returns, per triangle, its
// patch's representative: the member with positive area whose centroid is nearest the patch's
// area-weighted centroid (a patch of zero-area triangles only is represented by its first).
// cell_mm <= 0: every triangle represents itself.
std::vector<int> PatchRepresentatives(const Eigen::Matrix3Xd& rest_mm,
                                      const Eigen::Matrix3Xi& triangles, double cell_mm);

}  // namespace facedyn::detail
