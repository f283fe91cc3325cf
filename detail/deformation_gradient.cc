#include "detail/deformation_gradient.h"

#include <Eigen/Geometry>
#include <Eigen/LU>

namespace facedyn::detail {
namespace {

Eigen::Matrix3d TriangleFrame(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                              const Eigen::Vector3d& c) {
  Eigen::Matrix3d frame;
  frame.col(0) = b - a;
  frame.col(1) = c - a;
  const Eigen::Vector3d n = frame.col(0).cross(frame.col(1));
  const double norm = n.norm();
  frame.col(2) = norm > 0 ? Eigen::Vector3d(n / norm) : Eigen::Vector3d::Zero();
  return frame;
}

}  // namespace

Eigen::Matrix3d DeformationGradient(const Eigen::Matrix3d& rest_abc_mm,
                                    const Eigen::Matrix3d& deformed_abc_mm) {
  const Eigen::Matrix3d rest =
      TriangleFrame(rest_abc_mm.col(0), rest_abc_mm.col(1), rest_abc_mm.col(2));
  const Eigen::Matrix3d deformed =
      TriangleFrame(deformed_abc_mm.col(0), deformed_abc_mm.col(1), deformed_abc_mm.col(2));
  return deformed * rest.inverse();
}

DeformationGradients::DeformationGradients(const Mesh& neutral) : triangles_(neutral.Triangles()) {
  const Eigen::Matrix3Xd& x = neutral.positions_mm;
  rest_inverse_.resize(9, triangles_.cols());
  for (int t = 0; t < triangles_.cols(); ++t) {
    const Eigen::Matrix3d frame =
        TriangleFrame(x.col(triangles_(0, t)), x.col(triangles_(1, t)), x.col(triangles_(2, t)));
    Eigen::Map<Eigen::Matrix3d> inv(rest_inverse_.col(t).data());
    if (frame.col(2).squaredNorm() > 0) {
      inv = frame.inverse();
    } else {
      inv.setZero();
    }
  }
}

void DeformationGradients::Compute(const Eigen::Matrix3Xd& positions_mm,
                                   Eigen::Matrix<double, 9, Eigen::Dynamic>* f) const {
  f->resize(9, triangles_.cols());
  for (int t = 0; t < triangles_.cols(); ++t) {
    const Eigen::Matrix3d frame =
        TriangleFrame(positions_mm.col(triangles_(0, t)), positions_mm.col(triangles_(1, t)),
                      positions_mm.col(triangles_(2, t)));
    Eigen::Map<Eigen::Matrix3d>(f->col(t).data()) =
        frame * Eigen::Map<const Eigen::Matrix3d>(rest_inverse_.col(t).data());
  }
}

}  // namespace facedyn::detail
