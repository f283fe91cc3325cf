// CameraModel: a calibrated camera as capture, the simulator and reconstruction share it —
// pinhole intrinsics, OpenCV's 5-coefficient lens distortion (k1, k2, p1, p2, k3), the pose
// cam_from_world and the image size — and its file format, an OpenCV FileStorage YAML file
// (cv::FileStorage reads what WriteCameraModels writes, and the other way round).
//
// Projection of a point X_in_cam = cam_from_world * X_in_world (mm), Z > 0:
//   x = X/Z, y = Y/Z, r2 = x^2 + y^2,
//   radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3,
//   x' = x radial + 2 p1 x y + p2 (r2 + 2 x^2),   y' = y radial + p1 (r2 + 2 y^2) + 2 p2 x y,
//   u = fx x' + cx,  v = fy y' + cy   (pixels; (0,0) is the centre of the top-left pixel).
// This is exactly cv::projectPoints with distCoeffs (k1, k2, p1, p2, k3); the camera frame is
// OpenCV's (+X right, +Y down, +Z forward along the optical axis).
//
// The parameter block order (fx, fy, cx, cy, k1, k2, p1, p2, k3) is the one
// reconstruct/camera.h uses, so converting between the two is a copy.
//
// File layout (one map per camera under "cameras", in order; units mm):
//   %YAML:1.0
//   ---
//   camera_count: 2
//   cameras:
//      - name: cam0
//        image_width: 1280
//        image_height: 1024
//        camera_matrix: !!opencv-matrix { rows: 3, cols: 3, dt: d, data: [fx,0,cx, 0,fy,cy, 0,0,1]
//        } distortion_coefficients: !!opencv-matrix { rows: 1, cols: 5, dt: d, data:
//        [k1,k2,p1,p2,k3] } cam_from_world: !!opencv-matrix { rows: 4, cols: 4, dt: d, data: [R t;
//        0 0 0 1] }
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "core/rigid3.h"
#include "core/status.h"

namespace facedyn::capture {

inline constexpr int kIntrinsicCount = 9;
// fx, fy, cx, cy (pixels), k1, k2, p1, p2, k3 (dimensionless).
using Intrinsics = std::array<double, kIntrinsicCount>;

// Distorts a normalised point (x, y) = (X/Z, Y/Z) and maps it to pixels (formula above).
// Templated so Ceres autodiff can use it.
template <typename T>
void DistortAndScale(const T* intrinsics, const T& x, const T& y, T* u, T* v) {
  const T& k1 = intrinsics[4];
  const T& k2 = intrinsics[5];
  const T& p1 = intrinsics[6];
  const T& p2 = intrinsics[7];
  const T& k3 = intrinsics[8];
  const T r2 = x * x + y * y;
  const T radial = T(1.0) + r2 * (k1 + r2 * (k2 + r2 * k3));
  const T xd = x * radial + T(2.0) * p1 * x * y + p2 * (r2 + T(2.0) * x * x);
  const T yd = y * radial + p1 * (r2 + T(2.0) * y * y) + T(2.0) * p2 * x * y;
  *u = intrinsics[0] * xd + intrinsics[2];
  *v = intrinsics[1] * yd + intrinsics[3];
}

struct CameraModel {
  std::string name;
  int width_px = 0;
  int height_px = 0;
  Intrinsics intrinsics{0, 0, 0, 0, 0, 0, 0, 0, 0};
  Rigid3 cam_from_world;  // mm

  double fx() const { return intrinsics[0]; }
  double fy() const { return intrinsics[1]; }
  double cx() const { return intrinsics[2]; }
  double cy() const { return intrinsics[3]; }
  bool HasDistortion() const;

  // A camera at `center_in_world` looking at `target_in_world`; the image's -Y (up) is as
  // close to `up_in_world` as possible. Principal point at the image centre, no distortion.
  static CameraModel LookAt(const std::string& name, int width_px, int height_px, double focal_px,
                            const Eigen::Vector3d& center_in_world,
                            const Eigen::Vector3d& target_in_world,
                            const Eigen::Vector3d& up_in_world);

  Eigen::Matrix3d CameraMatrix() const;  // K
  Eigen::Vector3d CenterInWorld() const;

  // Pixel of a point in the camera frame; false (pixel untouched) when Z <= 1e-9 mm.
  bool ProjectFromCam(const Eigen::Vector3d& point_in_cam, Eigen::Vector2d* pixel) const;
  bool Project(const Eigen::Vector3d& point_in_world, Eigen::Vector2d* pixel) const {
    return ProjectFromCam(cam_from_world * point_in_world, pixel);
  }
  // Normalised undistorted coordinates (X/Z, Y/Z) of a pixel: inverts DistortAndScale by
  // fixed-point iteration with a Newton polish (accurate to ~1e-12 for real lens distortions,
  // i.e. while the distortion map is monotonic over the image).
  Eigen::Vector2d Undistort(const Eigen::Vector2d& pixel) const;
  bool InImage(const Eigen::Vector2d& pixel, double margin_px = 0.0) const;

  // Size positive, focal lengths positive, every value finite. The message names the camera
  // and the field.
  Status Check() const;
};

// Writes the cameras as OpenCV FileStorage YAML (layout above), atomically. Checks every
// camera first and writes nothing when one is invalid.
Status WriteCameraModels(const std::string& path, const std::vector<CameraModel>& cameras);
// Reads such a file. Errors name the file, the camera index and the field (a missing or
// mis-sized matrix, a non-rigid pose, a camera matrix with skew or a wrong last row).
StatusOr<std::vector<CameraModel>> ReadCameraModels(const std::string& path);

}  // namespace facedyn::capture
