#include "core/mesh_primitives.h"

#include <cmath>

#include "core/check.h"

namespace facedyn {

Mesh MakeEllipsoidPatch(double radius_x_mm, double radius_y_mm, double radius_z_mm,
                        double half_angle_u_rad, double half_angle_v_rad, int columns, int rows) {
  FACEDYN_CHECK(columns >= 1 && rows >= 1, "patch needs at least one quad");
  Mesh mesh;
  const int nu = columns + 1;
  const int nv = rows + 1;
  mesh.positions_mm.resize(3, nu * nv);
  mesh.uvs.resize(2, nu * nv);
  for (int j = 0; j < nv; ++j) {
    for (int i = 0; i < nu; ++i) {
      const double u = double(i) / columns;
      const double v = double(j) / rows;
      const double azimuth = (2 * u - 1) * half_angle_u_rad;
      const double elevation = (2 * v - 1) * half_angle_v_rad;
      const int k = j * nu + i;
      mesh.positions_mm.col(k) << radius_x_mm * std::cos(elevation) * std::sin(azimuth),
          radius_y_mm * std::sin(elevation), radius_z_mm * std::cos(elevation) * std::cos(azimuth);
      mesh.uvs.col(k) << u, v;
    }
  }
  for (int j = 0; j < rows; ++j) {
    for (int i = 0; i < columns; ++i) {
      const int a = j * nu + i, b = a + 1, c = a + nu + 1, d = a + nu;
      // Counter-clockwise seen from +Z (outside of the patch).
      mesh.AddFace({a, b, c}, {a, b, c});
      mesh.AddFace({a, c, d}, {a, c, d});
    }
  }
  return mesh;
}

}  // namespace facedyn
