#include "physics/face_anatomy.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <queue>
#include <utility>

#include "core/check.h"

namespace facedyn::physics {
namespace {

// Regions whose thickness range is enforced, in the priority used when a vertex is in several
// (only lips/jaw overlap the primary regions, and they are not listed).
const char* const kThicknessRegions[] = {"eyes",        "mouth_corners", "upper_lip", "lower_lip",
                                         "nose_bridge", "nose",          "brows",     "forehead",
                                         "temples",     "chin",          "cheeks"};

double MeanEdgeLengthMm(const Mesh& mesh, const Eigen::Matrix3Xd& positions_mm) {
  double sum = 0.0;
  int count = 0;
  for (int f = 0; f < mesh.face_count(); ++f) {
    const int begin = mesh.face_offsets[f], end = mesh.face_offsets[f + 1];
    for (int c = begin; c < end; ++c) {
      const int a = mesh.corner_vertices[c];
      const int b = mesh.corner_vertices[c + 1 < end ? c + 1 : begin];
      sum += (positions_mm.col(a) - positions_mm.col(b)).norm();
      ++count;
    }
  }
  return count > 0 ? sum / count : 1.0;
}

// Number of Jacobi smoothing iterations that spread a value over about `radius_mm`
// (diffusion reaches ~sqrt(iterations) edges).
int DiffusionIterations(double radius_mm, double edge_mm, int max_iterations) {
  const double ratio = radius_mm / std::max(edge_mm, 1e-6);
  return std::clamp(static_cast<int>(std::lround(ratio * ratio)), 2, max_iterations);
}

// Unit normals smoothed over about `radius_mm` of the surface.
Eigen::Matrix3Xd SmoothedNormals(const Mesh& mesh, const std::vector<std::vector<int>>& neighbors,
                                 double radius_mm) {
  Eigen::Matrix3Xd normals = VertexNormals(mesh, mesh.positions_mm);
  const int iterations =
      DiffusionIterations(radius_mm, MeanEdgeLengthMm(mesh, mesh.positions_mm), 200);
  Eigen::Matrix3Xd next(3, normals.cols());
  for (int it = 0; it < iterations; ++it) {
    for (Eigen::Index v = 0; v < normals.cols(); ++v) {
      Eigen::Vector3d sum = normals.col(v);
      for (int w : neighbors[v]) sum += normals.col(w);
      const double n = sum.norm();
      next.col(v) = n > 1e-12 ? Eigen::Vector3d(sum / n) : Eigen::Vector3d(normals.col(v));
    }
    normals.swap(next);
  }
  return normals;
}

const std::vector<int>& RegionOrEmpty(const FaceRig& rig, const std::string& name) {
  static const std::vector<int> kEmpty;
  const auto it = rig.regions.find(name);
  return it == rig.regions.end() ? kEmpty : it->second;
}

// The vertex of `vertices` nearest to their centroid, or -1 when empty.
int CentralVertex(const Eigen::Matrix3Xd& positions, const std::vector<int>& vertices) {
  if (vertices.empty()) return -1;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int v : vertices) centroid += positions.col(v);
  centroid /= static_cast<double>(vertices.size());
  int best = vertices.front();
  double best_d = std::numeric_limits<double>::infinity();
  for (int v : vertices) {
    const double d = (positions.col(v) - centroid).squaredNorm();
    if (d < best_d) best_d = d, best = v;
  }
  return best;
}

}  // namespace

std::map<std::string, std::vector<int>> LabelFaceRegions(const Eigen::Matrix3Xd& positions_mm,
                                                         const Eigen::Matrix3Xd& normals,
                                                         const FaceLayout& layout,
                                                         const Eigen::VectorXd& jaw_weight) {
  FACEDYN_CHECK(normals.cols() == positions_mm.cols() && jaw_weight.size() == positions_mm.cols(),
                "one normal and one jaw weight per vertex");
  const FaceLayout& l = layout;
  std::map<std::string, std::vector<int>> regions;
  for (const char* name :
       {"forehead", "brows", "nose_bridge", "temples", "nose", "cheeks", "mouth_corners", "lips",
        "upper_lip", "lower_lip", "chin", "jaw", "eyes"}) {
    regions[name];
  }
  const double ex = l.eye_center_x_mm;
  for (Eigen::Index i = 0; i < positions_mm.cols(); ++i) {
    const int v = static_cast<int>(i);
    const double x = std::abs(positions_mm(0, i));
    const double y = positions_mm(1, i);
    const double nz = normals(2, i);
    if (jaw_weight[i] >= 0.5) regions["jaw"].push_back(v);
    if (x > l.temple_max_x_mm) continue;
    const double eye_u = (x - ex) / (l.eye_half_width_mm + 8.0);
    const double eye_v = (y - l.eye_center_y_mm) / (l.eye_half_height_mm + 7.0);
    const double lip_h = y >= l.mouth_y_mm ? 10.0 : 11.0;
    const double lip_u = x / (l.mouth_half_width_mm + 1.0);
    const double lip_v = (y - l.mouth_y_mm) / lip_h;
    // Nose half width grows from the bridge (9 mm) to the alae at the tip.
    const double nose_top = l.eye_center_y_mm - 6.0;
    const double s =
        std::clamp((nose_top - y) / std::max(nose_top - l.nose_tip_y_mm, 1.0), 0.0, 1.0);
    const double nose_half = 9.0 + s * (l.nose_half_width_mm - 9.0);
    const char* name = nullptr;
    if (eye_u * eye_u + eye_v * eye_v < 1.0) {
      name = "eyes";
    } else if (std::hypot(x - l.mouth_half_width_mm, y - l.mouth_y_mm) < 8.0) {
      name = "mouth_corners";
    } else if (lip_u * lip_u + lip_v * lip_v < 1.0 && nz > -0.2) {
      name = jaw_weight[i] >= 0.5 ? "lower_lip" : "upper_lip";
      regions["lips"].push_back(v);
    } else if (x < 0.4 * ex && y >= nose_top && y <= l.brow_y_mm + 6.0 && nz > 0.0) {
      name = "nose_bridge";
    } else if (y >= l.nose_tip_y_mm - 10.0 && y < nose_top && x < nose_half && nz > -0.2) {
      name = "nose";
    } else if (y >= l.brow_y_mm - 8.0 && y <= l.brow_y_mm + 9.0 && x < 1.9 * ex && nz > 0.2) {
      name = "brows";
    } else if (y > l.brow_y_mm + 9.0 && x < 1.6 * ex && nz > 0.3) {
      name = "forehead";
    } else if (y >= l.eye_center_y_mm - 5.0 && y <= l.brow_y_mm + 30.0 && x >= 1.65 * ex &&
               nz > -0.3) {
      name = "temples";
    } else if (y < l.mouth_y_mm - 18.0 && y > l.chin_y_mm - 5.0 && x < 28.0 && nz > 0.0) {
      name = "chin";
    } else if (y >= l.mouth_y_mm - 15.0 && y <= l.eye_center_y_mm - 9.0 && x < 2.1 * ex &&
               nz > 0.0) {
      name = "cheeks";
    }
    if (name != nullptr) regions[name].push_back(v);
  }
  return regions;
}

std::vector<int> JawFitVertices(const FaceRig& rig) {
  const auto jaw_it = rig.regions.find(rig.jaw.region);
  if (jaw_it == rig.regions.end()) return {};
  std::vector<bool> rigid(rig.vertex_count(), false);
  for (const char* name : {"chin", "cheeks"}) {
    for (int v : RegionOrEmpty(rig, name)) rigid[v] = true;
  }
  std::vector<int> fit;
  for (int v : jaw_it->second) {
    if (rigid[v]) fit.push_back(v);
  }
  return fit.empty() ? jaw_it->second : fit;
}

std::vector<std::vector<int>> VertexNeighbors(const Mesh& mesh) {
  std::vector<std::vector<int>> neighbors(mesh.vertex_count());
  for (int f = 0; f < mesh.face_count(); ++f) {
    const int begin = mesh.face_offsets[f], end = mesh.face_offsets[f + 1];
    for (int c = begin; c < end; ++c) {
      const int a = mesh.corner_vertices[c];
      const int b = mesh.corner_vertices[c + 1 < end ? c + 1 : begin];
      neighbors[a].push_back(b);
      neighbors[b].push_back(a);
    }
  }
  for (auto& list : neighbors) {
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
  }
  return neighbors;
}

namespace {

// Directed boundary edges a -> b (as they appear in their single face), keyed by a.
std::multimap<int, int> BoundaryEdges(const Mesh& mesh) {
  std::map<std::pair<int, int>, int> use;  // undirected edge -> count
  std::vector<std::pair<int, int>> directed;
  for (int f = 0; f < mesh.face_count(); ++f) {
    const int begin = mesh.face_offsets[f], end = mesh.face_offsets[f + 1];
    for (int c = begin; c < end; ++c) {
      const int a = mesh.corner_vertices[c];
      const int b = mesh.corner_vertices[c + 1 < end ? c + 1 : begin];
      ++use[{std::min(a, b), std::max(a, b)}];
      directed.emplace_back(a, b);
    }
  }
  std::multimap<int, int> edges;
  for (const auto& [a, b] : directed) {
    if (use[{std::min(a, b), std::max(a, b)}] == 1) edges.emplace(a, b);
  }
  return edges;
}

}  // namespace

std::vector<bool> BoundaryVertices(const Mesh& mesh) {
  std::vector<bool> boundary(mesh.vertex_count(), false);
  for (const auto& [a, b] : BoundaryEdges(mesh)) boundary[a] = boundary[b] = true;
  return boundary;
}

std::vector<std::vector<int>> BoundaryLoops(const Mesh& mesh) {
  std::multimap<int, int> edges = BoundaryEdges(mesh);
  std::vector<std::vector<int>> loops;
  while (!edges.empty()) {
    auto it = edges.begin();
    const int start = it->first;
    std::vector<int> loop{start};
    int next = it->second;
    edges.erase(it);
    while (next != start) {
      loop.push_back(next);
      auto found = edges.find(next);
      if (found == edges.end()) break;  // open chain (non-manifold input): stop here
      next = found->second;
      edges.erase(found);
    }
    loops.push_back(std::move(loop));
  }
  return loops;
}

const std::map<std::string, ThicknessRange>& RegionThicknessRanges() {
  static const std::map<std::string, ThicknessRange> kRanges = {
      {"forehead", {4.0, 5.0, 6.0}},     {"brows", {4.0, 6.0, 7.0}},
      {"nose_bridge", {3.0, 4.0, 5.0}},  {"nose", {2.0, 3.0, 4.0}},
      {"temples", {5.0, 6.5, 8.0}},      {"eyes", {4.0, 5.5, 7.0}},
      {"cheeks", {12.0, 16.0, 20.0}},    {"mouth_corners", {10.0, 13.0, 16.0}},
      {"upper_lip", {10.0, 12.0, 14.0}}, {"lower_lip", {10.0, 12.0, 14.0}},
      {"chin", {8.0, 10.0, 12.0}},
  };
  return kRanges;
}

namespace {

// Index into kThicknessRegions of each vertex's region, or -1.
std::vector<int> ThicknessClasses(const FaceRig& rig) {
  const int n = rig.vertex_count();
  std::vector<int> label(n, -1);
  int k = 0;
  for (const char* name : kThicknessRegions) {
    for (int v : RegionOrEmpty(rig, name)) {
      if (v >= 0 && v < n && label[v] < 0) label[v] = k;
    }
    ++k;
  }
  return label;
}

}  // namespace

std::vector<double> ThicknessBorderDistanceMm(const FaceRig& rig) {
  const int n = rig.vertex_count();
  const Eigen::Matrix3Xd& p = rig.neutral.positions_mm;
  const std::vector<int> label = ThicknessClasses(rig);
  const auto neighbors = VertexNeighbors(rig.neutral);
  // Multi-source Dijkstra along edges from every vertex that touches another class.
  std::vector<double> distance(n, std::numeric_limits<double>::infinity());
  using Item = std::pair<double, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  for (int v = 0; v < n; ++v) {
    for (int w : neighbors[v]) {
      if (label[w] != label[v]) {
        distance[v] = 0.0;
        queue.emplace(0.0, v);
        break;
      }
    }
  }
  while (!queue.empty()) {
    const auto [d, v] = queue.top();
    queue.pop();
    if (d > distance[v]) continue;
    for (int w : neighbors[v]) {
      if (label[w] != label[v]) continue;
      const double next = d + (p.col(v) - p.col(w)).norm();
      if (next < distance[w]) {
        distance[w] = next;
        queue.emplace(next, w);
      }
    }
  }
  return distance;
}

Eigen::VectorXd TissueThicknessMm(const FaceRig& rig) {
  const Mesh& mesh = rig.neutral;
  const int n = mesh.vertex_count();
  const auto& ranges = RegionThicknessRanges();
  const std::vector<int> label = ThicknessClasses(rig);
  const std::vector<double> border = ThicknessBorderDistanceMm(rig);
  Eigen::VectorXd lo = Eigen::VectorXd::Constant(n, -std::numeric_limits<double>::infinity());
  Eigen::VectorXd hi = Eigen::VectorXd::Constant(n, std::numeric_limits<double>::infinity());
  Eigen::VectorXd t = Eigen::VectorXd::Constant(n, kDefaultThicknessMm);
  for (int v = 0; v < n; ++v) {
    if (label[v] < 0) continue;
    const ThicknessRange& range = ranges.at(kThicknessRegions[label[v]]);
    t[v] = range.target_mm;
    if (border[v] >= kThicknessBlendMm) lo[v] = range.min_mm, hi[v] = range.max_mm;
  }
  const auto neighbors = VertexNeighbors(mesh);
  const int iterations = DiffusionIterations(15.0, MeanEdgeLengthMm(mesh, mesh.positions_mm), 200);
  Eigen::VectorXd next(n);
  for (int it = 0; it < iterations; ++it) {
    for (int v = 0; v < n; ++v) {
      double sum = 0.0;
      for (int w : neighbors[v]) sum += t[w];
      const double mean = neighbors[v].empty() ? t[v] : sum / neighbors[v].size();
      next[v] = std::clamp(0.5 * (t[v] + mean), lo[v], hi[v]);
    }
    t.swap(next);
  }
  return t;
}

Status AnatomyOptions::Check() const {
  if (skin_sample_count < 1 || skin_sample_count > 100000) {
    return InvalidArgumentError(
        fmt::format("skin_sample_count: {} is outside 1..100000", skin_sample_count));
  }
  if (marker_count < 0 || marker_count > 100000) {
    return InvalidArgumentError(fmt::format("marker_count: {} is outside 0..100000", marker_count));
  }
  if (!(marker_diameter_mm > 0.0) || !std::isfinite(marker_diameter_mm) ||
      marker_diameter_mm > 50.0) {
    return InvalidArgumentError(
        fmt::format("marker_diameter_mm: {} is not in (0, 50] mm", marker_diameter_mm));
  }
  return Status::Ok();
}

double FitHingeAngleRad(const Eigen::Matrix3Xd& points_mm, const Eigen::Matrix3Xd& deltas_mm,
                        const Eigen::Vector3d& axis, const Eigen::Vector3d& pivot_mm) {
  FACEDYN_CHECK(points_mm.cols() == deltas_mm.cols(), "one delta per point");
  const Eigen::Vector3d e1 = axis.unitOrthogonal();
  const Eigen::Vector3d e2 = axis.cross(e1);
  double cross = 0.0, dot = 0.0;
  for (Eigen::Index i = 0; i < points_mm.cols(); ++i) {
    const Eigen::Vector3d a3 = points_mm.col(i) - pivot_mm;
    const Eigen::Vector3d b3 = a3 + deltas_mm.col(i);
    const Eigen::Vector2d a(a3.dot(e1), a3.dot(e2)), b(b3.dot(e1), b3.dot(e2));
    cross += a.x() * b.y() - a.y() * b.x();
    dot += a.dot(b);
  }
  return std::atan2(cross, dot);
}

std::vector<int> FarthestPointSample(const Eigen::Matrix3Xd& positions_mm,
                                     const std::vector<int>& candidates, int count, uint64_t seed) {
  FACEDYN_CHECK(count >= 0 && static_cast<size_t>(count) <= candidates.size(),
                "cannot sample more points than candidates");
  std::vector<int> picked;
  if (count == 0) return picked;
  picked.reserve(count);
  std::vector<double> distance(candidates.size(), std::numeric_limits<double>::infinity());
  size_t current = static_cast<size_t>(seed % candidates.size());
  for (int k = 0; k < count; ++k) {
    picked.push_back(candidates[current]);
    const Eigen::Vector3d p = positions_mm.col(candidates[current]);
    size_t farthest = 0;
    double farthest_d = -1.0;
    for (size_t c = 0; c < candidates.size(); ++c) {
      const double d = (positions_mm.col(candidates[c]) - p).squaredNorm();
      if (d < distance[c]) distance[c] = d;
      if (distance[c] > farthest_d) farthest_d = distance[c], farthest = c;
    }
    current = farthest;
  }
  return picked;
}

Status CompleteFaceAnatomy(const AnatomyOptions& options, FaceRig* rig) {
  FACEDYN_CHECK(rig != nullptr, "CompleteFaceAnatomy needs a rig");
  FACEDYN_RETURN_IF_ERROR(options.Check());
  const std::string what = "face rig '" + rig->name + "'";
  if (rig->neutral.vertex_count() == 0 || rig->neutral.face_count() == 0) {
    return FailedPreconditionError(what + ": the neutral mesh is empty");
  }
  FACEDYN_RETURN_IF_ERROR(rig->neutral.Validate(what + " neutral mesh"));
  for (const char* name : {"forehead", "nose_bridge", "temples"}) {
    if (RegionOrEmpty(*rig, name).empty()) {
      return FailedPreconditionError(
          fmt::format("{}: region '{}' is missing or empty; anatomy needs it", what, name));
    }
  }
  const Mesh& skin = rig->neutral;
  const Eigen::Matrix3Xd& p = skin.positions_mm;
  const int n = skin.vertex_count();
  const auto neighbors = VertexNeighbors(skin);

  // Skull: the skin moved inward along smoothed normals by the tissue thickness.
  const Eigen::VectorXd thickness = TissueThicknessMm(*rig);
  const Eigen::Matrix3Xd inward = SmoothedNormals(skin, neighbors, 12.0);
  rig->skull = skin;
  for (int v = 0; v < n; ++v)
    rig->skull.positions_mm.col(v) = p.col(v) - thickness[v] * inward.col(v);

  // Landmarks b1..b5 on the cranium.
  const Eigen::Matrix3Xd& skull = rig->skull.positions_mm;
  const auto& forehead = RegionOrEmpty(*rig, "forehead");
  int top = forehead.front();  // highest on the midline
  for (int v : forehead) {
    if (p(1, v) - std::abs(p(0, v)) > p(1, top) - std::abs(p(0, top))) top = v;
  }
  std::vector<int> left_temple, right_temple;
  for (int v : RegionOrEmpty(*rig, "temples"))
    (p(0, v) > 0 ? left_temple : right_temple).push_back(v);
  if (left_temple.empty() || right_temple.empty()) {
    return FailedPreconditionError(what + ": region 'temples' must have vertices on both sides");
  }
  const int nasion = CentralVertex(p, RegionOrEmpty(*rig, "nose_bridge"));
  const Eigen::Vector3d b1 = skull.col(top);
  const Eigen::Vector3d crown_direction = Eigen::Vector3d(0.0, 0.77, -0.64).normalized();
  rig->skull_landmarks = {
      {"b1", b1},
      {"b2", skull.col(CentralVertex(p, left_temple))},
      {"b3", skull.col(CentralVertex(p, right_temple))},
      {"b4", skull.col(nasion)},
      {"b5", b1.norm() * crown_direction},
  };

  // Sample candidates: off every boundary, facing forward, within the labelled face's width.
  const std::vector<bool> boundary = BoundaryVertices(skin);
  const Eigen::Matrix3Xd normals = VertexNormals(skin, p);
  double max_x = 0.0;
  for (const auto& [name, vertices] : rig->regions) {
    if (name == "jaw") continue;
    for (int v : vertices) max_x = std::max(max_x, std::abs(p(0, v)));
  }
  std::vector<bool> in_eyes(n, false);
  for (int v : RegionOrEmpty(*rig, "eyes")) in_eyes[v] = true;
  std::vector<int> sample_candidates, marker_candidates;
  for (int v = 0; v < n; ++v) {
    if (boundary[v] || normals(2, v) <= 0.0 || std::abs(p(0, v)) > max_x) continue;
    sample_candidates.push_back(v);
    if (!in_eyes[v] && normals(2, v) > 0.2) marker_candidates.push_back(v);
  }
  if (static_cast<int>(sample_candidates.size()) < options.skin_sample_count ||
      static_cast<int>(marker_candidates.size()) < options.marker_count) {
    return FailedPreconditionError(
        fmt::format("{}: {} skin samples and {} markers requested, but the face has only {} and {} "
                    "candidate vertices",
                    what, options.skin_sample_count, options.marker_count, sample_candidates.size(),
                    marker_candidates.size()));
  }
  rig->skin_samples.clear();
  for (int v : FarthestPointSample(p, sample_candidates, options.skin_sample_count, options.seed)) {
    rig->skin_samples.push_back(SurfacePoint::AtVertex(v));
  }
  rig->markers.clear();
  const std::vector<int> marker_vertices =
      FarthestPointSample(p, marker_candidates, options.marker_count, options.seed + 1);
  for (size_t k = 0; k < marker_vertices.size(); ++k) {
    rig->markers.push_back({fmt::format("m{:03d}", k), SurfacePoint::AtVertex(marker_vertices[k]),
                            options.marker_diameter_mm});
  }
  rig->stable_regions = {"forehead", "nose_bridge", "temples"};
  return Status::Ok();
}

}  // namespace facedyn::physics
