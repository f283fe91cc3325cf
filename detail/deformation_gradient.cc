#include "detail/deformation_gradient.h"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <utility>

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

Eigen::Matrix3d DeformationGradients::GradientOf(const Eigen::Matrix3Xd& positions_mm,
                                                 int t) const {
  const Eigen::Matrix3d frame =
      TriangleFrame(positions_mm.col(triangles_(0, t)), positions_mm.col(triangles_(1, t)),
                    positions_mm.col(triangles_(2, t)));
  return frame * Eigen::Map<const Eigen::Matrix3d>(rest_inverse_.col(t).data());
}

void DeformationGradients::Compute(const Eigen::Matrix3Xd& positions_mm,
                                   Eigen::Matrix<double, 9, Eigen::Dynamic>* f) const {
  f->resize(9, triangles_.cols());
  for (int t = 0; t < triangles_.cols(); ++t)
    Eigen::Map<Eigen::Matrix3d>(f->col(t).data()) = GradientOf(positions_mm, t);
}

void DeformationGradients::Compute(const Eigen::Matrix3Xd& positions_mm,
                                   const std::vector<int>& subset,
                                   Eigen::Matrix<double, 9, Eigen::Dynamic>* f) const {
  f->resize(9, static_cast<int>(subset.size()));
  for (size_t k = 0; k < subset.size(); ++k)
    Eigen::Map<Eigen::Matrix3d>(f->col(static_cast<int>(k)).data()) =
        GradientOf(positions_mm, subset[k]);
}

std::vector<int> PatchRepresentatives(const Eigen::Matrix3Xd& rest_mm,
                                      const Eigen::Matrix3Xi& triangles, double cell_mm) {
  const int t_count = static_cast<int>(triangles.cols());
  std::vector<int> representative(t_count);
  std::iota(representative.begin(), representative.end(), 0);
  if (!(cell_mm > 0) || t_count == 0) return representative;

  std::vector<Eigen::Vector3d> centroid(t_count);
  std::vector<double> area(t_count);
  std::vector<std::array<int64_t, 3>> cell(t_count);
  for (int t = 0; t < t_count; ++t) {
    const Eigen::Vector3d a = rest_mm.col(triangles(0, t)), b = rest_mm.col(triangles(1, t)),
                          c = rest_mm.col(triangles(2, t));
    centroid[t] = (a + b + c) / 3.0;
    area[t] = 0.5 * (b - a).cross(c - a).norm();
    for (int k = 0; k < 3; ++k)
      cell[t][k] = static_cast<int64_t>(std::floor(centroid[t][k] / cell_mm));
  }

  // Union-find over triangles that share an edge and a cell.
  std::vector<int> parent(t_count);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int t) {
    while (parent[t] != t) t = parent[t] = parent[parent[t]];
    return t;
  };
  std::map<std::pair<int, int>, int> first_on_edge;
  for (int t = 0; t < t_count; ++t) {
    for (int k = 0; k < 3; ++k) {
      const int u = triangles(k, t), v = triangles((k + 1) % 3, t);
      const auto [it, inserted] = first_on_edge.emplace(std::minmax(u, v), t);
      if (inserted || cell[it->second] != cell[t]) continue;
      const int ra = find(it->second), rb = find(t);
      if (ra != rb) parent[std::max(ra, rb)] = std::min(ra, rb);
    }
  }

  // Each patch's area-weighted centroid, then its member nearest to it.
  std::vector<Eigen::Vector3d> weighted(t_count, Eigen::Vector3d::Zero());
  std::vector<double> patch_area(t_count, 0.0);
  for (int t = 0; t < t_count; ++t) {
    const int root = find(t);
    weighted[root] += area[t] * centroid[t];
    patch_area[root] += area[t];
  }
  std::vector<double> best(t_count, std::numeric_limits<double>::infinity());
  std::vector<int> chosen(t_count, -1);
  for (int t = 0; t < t_count; ++t) {
    const int root = find(t);
    if (area[t] <= 0) continue;
    const double d = (centroid[t] - weighted[root] / patch_area[root]).squaredNorm();
    if (d < best[root]) {
      best[root] = d;
      chosen[root] = t;
    }
  }
  for (int t = 0; t < t_count; ++t) {
    const int root = find(t);
    representative[t] = chosen[root] >= 0 ? chosen[root] : root;
  }
  return representative;
}

}  // namespace facedyn::detail
