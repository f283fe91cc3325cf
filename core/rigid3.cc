#include "core/rigid3.h"

#include <cmath>

#include "core/check.h"

namespace facedyn {

Rigid3::Rigid3(const Eigen::Quaterniond& rotation, const Eigen::Vector3d& translation)
    : rotation_(rotation), translation_(translation) {
  const double norm = rotation_.norm();
  FACEDYN_CHECK(norm > 1e-12 && std::isfinite(norm), "Rigid3 needs a non-zero finite quaternion");
  rotation_.coeffs() /= norm;
}

Rigid3 Rigid3::FromAxisAngle(const Eigen::Vector3d& axis, double angle_rad,
                             const Eigen::Vector3d& translation) {
  FACEDYN_CHECK(axis.norm() > 1e-12, "rotation axis must be non-zero");
  return Rigid3(Eigen::Quaterniond(Eigen::AngleAxisd(angle_rad, axis.normalized())), translation);
}

bool Rigid3::IsRigidMatrix(const Eigen::Matrix4d& matrix, double tolerance) {
  if (!matrix.allFinite()) return false;
  if (!matrix.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1), tolerance)) return false;
  const Eigen::Matrix3d r = matrix.topLeftCorner<3, 3>();
  if (!(r.transpose() * r).isIdentity(tolerance)) return false;
  return std::abs(r.determinant() - 1.0) <= tolerance;
}

Rigid3 Rigid3::FromMatrix4(const Eigen::Matrix4d& matrix) {
  FACEDYN_CHECK(IsRigidMatrix(matrix), "FromMatrix4 needs a rigid [R t; 0 1] matrix");
  const Eigen::Matrix3d r = matrix.topLeftCorner<3, 3>();
  return Rigid3(Eigen::Quaterniond(r), matrix.topRightCorner<3, 1>());
}

Eigen::Matrix4d Rigid3::ToMatrix4() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = RotationMatrix();
  m.topRightCorner<3, 1>() = translation_;
  return m;
}

Rigid3 Rigid3::operator*(const Rigid3& b_from_c) const {
  return Rigid3(rotation_ * b_from_c.rotation_, rotation_ * b_from_c.translation_ + translation_);
}

Eigen::Matrix3Xd Rigid3::Apply(const Eigen::Matrix3Xd& points_in_b) const {
  return (RotationMatrix() * points_in_b).colwise() + translation_;
}

Rigid3 Rigid3::Inverse() const {
  const Eigen::Quaterniond inverse_rotation = rotation_.conjugate();
  return Rigid3(inverse_rotation, -(inverse_rotation * translation_));
}

double Rigid3::AngleRad() const {
  // 2 atan2(|v|, |w|) is accurate near 0 and pi, unlike 2 acos(w).
  return 2.0 * std::atan2(rotation_.vec().norm(), std::abs(rotation_.w()));
}

Rigid3 Rigid3::Interpolate(const Rigid3& a, const Rigid3& b, double t) {
  // Eigen's slerp takes the shorter arc (it flips the sign of b when the dot product is < 0).
  return Rigid3(a.rotation_.slerp(t, b.rotation_),
                (1.0 - t) * a.translation_ + t * b.translation_);
}

bool Rigid3::IsApprox(const Rigid3& other, double tolerance) const {
  // q and -q are the same rotation.
  const double rotation_distance =
      std::min((rotation_.coeffs() - other.rotation_.coeffs()).norm(),
               (rotation_.coeffs() + other.rotation_.coeffs()).norm());
  return rotation_distance <= tolerance &&
         (translation_ - other.translation_).norm() <= tolerance * (1.0 + translation_.norm());
}

}  // namespace facedyn
