#include "capture/camera_model.h"

#include <Eigen/Geometry>
#include <cmath>
#include <exception>
#include <filesystem>
#include <sstream>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>

#include "core/file_util.h"

namespace facedyn::capture {

bool CameraModel::HasDistortion() const {
  for (int i = 4; i < kIntrinsicCount; ++i) {
    if (intrinsics[i] != 0.0) return true;
  }
  return false;
}

CameraModel CameraModel::LookAt(const std::string& name, int width_px, int height_px,
                                double focal_px, const Eigen::Vector3d& center_in_world,
                                const Eigen::Vector3d& target_in_world,
                                const Eigen::Vector3d& up_in_world) {
  const Eigen::Vector3d z = (target_in_world - center_in_world).normalized();
  Eigen::Vector3d x = z.cross(up_in_world);  // image +X: right of the view; +Y = z x x: down
  FACEDYN_CHECK(x.norm() > 1e-9, "LookAt: viewing direction parallel to up");
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d cam_from_world_rotation;
  cam_from_world_rotation.row(0) = x.transpose();
  cam_from_world_rotation.row(1) = y.transpose();
  cam_from_world_rotation.row(2) = z.transpose();
  CameraModel camera;
  camera.name = name;
  camera.width_px = width_px;
  camera.height_px = height_px;
  camera.intrinsics = {focal_px, focal_px, (width_px - 1) / 2.0, (height_px - 1) / 2.0, 0, 0, 0,
                       0,        0};
  camera.cam_from_world = Rigid3(Eigen::Quaterniond(cam_from_world_rotation),
                                 -cam_from_world_rotation * center_in_world);
  return camera;
}

Eigen::Matrix3d CameraModel::CameraMatrix() const {
  Eigen::Matrix3d k = Eigen::Matrix3d::Identity();
  k(0, 0) = fx();
  k(1, 1) = fy();
  k(0, 2) = cx();
  k(1, 2) = cy();
  return k;
}

Eigen::Vector3d CameraModel::CenterInWorld() const {
  return cam_from_world.Inverse().translation();
}

bool CameraModel::ProjectFromCam(const Eigen::Vector3d& point_in_cam,
                                 Eigen::Vector2d* pixel) const {
  if (!(point_in_cam.z() > 1e-9)) return false;
  const double x = point_in_cam.x() / point_in_cam.z();
  const double y = point_in_cam.y() / point_in_cam.z();
  DistortAndScale(intrinsics.data(), x, y, &pixel->x(), &pixel->y());
  return true;
}

Eigen::Vector2d CameraModel::Undistort(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector2d distorted((pixel.x() - cx()) / fx(), (pixel.y() - cy()) / fy());
  if (!HasDistortion()) return distorted;
  // Distortion in normalised coordinates: d(p) = DistortAndScale with unit focal, zero centre.
  Intrinsics unit = intrinsics;
  unit[0] = 1.0;
  unit[1] = 1.0;
  unit[2] = 0.0;
  unit[3] = 0.0;
  auto distort = [&unit](const Eigen::Vector2d& p) {
    Eigen::Vector2d out;
    DistortAndScale(unit.data(), p.x(), p.y(), &out.x(), &out.y());
    return out;
  };
  // Fixed point p <- p + (target - d(p)) first (robust), then Newton with a numerical Jacobian.
  Eigen::Vector2d p = distorted;
  for (int i = 0; i < 20; ++i) p += distorted - distort(p);
  for (int i = 0; i < 5; ++i) {
    const Eigen::Vector2d residual = distort(p) - distorted;
    if (residual.norm() < 1e-15) break;
    constexpr double kStep = 1e-7;
    Eigen::Matrix2d jacobian;
    jacobian.col(0) =
        (distort(p + Eigen::Vector2d(kStep, 0)) - distort(p - Eigen::Vector2d(kStep, 0))) /
        (2 * kStep);
    jacobian.col(1) =
        (distort(p + Eigen::Vector2d(0, kStep)) - distort(p - Eigen::Vector2d(0, kStep))) /
        (2 * kStep);
    if (std::abs(jacobian.determinant()) < 1e-12) break;
    p -= jacobian.inverse() * residual;
  }
  return p;
}

bool CameraModel::InImage(const Eigen::Vector2d& pixel, double margin_px) const {
  return pixel.x() >= -0.5 + margin_px && pixel.y() >= -0.5 + margin_px &&
         pixel.x() <= width_px - 0.5 - margin_px && pixel.y() <= height_px - 0.5 - margin_px;
}

Status CameraModel::Check() const {
  const std::string what = "camera '" + name + "'";
  if (width_px <= 0 || height_px <= 0) {
    return InvalidArgumentError(what + ": image size " + std::to_string(width_px) + "x" +
                                std::to_string(height_px) + " is not positive");
  }
  static const char* kNames[kIntrinsicCount] = {"fx", "fy", "cx", "cy", "k1",
                                                "k2", "p1", "p2", "k3"};
  for (int i = 0; i < kIntrinsicCount; ++i) {
    if (!std::isfinite(intrinsics[i]))
      return InvalidArgumentError(what + ": " + kNames[i] + " is not finite");
  }
  if (!(fx() > 0) || !(fy() > 0))
    return InvalidArgumentError(what + ": focal lengths fx, fy must be positive");
  if (!cam_from_world.translation().allFinite() ||
      !cam_from_world.rotation().coeffs().allFinite()) {
    return InvalidArgumentError(what + ": cam_from_world is not finite");
  }
  return Status::Ok();
}

Status WriteCameraModels(const std::string& path, const std::vector<CameraModel>& cameras) {
  for (size_t i = 0; i < cameras.size(); ++i) {
    Status status = cameras[i].Check();
    if (!status.ok()) return status.WithContext(path + ": camera " + std::to_string(i));
  }
  std::string text;
  try {
    cv::FileStorage fs(".yaml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY);
    fs.writeComment(
        "facedyn camera models (capture/camera_model.h); lengths in mm, pixels with (0,0)"
        " at the centre of the top-left pixel; distortion k1 k2 p1 p2 k3 (OpenCV)");
    fs << "camera_count" << static_cast<int>(cameras.size());
    fs << "cameras"
       << "[";
    for (const CameraModel& camera : cameras) {
      cv::Mat k, dist, pose;
      Eigen::Matrix<double, 1, 5> d;
      d << camera.intrinsics[4], camera.intrinsics[5], camera.intrinsics[6], camera.intrinsics[7],
          camera.intrinsics[8];
      cv::eigen2cv(Eigen::Matrix3d(camera.CameraMatrix()), k);
      cv::eigen2cv(d, dist);
      cv::eigen2cv(Eigen::Matrix4d(camera.cam_from_world.ToMatrix4()), pose);
      fs << "{"
         << "name" << camera.name << "image_width" << camera.width_px << "image_height"
         << camera.height_px << "camera_matrix" << k << "distortion_coefficients" << dist
         << "cam_from_world" << pose << "}";
    }
    fs << "]";
    text = fs.releaseAndGetString();
  } catch (const cv::Exception& e) {
    return InternalError(path + ": OpenCV FileStorage failed: " + e.what());
  }
  return WriteFileAtomic(path, text);
}

namespace {

Status ReadMatrix(const cv::FileNode& node, const std::string& field, int rows, int cols,
                  const std::string& what, cv::Mat* out) {
  if (node[field].empty()) return InvalidArgumentError(what + ": missing field '" + field + "'");
  // OpenCV allocates rows x cols before reading the data, so a header claiming 2^18 x 2^18 asked
  // for 64 GiB (fuzz/calibration). The size is checked first.
  const cv::FileNode header_rows = node[field]["rows"];
  const cv::FileNode header_cols = node[field]["cols"];
  if (!header_rows.isInt() || !header_cols.isInt() ||
      static_cast<int64_t>(static_cast<int>(header_rows)) * static_cast<int>(header_cols) !=
          static_cast<int64_t>(rows) * cols) {
    return InvalidArgumentError(what + ": field '" + field + "' must be an opencv-matrix of " +
                                std::to_string(rows) + "x" + std::to_string(cols));
  }
  try {
    node[field] >> *out;
  } catch (const cv::Exception& e) {
    return InvalidArgumentError(what + ": field '" + field +
                                "' is not an opencv-matrix: " + e.what());
  }
  if (out->rows * out->cols == rows * cols && (out->rows == 1 || out->cols == 1) &&
      (rows == 1 || cols == 1)) {
    *out = out->reshape(1, rows);  // accept a 5x1 distortion vector as well as 1x5
  }
  if (out->rows != rows || out->cols != cols) {
    return InvalidArgumentError(what + ": field '" + field + "' is " + std::to_string(out->rows) +
                                "x" + std::to_string(out->cols) + ", expected " +
                                std::to_string(rows) + "x" + std::to_string(cols));
  }
  out->convertTo(*out, CV_64F);
  return Status::Ok();
}

// OpenCV's YAML reader never returned on "%YAML:1.0\n---%YAML:1\nc.0\n--a-" (fuzz/calibration),
// so the text's outline is checked before it sees it: a calibration is one YAML document as
// SaveCalibration (OpenCV FileStorage) writes it, "%YAML:1.0" then "---", with no further
// directive or document marker. Errors name the file and line.
Status CheckCalibrationOutline(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(const std::string text, ReadFileToString(path));
  std::istringstream lines(text);
  std::string line;
  int line_number = 0;
  while (std::getline(lines, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    auto fail = [&](const std::string& why) {
      return InvalidArgumentError(path + ":" + std::to_string(line_number) + ": " + why);
    };
    if (line_number == 1) {
      if (line != "%YAML:1.0" && line != "%YAML 1.0")
        return fail("a calibration starts with the line '%YAML:1.0' (OpenCV FileStorage YAML)");
    } else if (line_number == 2) {
      if (line != "---") return fail("expected '---' after '%YAML:1.0'");
    } else if (line.rfind('%', 0) == 0 || line.rfind("---", 0) == 0 ||
               line.rfind("...", 0) == 0) {
      return fail("a calibration is one YAML document: no directive or '---'/'...' here");
    }
  }
  if (line_number < 2) {
    return InvalidArgumentError(path + ": too short for a calibration ('%YAML:1.0', '---', ...)");
  }
  return Status::Ok();
}

}  // namespace

StatusOr<std::vector<CameraModel>> ReadCameraModels(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return NotFoundError(path + ": no such file");
  FACEDYN_RETURN_IF_ERROR(CheckCalibrationOutline(path));
  std::vector<CameraModel> cameras;
  try {
    cv::FileStorage fs(path, cv::FileStorage::READ);
    if (!fs.isOpened()) return InvalidArgumentError(path + ": not an OpenCV FileStorage file");
    const cv::FileNode list = fs["cameras"];
    if (list.empty() || !list.isSeq())
      return InvalidArgumentError(path + ": missing sequence 'cameras'");
    int index = 0;
    for (auto it = list.begin(); it != list.end(); ++it, ++index) {
      const cv::FileNode node = *it;
      const std::string what = path + ": cameras[" + std::to_string(index) + "]";
      if (!node.isMap()) return InvalidArgumentError(what + ": expected a map");
      CameraModel camera;
      if (node["name"].empty() || !node["name"].isString()) {
        return InvalidArgumentError(what + ": missing string field 'name'");
      }
      camera.name = static_cast<std::string>(node["name"]);
      for (const char* field : {"image_width", "image_height"}) {
        if (node[field].empty() || !node[field].isInt()) {
          return InvalidArgumentError(what + ": missing integer field '" + field + "'");
        }
      }
      camera.width_px = static_cast<int>(node["image_width"]);
      camera.height_px = static_cast<int>(node["image_height"]);
      cv::Mat k, dist, pose;
      FACEDYN_RETURN_IF_ERROR(ReadMatrix(node, "camera_matrix", 3, 3, what, &k));
      FACEDYN_RETURN_IF_ERROR(ReadMatrix(node, "distortion_coefficients", 1, 5, what, &dist));
      FACEDYN_RETURN_IF_ERROR(ReadMatrix(node, "cam_from_world", 4, 4, what, &pose));
      if (k.at<double>(0, 1) != 0.0 || k.at<double>(1, 0) != 0.0 || k.at<double>(2, 0) != 0.0 ||
          k.at<double>(2, 1) != 0.0 || k.at<double>(2, 2) != 1.0) {
        return InvalidArgumentError(what +
                                    ": camera_matrix must be [fx 0 cx; 0 fy cy; 0 0 1] (no skew)");
      }
      camera.intrinsics = {k.at<double>(0, 0),    k.at<double>(1, 1),    k.at<double>(0, 2),
                           k.at<double>(1, 2),    dist.at<double>(0, 0), dist.at<double>(0, 1),
                           dist.at<double>(0, 2), dist.at<double>(0, 3), dist.at<double>(0, 4)};
      Eigen::Matrix4d pose_matrix;
      cv::cv2eigen(pose, pose_matrix);
      if (!pose_matrix.allFinite() || !Rigid3::IsRigidMatrix(pose_matrix, 1e-6)) {
        return InvalidArgumentError(what +
                                    ": cam_from_world is not a rigid transform [R t; 0 0 0 1]");
      }
      camera.cam_from_world = Rigid3::FromMatrix4(pose_matrix);
      Status status = camera.Check();
      if (!status.ok()) return status.WithContext(what);
      cameras.push_back(std::move(camera));
    }
    if (!fs["camera_count"].empty() && static_cast<int>(fs["camera_count"]) != index) {
      return InvalidArgumentError(path + ": camera_count is " +
                                  std::to_string(static_cast<int>(fs["camera_count"])) +
                                  " but 'cameras' lists " + std::to_string(index));
    }
  } catch (const cv::Exception& e) {
    return InvalidArgumentError(path + ": cannot parse as OpenCV FileStorage YAML: " + e.what());
  } catch (const std::exception& e) {
    // OpenCV's parser also lets standard exceptions out: a malformed key made FileStorage's
    // constructor throw std::length_error, which ended the process (fuzz/calibration).
    return InvalidArgumentError(path + ": cannot parse as OpenCV FileStorage YAML (" + e.what() +
                                ")");
  }
  if (cameras.empty()) return InvalidArgumentError(path + ": 'cameras' is empty");
  return cameras;
}

}  // namespace facedyn::capture
