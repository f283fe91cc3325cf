#include "physics/tet_shell.h"

#include <algorithm>
#include <array>

#include <Eigen/Geometry>

#include "core/check.h"

namespace facedyn::physics {
namespace {
double SignedVolume(const Eigen::Matrix3Xd& x, int a, int b, int c, int d) {
  return (x.col(b) - x.col(a)).cross(x.col(c) - x.col(a)).dot(x.col(d) - x.col(a)) / 6.0;
}
}  // namespace

TetShell BuildTetShell(const Mesh& skin, const Eigen::Matrix3Xd& skull_positions_mm, int layers) {
  FACEDYN_CHECK(layers >= 1, "a tet shell needs at least one layer");
  FACEDYN_CHECK(skull_positions_mm.cols() == skin.vertex_count(),
                "the skull surface must share the skin's topology");
  TetShell shell;
  shell.layers = layers;
  const int v_count = skin.vertex_count();
  shell.surface_vertex_count = v_count;
  shell.rest_positions_mm.resize(3, (layers + 1) * v_count);
  for (int l = 0; l <= layers; ++l) {
    const double s = double(l) / layers;
    shell.rest_positions_mm.middleCols(l * v_count, v_count) =
        (1.0 - s) * skull_positions_mm + s * skin.positions_mm;
  }
  const Eigen::Matrix3Xi triangles = skin.Triangles();
  std::vector<std::array<int, 4>> tets;
  std::vector<int> owner;
  tets.reserve(3 * layers * triangles.cols());
  const double min_volume = 1e-6;  // mm^3
  for (int t = 0; t < triangles.cols(); ++t) {
    std::array<int, 3> v = {triangles(0, t), triangles(1, t), triangles(2, t)};
    std::sort(v.begin(), v.end());
    for (int l = 0; l < layers; ++l) {
      const int a = shell.Node(l, v[0]), b = shell.Node(l, v[1]), c = shell.Node(l, v[2]);
      const int a1 = shell.Node(l + 1, v[0]), b1 = shell.Node(l + 1, v[1]), c1 = shell.Node(l + 1, v[2]);
      const std::array<std::array<int, 4>, 3> prism = {{{a, b, c, a1}, {b, c, a1, b1}, {c, a1, b1, c1}}};
      for (auto tet : prism) {
        double volume = SignedVolume(shell.rest_positions_mm, tet[0], tet[1], tet[2], tet[3]);
        if (volume < 0) {
          std::swap(tet[2], tet[3]);
          volume = -volume;
        }
        if (volume < min_volume) continue;
        tets.push_back(tet);
        owner.push_back(v[0]);
      }
    }
  }
  shell.tets.resize(4, tets.size());
  shell.tet_surface_vertex.resize(tets.size());
  for (size_t e = 0; e < tets.size(); ++e) {
    for (int k = 0; k < 4; ++k) shell.tets(k, e) = tets[e][k];
    shell.tet_surface_vertex[e] = owner[e];
  }
  return shell;
}

}  // namespace facedyn::physics
