// Multi-camera calibration from planar targets: per-camera intrinsics and distortion, then all
// cameras' extrinsics jointly by bundle adjustment (Ceres) over every board corner seen, with
// robust loss and iterative outlier rejection.
//
// Model: pixel = DistortAndScale(K_c, cam_from_world_c * world_from_board_v * X_i) for
// corner i of the board in view v (a view is one instant: every camera that saw the board at
// that instant sees the same board pose). The world frame is camera 0's frame (camera 0's
// cam_from_world is the identity); rotate/translate afterwards if another world is wanted.
//
// Steps: (1) per camera: focal length from the views' homographies (cv::initCameraMatrix2D,
// principal point at the centre, no distortion), board poses by PnP, then a Ceres refinement of
// fx, fy, cx, cy, k1, k2, p1, p2, k3 and the poses; (2) extrinsics: breadth-first from camera 0
// through shared views (the candidate that best explains every shared view wins; for a
// chessboard, whose corner order may come out turned by 180 degrees, each view's order is
// chosen the same way); (3) bundle adjustment of intrinsics, cam_from_world and
// world_from_board over every corner. Every solve runs `outlier_rounds` times: Huber loss,
// then corners whose residual exceeds max(outlier_min_px, outlier_sigmas * sigma) are removed
// (sigma = the robust noise estimate from the median residual); a last solve uses plain least
// squares on the inliers, so the RMS figures are those of an ordinary calibration on them.
//
// RMS convention (as cv::calibrateCamera): sqrt(mean over corners of |residual|^2), pixels.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/rigid3.h"
#include "core/status.h"
#include "reconstruct/board.h"
#include "reconstruct/camera.h"

namespace facedyn::reconstruct {

struct CalibrationInput {
  BoardSpec board;
  struct CameraInfo {
    std::string name;
    int width_px = 0;
    int height_px = 0;
  };
  std::vector<CameraInfo> cameras;
  std::vector<std::string> view_names;
  struct Observation {
    int camera = 0;
    int view = 0;
    BoardObservation corners;
  };
  std::vector<Observation> observations;
};

struct CalibrationOptions {
  bool estimate_k3 = true;               // as cv::calibrateCamera's default
  bool refine_intrinsics_in_rig = true;  // let the joint adjustment move the intrinsics too
  double huber_px = 1.0;
  double outlier_min_px = 1.0;
  double outlier_sigmas = 4.0;
  int outlier_rounds = 2;
  int min_corners_per_view = 6;
  int min_views_per_camera = 3;
  int max_iterations = 200;
  Status Check() const;
};

struct ViewError {
  int camera = 0;
  int view = 0;
  int corners = 0;   // inliers used
  int outliers = 0;  // rejected corners
  double rms_px = 0.0;
};

struct RigCalibration {
  std::string board;  // BoardSpec::ToString()
  std::vector<Camera> cameras;
  std::vector<std::string> view_names;
  std::vector<double> camera_rms_px;
  std::vector<int> camera_corners;
  std::vector<ViewError> view_errors;
  std::vector<std::optional<Rigid3>> world_from_board;  // per view; empty when unused
  double rms_px = 0.0;
};

struct CalibrationSummary {
  bool converged = false;
  int iterations = 0;  // Ceres iterations over every solve
  double initial_cost = 0.0;
  double final_cost = 0.0;
  int corners = 0;
  int outliers = 0;
  double rms_px = 0.0;
  std::vector<std::string> dropped;  // observations left out, and why
};

StatusOr<RigCalibration> Calibrate(const CalibrationInput& input, const CalibrationOptions& options,
                                   CalibrationSummary* summary = nullptr);

// OpenCV FileStorage YAML, written atomically. The cameras are capture/camera_model.h's
// layout (camera_count; per camera name, image_width, image_height, camera_matrix 3x3,
// distortion_coefficients 1x5 = k1 k2 p1 p2 k3, cam_from_world 4x4), so
// capture::ReadCameraModels reads a calibration as a camera rig; facedyn adds per camera
// rms_px and corners, then board, rms_px and per view and camera corners, outliers, rms_px.
Status SaveCalibration(const RigCalibration& calibration, const std::string& path);
StatusOr<RigCalibration> LoadCalibration(const std::string& path);

// The pose parameter block used by the solvers: angle-axis (3) then translation (3), mm.
using PoseBlock = std::array<double, 6>;
PoseBlock ToPoseBlock(const Rigid3& transform);
Rigid3 FromPoseBlock(const PoseBlock& block);

// Residual of one board corner for the joint adjustment (Ceres autodiff functor):
// observed - DistortAndScale(K, cam_from_world * world_from_board * point_in_board).
struct BoardCornerResidual {
  BoardCornerResidual(const Eigen::Vector2d& observed_px, const Eigen::Vector3d& point_in_board)
      : observed_px_(observed_px), point_in_board_(point_in_board) {}
  template <typename T>
  bool operator()(const T* intrinsics, const T* cam_from_world, const T* world_from_board,
                  T* residual) const;

 private:
  Eigen::Vector2d observed_px_;
  Eigen::Vector3d point_in_board_;
};

}  // namespace facedyn::reconstruct

#include <ceres/rotation.h>

namespace facedyn::reconstruct {

template <typename T>
bool BoardCornerResidual::operator()(const T* intrinsics, const T* cam_from_world,
                                     const T* world_from_board, T* residual) const {
  const T point[3] = {T(point_in_board_.x()), T(point_in_board_.y()), T(point_in_board_.z())};
  T in_world[3];
  ceres::AngleAxisRotatePoint(world_from_board, point, in_world);
  for (int k = 0; k < 3; ++k) in_world[k] += world_from_board[3 + k];
  T in_cam[3];
  ceres::AngleAxisRotatePoint(cam_from_world, in_world, in_cam);
  for (int k = 0; k < 3; ++k) in_cam[k] += cam_from_world[3 + k];
  T u, v;
  DistortAndScale(intrinsics, in_cam[0] / in_cam[2], in_cam[1] / in_cam[2], &u, &v);
  residual[0] = T(observed_px_.x()) - u;
  residual[1] = T(observed_px_.y()) - v;
  return true;
}

}  // namespace facedyn::reconstruct
