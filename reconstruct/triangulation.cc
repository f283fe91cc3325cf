#include "reconstruct/triangulation.h"

#include <ceres/jet.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_map>

namespace facedyn::reconstruct {
namespace {

struct Grid {
  double cell_px = 8.0;
  std::unordered_map<uint64_t, std::vector<int>> cells;
  uint64_t Key(int x, int y) const {
    return (static_cast<uint64_t>(static_cast<uint32_t>(x)) << 32) | static_cast<uint32_t>(y);
  }
  void Insert(const Eigen::Vector2d& p, int index) {
    cells[Key(static_cast<int>(std::floor(p.x() / cell_px)),
              static_cast<int>(std::floor(p.y() / cell_px)))]
        .push_back(index);
  }
  // Nearest indexed point within radius (-1 if none), skipping `used`.
  int Nearest(const Eigen::Vector2d& p, double radius, const std::vector<ImageObservation>& points,
              const std::vector<char>& used, double* distance) const {
    const int x0 = static_cast<int>(std::floor((p.x() - radius) / cell_px));
    const int x1 = static_cast<int>(std::floor((p.x() + radius) / cell_px));
    const int y0 = static_cast<int>(std::floor((p.y() - radius) / cell_px));
    const int y1 = static_cast<int>(std::floor((p.y() + radius) / cell_px));
    int best = -1;
    double best_d = radius;
    for (int x = x0; x <= x1; ++x) {
      for (int y = y0; y <= y1; ++y) {
        const auto it = cells.find(Key(x, y));
        if (it == cells.end()) continue;
        for (int i : it->second) {
          if (used[i]) continue;
          const double d = (points[i].pixel - p).norm();
          if (d <= best_d) {
            best_d = d;
            best = i;
          }
        }
      }
    }
    if (distance) *distance = best_d;
    return best;
  }
};

// Projection and its 2x3 Jacobian with respect to the world point (autodiff through the lens).
bool ProjectWithJacobian(const Camera& camera, const Eigen::Vector3d& point, Eigen::Vector2d* pixel,
                         Eigen::Matrix<double, 2, 3>* jacobian) {
  using Jet = ceres::Jet<double, 3>;
  const Jet p[3] = {Jet(point.x(), 0), Jet(point.y(), 1), Jet(point.z(), 2)};
  const PointReprojectionResidual residual(camera, Eigen::Vector2d::Zero());
  Jet r[2];
  residual(p, r);
  // residual = 0 - projection
  *pixel = Eigen::Vector2d(-r[0].a, -r[1].a);
  jacobian->row(0) = -r[0].v.transpose();
  jacobian->row(1) = -r[1].v.transpose();
  return (camera.cam_from_world * point).z() > 1e-6 && pixel->allFinite();
}

}  // namespace

namespace {

// One view of the linear triangulation: its camera and the observation in normalised
// (undistorted) coordinates.
struct NormalizedView {
  const Camera* camera;
  Eigen::Vector2d normalized;
  double weight;
};

// The linear (DLT) system A [x; 1] = 0 of the stacked 2N x 4 rows, solved for the
// inhomogeneous point: with A^T A = [M b; b^T c], x = -M^-1 b (Hartley & Zisserman, section
// 12.2; the same point as the homogeneous null vector without noise, and a start the
// refinement takes to the same minimum with it). A 3 x 3 solve: correspondence triangulates
// every epipolar hypothesis, and the 4 x 4 eigen-decomposition it replaces was the largest
// part of that. The rows are in normalised coordinates, so M stays well conditioned; rays too
// close to parallel (M near singular) are refused.
bool TriangulateNormalized(const NormalizedView* views, size_t count,
                           Eigen::Vector3d* point_in_world) {
  Eigen::Matrix4d ata = Eigen::Matrix4d::Zero();
  for (size_t i = 0; i < count; ++i) {
    const Camera& camera = *views[i].camera;
    const Eigen::Vector2d& n = views[i].normalized;
    Eigen::Matrix<double, 3, 4> pose;
    pose.leftCols<3>() = camera.cam_from_world.RotationMatrix();
    pose.col(3) = camera.cam_from_world.translation();
    const double w = std::max(1e-3, views[i].weight);
    Eigen::Matrix<double, 2, 4> rows;
    rows.row(0) = w * (n.x() * pose.row(2) - pose.row(0));
    rows.row(1) = w * (n.y() * pose.row(2) - pose.row(1));
    ata.noalias() += rows.transpose() * rows;
  }
  const Eigen::Matrix3d m = ata.topLeftCorner<3, 3>();
  const double scale = m.trace();
  if (!(std::abs(m.determinant()) > 1e-12 * scale * scale * scale)) return false;
  *point_in_world = -m.inverse() * ata.topRightCorner<3, 1>();
  for (size_t i = 0; i < count; ++i) {
    if ((views[i].camera->cam_from_world * *point_in_world).z() <= 0) return false;
  }
  return point_in_world->allFinite();
}

}  // namespace

bool TriangulateLinear(const std::vector<Camera>& cameras,
                       const std::vector<ImageObservation>& observations,
                       Eigen::Vector3d* point_in_world) {
  if (observations.size() < 2) return false;
  std::vector<NormalizedView> views;
  views.reserve(observations.size());
  for (const ImageObservation& o : observations) {
    const Camera& camera = cameras[o.camera];
    views.push_back({&camera, camera.Undistort(o.pixel), o.weight});
  }
  return TriangulateNormalized(views.data(), views.size(), point_in_world);
}

bool RefinePoint(const std::vector<Camera>& cameras, std::vector<ImageObservation> observations,
                 const Eigen::Vector3d& initial, double reprojection_px, int min_views,
                 TriangulatedPoint* point) {
  Eigen::Vector3d x = initial;
  for (int round = 0; round < 4; ++round) {
    if (static_cast<int>(observations.size()) < min_views) return false;
    for (int iteration = 0; iteration < 10; ++iteration) {
      Eigen::Matrix3d jtj = Eigen::Matrix3d::Zero();
      Eigen::Vector3d jtr = Eigen::Vector3d::Zero();
      for (const ImageObservation& o : observations) {
        Eigen::Vector2d pixel;
        Eigen::Matrix<double, 2, 3> j;
        if (!ProjectWithJacobian(cameras[o.camera], x, &pixel, &j)) return false;
        const double w = std::max(1e-3, o.weight);
        jtj.noalias() += w * j.transpose() * j;
        jtr.noalias() += w * j.transpose() * (o.pixel - pixel);
      }
      const Eigen::Vector3d step = jtj.ldlt().solve(jtr);
      if (!step.allFinite()) return false;
      x += step;
      if (step.norm() < 1e-7) break;
    }
    // Drop the worst view if it is beyond the threshold, then re-solve.
    double worst = -1.0;
    size_t worst_index = 0;
    for (size_t i = 0; i < observations.size(); ++i) {
      Eigen::Vector2d pixel;
      if (!cameras[observations[i].camera].Project(x, &pixel)) return false;
      const double e = (pixel - observations[i].pixel).norm();
      if (e > worst) {
        worst = e;
        worst_index = i;
      }
    }
    if (worst <= reprojection_px) break;
    observations.erase(observations.begin() + static_cast<long>(worst_index));
  }
  if (static_cast<int>(observations.size()) < min_views) return false;
  double sq = 0.0, max_px = 0.0;
  for (const ImageObservation& o : observations) {
    Eigen::Vector2d pixel;
    if (!cameras[o.camera].Project(x, &pixel)) return false;
    const double e = (pixel - o.pixel).norm();
    sq += e * e;
    max_px = std::max(max_px, e);
  }
  if (max_px > reprojection_px) return false;
  point->position_in_world = x;
  point->rms_px = std::sqrt(sq / observations.size());
  point->max_px = max_px;
  point->observations = std::move(observations);
  point->confidence =
      std::min(1.0, point->observations.size() / 4.0) * std::exp(-std::pow(point->rms_px / 0.5, 2));
  return true;
}

Status CorrespondenceOptions::Check() const {
  if (!(epipolar_px > 0)) return InvalidArgumentError("epipolar_px must be > 0");
  if (!(reprojection_px > 0)) return InvalidArgumentError("reprojection_px must be > 0");
  if (min_views < 2) return InvalidArgumentError("min_views must be >= 2");
  if (!(max_rms_px > 0)) return InvalidArgumentError("max_rms_px must be > 0");
  if (!(min_depth_mm > 0 && max_depth_mm > min_depth_mm)) {
    return InvalidArgumentError("need 0 < min_depth_mm < max_depth_mm");
  }
  return Status::Ok();
}

std::vector<TriangulatedPoint> TriangulateDetections(
    const std::vector<Camera>& cameras,
    const std::vector<std::vector<ImageObservation>>& detections,
    const CorrespondenceOptions& options, TriangulationSummary* summary_out) {
  TriangulationSummary local;
  TriangulationSummary& summary = summary_out ? *summary_out : local;
  summary = TriangulationSummary();
  const int n = static_cast<int>(cameras.size());
  FACEDYN_CHECK(static_cast<int>(detections.size()) == n, "one detection list per camera");
  std::vector<std::vector<Eigen::Vector2d>> normalized(n);
  std::vector<Grid> grids(n);
  std::vector<std::vector<char>> used(n);
  for (int c = 0; c < n; ++c) {
    used[c].assign(detections[c].size(), 0);
    for (int i = 0; i < static_cast<int>(detections[c].size()); ++i) {
      normalized[c].push_back(cameras[c].Undistort(detections[c][i].pixel));
      grids[c].Insert(detections[c][i].pixel, i);
    }
    summary.detections += static_cast<int>(detections[c].size());
  }
  // Camera pairs by decreasing baseline angle (viewing directions), up to 75 degrees.
  struct Pair {
    int a, b;
    double angle;
  };
  std::vector<Pair> pairs;
  for (int a = 0; a < n; ++a) {
    for (int b = a + 1; b < n; ++b) {
      const Eigen::Vector3d za =
          cameras[a].cam_from_world.Inverse().RotateVector(Eigen::Vector3d::UnitZ());
      const Eigen::Vector3d zb =
          cameras[b].cam_from_world.Inverse().RotateVector(Eigen::Vector3d::UnitZ());
      const double angle = std::acos(std::clamp(za.dot(zb), -1.0, 1.0));
      if (angle < 75.0 * M_PI / 180.0) pairs.push_back({a, b, angle});
    }
  }
  std::sort(pairs.begin(), pairs.end(),
            [](const Pair& x, const Pair& y) { return x.angle > y.angle; });

  std::vector<TriangulatedPoint> points;
  std::vector<TriangulatedPoint> hypotheses;
  // member_of[c][i]: the hypotheses that already contain detection i of camera c. A marker
  // seen by k cameras is found from each of its k(k-1)/2 camera pairs; once one pair's
  // hypothesis holds both detections of another pair, that pair would triangulate, verify and
  // refine the same point again (most of correspondence's time on an 8-camera rig), so it is
  // skipped.
  std::vector<std::vector<std::vector<int>>> member_of(n);
  for (int c = 0; c < n; ++c) member_of[c].resize(detections[c].size());
  const auto already_hypothesised = [&](int a, int i, int b, int j) {
    for (int h : member_of[a][i]) {
      if (std::find(member_of[b][j].begin(), member_of[b][j].end(), h) != member_of[b][j].end()) {
        return true;
      }
    }
    return false;
  };
  for (const Pair& pair : pairs) {
    const Camera& ca = cameras[pair.a];
    const Camera& cb = cameras[pair.b];
    // Essential matrix of b_from_a: x_b^T E x_a = 0 for normalised coordinates.
    const Rigid3 b_from_a = cb.cam_from_world * ca.cam_from_world.Inverse();
    const Eigen::Vector3d t = b_from_a.translation();
    Eigen::Matrix3d tx;
    tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
    const Eigen::Matrix3d essential = tx * b_from_a.RotationMatrix();
    const double focal_b = 0.5 * (cb.fx() + cb.fy());
    for (int i = 0; i < static_cast<int>(detections[pair.a].size()); ++i) {
      const Eigen::Vector3d xa(normalized[pair.a][i].x(), normalized[pair.a][i].y(), 1.0);
      const Eigen::Vector3d line = essential * xa;
      const double line_norm = line.head<2>().norm();
      if (line_norm < 1e-15) continue;
      for (int j = 0; j < static_cast<int>(detections[pair.b].size()); ++j) {
        const Eigen::Vector3d xb(normalized[pair.b][j].x(), normalized[pair.b][j].y(), 1.0);
        if (std::abs(xb.dot(line)) / line_norm * focal_b > options.epipolar_px) continue;
        if (already_hypothesised(pair.a, i, pair.b, j)) {
          ++summary.repeated_pairs;
          continue;
        }
        std::vector<ImageObservation> observations = {detections[pair.a][i], detections[pair.b][j]};
        observations[0].camera = pair.a;
        observations[0].detection = i;
        observations[1].camera = pair.b;
        observations[1].detection = j;
        // The pair's linear point from the normalised coordinates already at hand (undistorting
        // again per hypothesis was most of correspondence's time).
        Eigen::Vector3d x;
        const NormalizedView pair_views[2] = {
            NormalizedView{&ca, normalized[pair.a][i], detections[pair.a][i].weight},
            NormalizedView{&cb, normalized[pair.b][j], detections[pair.b][j].weight}};
        if (!TriangulateNormalized(pair_views, 2, &x)) continue;
        const double depth = (ca.cam_from_world * x).z();
        if (depth < options.min_depth_mm || depth > options.max_depth_mm) continue;
        for (int c = 0; c < n; ++c) {
          if (c == pair.a || c == pair.b) continue;
          Eigen::Vector2d pixel;
          if (!cameras[c].Project(x, &pixel) || !cameras[c].InImage(pixel)) continue;
          const int k = grids[c].Nearest(pixel, 2.0 * options.reprojection_px, detections[c],
                                         used[c], nullptr);
          if (k < 0) continue;
          ImageObservation o = detections[c][k];
          o.camera = c;
          o.detection = k;
          observations.push_back(o);
        }
        ++summary.hypotheses;
        if (static_cast<int>(observations.size()) < options.min_views) continue;
        TriangulatedPoint point;
        if (!RefinePoint(cameras, observations, x, options.reprojection_px, options.min_views,
                         &point) ||
            point.rms_px > options.max_rms_px) {
          continue;
        }
        for (const ImageObservation& o : point.observations) {
          member_of[o.camera][o.detection].push_back(static_cast<int>(hypotheses.size()));
        }
        hypotheses.push_back(std::move(point));
      }
    }
  }
  // Accept globally best-first (a weak 3-view coincidence found early must not take the
  // detections of a 6-view point found from a later pair). A hypothesis that lost some views
  // to better ones is re-refined on the rest and tried again if it still has enough.
  auto better = [](const TriangulatedPoint& x, const TriangulatedPoint& y) {
    if (x.observations.size() != y.observations.size()) {
      return x.observations.size() > y.observations.size();
    }
    return x.rms_px < y.rms_px;
  };
  for (int round = 0; round < 2; ++round) {
    std::sort(hypotheses.begin(), hypotheses.end(), better);
    std::vector<TriangulatedPoint> retry;
    for (TriangulatedPoint& h : hypotheses) {
      std::vector<ImageObservation> free;
      for (const ImageObservation& o : h.observations) {
        if (!used[o.camera][o.detection]) free.push_back(o);
      }
      if (free.size() == h.observations.size()) {
        for (const ImageObservation& o : h.observations) used[o.camera][o.detection] = 1;
        points.push_back(std::move(h));
      } else if (static_cast<int>(free.size()) >= options.min_views) {
        TriangulatedPoint again;
        if (RefinePoint(cameras, free, h.position_in_world, options.reprojection_px,
                        options.min_views, &again) &&
            again.rms_px <= options.max_rms_px) {
          retry.push_back(std::move(again));
        }
      }
    }
    hypotheses = std::move(retry);
  }
  summary.points = static_cast<int>(points.size());
  for (int c = 0; c < n; ++c) {
    for (char u : used[c]) summary.unused_detections += u ? 0 : 1;
  }
  return points;
}

}  // namespace facedyn::reconstruct
