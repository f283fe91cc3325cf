// SkullKinematics: the rigid motion of the skull at one instant, in the form the soft-tissue
// simulation needs. The tissue is simulated in the skull frame (a non-inertial frame), where
// head motion appears as fictitious body forces per unit mass:
//   a_fict(x) = -(a0 + alpha x (x) + omega x (omega x x) + 2 omega x v)
// with every vector expressed in skull coordinates (Goldstein, Classical Mechanics, ch. 4.9).
// Gravity (-Y in world) is rotated into skull coordinates as well.
#pragma once

#include <Eigen/Core>

#include "core/rigid3.h"

namespace facedyn::physics {

// World gravity, mm/s^2, along -Y (ARCHITECTURE.md: world frame is +Y up).
inline const Eigen::Vector3d kGravityInWorld(0.0, -9810.0, 0.0);

struct SkullKinematics {
  Rigid3 world_from_skull;
  // Acceleration of the skull frame's origin, expressed in skull coordinates, mm/s^2.
  Eigen::Vector3d origin_acceleration_in_skull = Eigen::Vector3d::Zero();
  // Angular velocity and acceleration of the skull, expressed in skull coordinates, rad/s, rad/s^2.
  Eigen::Vector3d angular_velocity_in_skull = Eigen::Vector3d::Zero();
  Eigen::Vector3d angular_acceleration_in_skull = Eigen::Vector3d::Zero();

  Eigen::Vector3d GravityInSkull() const {
    return world_from_skull.rotation().conjugate() * kGravityInWorld;
  }
};

}  // namespace facedyn::physics
