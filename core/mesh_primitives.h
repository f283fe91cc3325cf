// Small procedural surfaces with UVs, for tests, benchmarks and the demo before the face
// generators of sim/ exist. Not faces: see sim/ for those.
#pragma once

#include "core/mesh.h"

namespace facedyn {

// A patch of an ellipsoid with semi-axes (radius_x, radius_y, radius_z) mm facing +Z,
// spanning +-half_angle_u_rad in azimuth and +-half_angle_v_rad in elevation, as a grid of
// `columns` x `rows` quads split into triangles. UVs map the patch to [0,1]^2.
// Preconditions: columns, rows >= 1; angles in (0, pi/2].
Mesh MakeEllipsoidPatch(double radius_x_mm, double radius_y_mm, double radius_z_mm,
                        double half_angle_u_rad, double half_angle_v_rad, int columns, int rows);

}  // namespace facedyn
