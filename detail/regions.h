// Marker regions with soft boundaries (Masquerade, Moser et al. 2017: "segmenting the face into
// small regions, one per marker ... regions have soft boundaries and their results are blended
// using geodesic weights for each vertex").
//
// Geodesic distance is approximated by the shortest path along mesh edges (Dijkstra on the
// neutral's edge lengths, mm), seeded at each marker's three vertices with their straight-line
// distance to the marker. Vertex v's weight for region r is a Gaussian falloff relative to its
// nearest marker,
//   g_rv = exp(-(d_rv^2 - d_min,v^2) / (2 sigma^2))   for d_rv^2 - d_min,v^2 <= (3 sigma)^2,
// normalised so that sum_r w_rv = 1 at every vertex. Measuring from the nearest marker keeps
// vertices far from every marker (ears, back of the head) well defined instead of underflowing.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/face_rig.h"
#include "core/mesh.h"
#include "core/status.h"

namespace facedyn::detail {

// Edge-path distances (mm) from a set of seeds (vertex, initial distance) to every vertex;
// +inf where no path exists.
Eigen::VectorXd MeshGraphDistances(const Mesh& mesh,
                                   const std::vector<std::pair<int, double>>& seeds);

struct MarkerRegions {
  // One entry per marker: the vertices with a non-zero weight and their weights.
  std::vector<std::vector<int>> vertices;
  std::vector<std::vector<double>> weights;
  // distances_mm(r, v): edge-path distance from marker r to vertex v.
  Eigen::MatrixXd distances_mm;

  int region_count() const { return static_cast<int>(vertices.size()); }
  // Sum over regions of each vertex's weight (1 everywhere by construction; for tests).
  Eigen::VectorXd WeightSums(int vertex_count) const;
};

// Precondition: sigma_mm > 0 (checked: an error names it).
StatusOr<MarkerRegions> ComputeMarkerRegions(const Mesh& neutral,
                                             const std::vector<SurfacePoint>& markers,
                                             double sigma_mm);

}  // namespace facedyn::detail
