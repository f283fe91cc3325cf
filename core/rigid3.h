// Rigid3: a rigid transform of 3-space, a unit quaternion plus a translation (mm).
//
// Named target_from_source everywhere (ARCHITECTURE.md): `world_from_skull` maps a point in
// the skull frame to the world frame, so `world_from_skull * point_in_skull` is
// `point_in_world`, and composition reads right to left:
// `cam_from_skull = cam_from_world * world_from_skull`. The quaternion is kept unit; every
// operation renormalises so drift from long products does not accumulate.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace facedyn {

class Rigid3 {
 public:
  Rigid3() : rotation_(Eigen::Quaterniond::Identity()), translation_(Eigen::Vector3d::Zero()) {}
  // `rotation` must be non-zero; it is normalised.
  Rigid3(const Eigen::Quaterniond& rotation, const Eigen::Vector3d& translation);

  static Rigid3 Identity() { return Rigid3(); }
  static Rigid3 FromTranslation(const Eigen::Vector3d& translation) {
    return Rigid3(Eigen::Quaterniond::Identity(), translation);
  }
  // Rotation by `angle_rad` about the unit `axis` (through the origin).
  static Rigid3 FromAxisAngle(const Eigen::Vector3d& axis, double angle_rad,
                              const Eigen::Vector3d& translation = Eigen::Vector3d::Zero());
  // From a homogeneous 4x4 matrix [R t; 0 0 0 1]. Precondition: R is a rotation within 1e-6
  // (use IsRigidMatrix to check data first); R is re-orthonormalised through the quaternion.
  static Rigid3 FromMatrix4(const Eigen::Matrix4d& matrix);
  // True when `matrix` is [R t; 0 0 0 1] with R orthonormal, det +1, within `tolerance`.
  static bool IsRigidMatrix(const Eigen::Matrix4d& matrix, double tolerance = 1e-6);

  const Eigen::Quaterniond& rotation() const { return rotation_; }
  const Eigen::Vector3d& translation() const { return translation_; }
  Eigen::Matrix3d RotationMatrix() const { return rotation_.toRotationMatrix(); }
  Eigen::Matrix4d ToMatrix4() const;

  // a_from_c = a_from_b * b_from_c.
  Rigid3 operator*(const Rigid3& b_from_c) const;
  // point_in_a = a_from_b * point_in_b.
  Eigen::Vector3d operator*(const Eigen::Vector3d& point_in_b) const {
    return rotation_ * point_in_b + translation_;
  }
  // Applies the transform to every column of a 3xN block of points.
  Eigen::Matrix3Xd Apply(const Eigen::Matrix3Xd& points_in_b) const;
  // Rotates a direction (no translation).
  Eigen::Vector3d RotateVector(const Eigen::Vector3d& vector_in_b) const {
    return rotation_ * vector_in_b;
  }

  // b_from_a for this a_from_b.
  Rigid3 Inverse() const;

  // Rotation angle of the transform in radians, in [0, pi].
  double AngleRad() const;

  // Interpolates from `a` (t = 0) to `b` (t = 1): quaternion slerp along the shorter arc and
  // linear interpolation of the translation. This is the interpolation of a rigid body whose
  // origin moves on a straight line, which is what per-frame skull poses need.
  static Rigid3 Interpolate(const Rigid3& a, const Rigid3& b, double t);

  bool IsApprox(const Rigid3& other, double tolerance = 1e-9) const;

 private:
  Eigen::Quaterniond rotation_;
  Eigen::Vector3d translation_;
};

}  // namespace facedyn
