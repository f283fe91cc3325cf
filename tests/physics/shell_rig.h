// The spherical shell patch the physics tests run on (skin radius 90 mm over a skull of radius
// 75 mm, 15 mm of flesh), with one expression: a 5 mm bulge of the patch centre along +Z.
#pragma once

#include <cmath>

#include "core/face_rig.h"
#include "core/mesh_primitives.h"

namespace facedyn::physics {

inline FaceRig MakeShellRig(int resolution = 14) {
  FaceRig rig;
  rig.name = "shell";
  rig.neutral = MakeEllipsoidPatch(90, 90, 90, 0.7, 0.6, resolution, resolution);
  rig.skull = MakeEllipsoidPatch(75, 75, 75, 0.7, 0.6, resolution, resolution);
  Eigen::Matrix3Xd bulge = Eigen::Matrix3Xd::Zero(3, rig.vertex_count());
  for (int v = 0; v < rig.vertex_count(); ++v) {
    const Eigen::Vector3d p = rig.neutral.positions_mm.col(v);
    const double r2 = (p.x() * p.x() + p.y() * p.y()) / (30.0 * 30.0);
    bulge(2, v) = 5.0 * std::exp(-r2);
  }
  rig.blendshape_names = {"bulge"};
  rig.blendshape_deltas_mm = {bulge};
  return rig;
}

}  // namespace facedyn::physics
