#include "detail/regions.h"

#include <fmt/format.h>

#include <cmath>
#include <functional>
#include <limits>
#include <queue>

namespace facedyn::detail {

Eigen::VectorXd MeshGraphDistances(const Mesh& mesh,
                                   const std::vector<std::pair<int, double>>& seeds) {
  const int v_count = mesh.vertex_count();
  // Adjacency from the polygon boundaries (each face's consecutive corners).
  std::vector<std::vector<int>> neighbours(v_count);
  for (int f = 0; f < mesh.face_count(); ++f) {
    const int begin = mesh.face_offsets[f], size = mesh.FaceSize(f);
    for (int k = 0; k < size; ++k) {
      const int a = mesh.corner_vertices[begin + k],
                b = mesh.corner_vertices[begin + (k + 1) % size];
      neighbours[a].push_back(b);
      neighbours[b].push_back(a);
    }
  }
  Eigen::VectorXd dist =
      Eigen::VectorXd::Constant(v_count, std::numeric_limits<double>::infinity());
  using Item = std::pair<double, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  for (const auto& [v, d] : seeds) {
    if (d < dist[v]) {
      dist[v] = d;
      queue.emplace(d, v);
    }
  }
  while (!queue.empty()) {
    const auto [d, v] = queue.top();
    queue.pop();
    if (d > dist[v]) continue;
    for (int u : neighbours[v]) {
      const double nd = d + (mesh.positions_mm.col(u) - mesh.positions_mm.col(v)).norm();
      if (nd < dist[u]) {
        dist[u] = nd;
        queue.emplace(nd, u);
      }
    }
  }
  return dist;
}

Eigen::VectorXd MarkerRegions::WeightSums(int vertex_count) const {
  Eigen::VectorXd sums = Eigen::VectorXd::Zero(vertex_count);
  for (int r = 0; r < region_count(); ++r) {
    for (size_t k = 0; k < vertices[r].size(); ++k) sums[vertices[r][k]] += weights[r][k];
  }
  return sums;
}

StatusOr<MarkerRegions> ComputeMarkerRegions(const Mesh& neutral,
                                             const std::vector<SurfacePoint>& markers,
                                             double sigma_mm) {
  if (!(sigma_mm > 0 && std::isfinite(sigma_mm))) {
    return InvalidArgumentError(
        fmt::format("detail: region sigma_mm must be > 0, got {}", sigma_mm));
  }
  const int v_count = neutral.vertex_count();
  const int r_count = static_cast<int>(markers.size());
  if (r_count == 0) return InvalidArgumentError("detail: no markers to build regions from");
  MarkerRegions regions;
  regions.distances_mm.resize(r_count, v_count);
  for (int r = 0; r < r_count; ++r) {
    const SurfacePoint& p = markers[r];
    for (int k = 0; k < 3; ++k) {
      if (p.vertices[k] < 0 || p.vertices[k] >= v_count) {
        return InvalidArgumentError(
            fmt::format("detail: marker {} refers to vertex {}, the mesh has {} vertices", r,
                        p.vertices[k], v_count));
      }
    }
    const Eigen::Vector3d x = p.Evaluate(neutral.positions_mm);
    std::vector<std::pair<int, double>> seeds;
    for (int k = 0; k < 3; ++k)
      seeds.emplace_back(p.vertices[k], (neutral.positions_mm.col(p.vertices[k]) - x).norm());
    regions.distances_mm.row(r) = MeshGraphDistances(neutral, seeds).transpose();
  }
  regions.vertices.assign(r_count, {});
  regions.weights.assign(r_count, {});
  const double cutoff2 = 9.0 * sigma_mm * sigma_mm;
  std::vector<std::pair<int, double>> kept;
  for (int v = 0; v < v_count; ++v) {
    const Eigen::VectorXd d = regions.distances_mm.col(v);
    int nearest = 0;
    const double d_min = d.minCoeff(&nearest);
    kept.clear();
    double sum = 0;
    if (!std::isfinite(d_min)) {
      // A vertex no marker reaches along edges (a separate piece of mesh): its detail can not
      // be predicted; one region of weight 1 keeps the blend well defined (offsets are zero
      // there in training, so it learns zero).
      kept.emplace_back(0, 1.0);
      sum = 1.0;
    } else {
      for (int r = 0; r < r_count; ++r) {
        const double excess = d[r] * d[r] - d_min * d_min;
        if (excess > cutoff2) continue;
        const double g = std::exp(-excess / (2 * sigma_mm * sigma_mm));
        kept.emplace_back(r, g);
        sum += g;
      }
    }
    for (const auto& [r, g] : kept) {
      regions.vertices[r].push_back(v);
      regions.weights[r].push_back(g / sum);
    }
  }
  return regions;
}

}  // namespace facedyn::detail
