// Multi-view correspondence and triangulation of marker detections.
//
// Triangulation of one point from N >= 2 views: linear (DLT on undistorted normalised
// coordinates, rows weighted by the detection quality; the null vector from the 4x4 normal
// matrix), then Gauss-Newton on the reprojection error in pixels through the full lens model,
// dropping views whose residual exceeds `reprojection_px` and re-solving.
//
// Correspondence (which detections in which cameras are the same marker) uses the epipolar
// constraint and verification in further views: for every camera pair whose viewing
// directions differ by less than 75 degrees, every pair of detections within `epipolar_px` of
// each other's epipolar line is triangulated and projected into every other camera; the
// nearest detection within 2 `reprojection_px` of the projection supports it. A pair whose two
// detections are already in one hypothesis is not tried again (it would find the same point).
// Hypotheses with at least `min_views` views are refined, then accepted globally best-first
// (most views, then lowest RMS) while none of their detections is taken; one that lost views
// to a better one is re-refined on the rest and tried again. Global order matters: a 3-view
// coincidence must not take the detections of a 6-view point. Two views alone cannot tell a
// true match from an accidental epipolar coincidence, so min_views defaults to 3.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/status.h"
#include "reconstruct/camera.h"

namespace facedyn::reconstruct {

struct ImageObservation {
  int camera = 0;
  int detection = 0;  // index into that camera's detections (-1 when not from a detector)
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
  double weight = 1.0;
};

// Linear triangulation. False when the system is degenerate (fewer than 2 views, parallel
// rays) or the point is not in front of every camera.
bool TriangulateLinear(const std::vector<Camera>& cameras,
                       const std::vector<ImageObservation>& observations,
                       Eigen::Vector3d* point_in_world);

// Residual of one observation (Ceres autodiff functor): observed - projection of the point.
struct PointReprojectionResidual {
  PointReprojectionResidual(const Camera& camera, const Eigen::Vector2d& observed_px)
      : camera_(camera), observed_px_(observed_px) {}
  template <typename T>
  bool operator()(const T* point_in_world, T* residual) const;

 private:
  const Camera& camera_;
  Eigen::Vector2d observed_px_;
};

struct TriangulatedPoint {
  Eigen::Vector3d position_in_world = Eigen::Vector3d::Zero();
  std::vector<ImageObservation> observations;  // inliers
  double rms_px = 0.0;
  double max_px = 0.0;
  // min(1, views / 4) * exp(-(rms / 0.5 px)^2): more views and a tighter fit, more trust.
  double confidence = 0.0;
};

// Weighted Gauss-Newton refinement from `initial`, with outlier views removed (see above).
// False when fewer than `min_views` views remain.
bool RefinePoint(const std::vector<Camera>& cameras, std::vector<ImageObservation> observations,
                 const Eigen::Vector3d& initial, double reprojection_px, int min_views,
                 TriangulatedPoint* point);

struct CorrespondenceOptions {
  double epipolar_px = 2.0;
  double reprojection_px = 1.5;
  int min_views = 3;
  double max_rms_px = 1.0;
  double min_depth_mm = 50.0;
  double max_depth_mm = 5000.0;
  Status Check() const;
};

struct TriangulationSummary {
  int detections = 0;
  int hypotheses = 0;
  int repeated_pairs = 0;  // epipolar pairs skipped: both detections already in one hypothesis
  int points = 0;
  int unused_detections = 0;
};

// Points from per-camera 2D detections (pixels; weights = detection quality in [0, 1]).
// detections[c] are camera c's.
std::vector<TriangulatedPoint> TriangulateDetections(
    const std::vector<Camera>& cameras,
    const std::vector<std::vector<ImageObservation>>& detections,
    const CorrespondenceOptions& options, TriangulationSummary* summary = nullptr);

template <typename T>
bool PointReprojectionResidual::operator()(const T* point_in_world, T* residual) const {
  const Eigen::Matrix3d r = camera_.cam_from_world.RotationMatrix();
  const Eigen::Vector3d t = camera_.cam_from_world.translation();
  T in_cam[3];
  for (int i = 0; i < 3; ++i) {
    in_cam[i] = T(t[i]) + T(r(i, 0)) * point_in_world[0] + T(r(i, 1)) * point_in_world[1] +
                T(r(i, 2)) * point_in_world[2];
  }
  T intrinsics[kIntrinsicCount];
  for (int i = 0; i < kIntrinsicCount; ++i) intrinsics[i] = T(camera_.intrinsics[i]);
  T u, v;
  DistortAndScale(intrinsics, in_cam[0] / in_cam[2], in_cam[1] / in_cam[2], &u, &v);
  residual[0] = T(observed_px_.x()) - u;
  residual[1] = T(observed_px_.y()) - v;
  return true;
}

}  // namespace facedyn::reconstruct
