#include "reconstruct/synthetic_views.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace facedyn::reconstruct {

std::vector<Camera> MakeCameraRing(const CameraRingOptions& options) {
  std::vector<Camera> cameras;
  for (int i = 0; i < options.camera_count; ++i) {
    const double t = options.camera_count == 1 ? 0.5 : i / (options.camera_count - 1.0);
    const double azimuth = (t - 0.5) * options.arc_deg * M_PI / 180.0;
    const double elevation = (i % 2 == 0 ? 1.0 : -1.0) * options.elevation_deg * M_PI / 180.0;
    const Eigen::Vector3d direction(std::sin(azimuth) * std::cos(elevation), std::sin(elevation),
                                    std::cos(azimuth) * std::cos(elevation));
    cameras.push_back(Camera::LookAt("cam" + std::to_string(i), options.width_px, options.height_px,
                                     options.focal_px,
                                     options.target_in_world + options.radius_mm * direction,
                                     options.target_in_world, Eigen::Vector3d::UnitY()));
  }
  return cameras;
}

std::vector<Camera> MakeFaceCameraRing(int camera_count) {
  std::vector<Camera> cameras;
  const Eigen::Vector3d target(0.0, -15.0, 60.0);
  for (int i = 0; i < camera_count; ++i) {
    const double t = camera_count == 1 ? 0.5 : i / (camera_count - 1.0);
    const double azimuth = (t - 0.5) * 120.0 * M_PI / 180.0;
    const double elevation = (i % 2 == 0 ? 12.0 : -8.0) * M_PI / 180.0;
    const Eigen::Vector3d direction(std::sin(azimuth) * std::cos(elevation), std::sin(elevation),
                                    std::cos(azimuth) * std::cos(elevation));
    Camera camera = Camera::LookAt("cam" + std::to_string(i), 1280, 1024, 2200.0,
                                   target + 600.0 * direction, target, Eigen::Vector3d::UnitY());
    camera.intrinsics[4] = -0.06;
    camera.intrinsics[5] = 0.02;
    cameras.push_back(camera);
  }
  return cameras;
}

CameraRays MakeCameraRays(const Camera& camera, int supersample) {
  CameraRays rays;
  rays.camera = camera;
  rays.supersample = supersample;
  const int w = camera.width_px * supersample, h = camera.height_px * supersample;
  rays.normalized.resize(static_cast<size_t>(w) * h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector2d pixel((x + 0.5) / supersample - 0.5, (y + 0.5) / supersample - 0.5);
      rays.normalized[static_cast<size_t>(y) * w + x] = camera.Undistort(pixel).cast<float>();
    }
  }
  return rays;
}

cv::Mat RenderPlanarView(const cv::Mat& texture, double pixels_per_mm, double margin_mm,
                         const CameraRays& rays, const Rigid3& world_from_board,
                         unsigned char background) {
  const Camera& camera = rays.camera;
  const int supersample = rays.supersample;
  const Rigid3 board_from_cam = (camera.cam_from_world * world_from_board).Inverse();
  const Eigen::Vector3d origin = board_from_cam.translation();
  const Eigen::Matrix3d rotation = board_from_cam.RotationMatrix();
  const int w = camera.width_px * supersample, h = camera.height_px * supersample;
  cv::Mat map_x(h, w, CV_32F), map_y(h, w, CV_32F);
  for (int y = 0; y < h; ++y) {
    float* row_x = map_x.ptr<float>(y);
    float* row_y = map_y.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector2f& n = rays.normalized[static_cast<size_t>(y) * w + x];
      const Eigen::Vector3d ray = rotation * Eigen::Vector3d(n.x(), n.y(), 1.0);
      float sx = -1e6f, sy = -1e6f;
      if (std::abs(ray.z()) > 1e-12) {
        const double s = -origin.z() / ray.z();
        if (s > 0) {
          sx = static_cast<float>((origin.x() + s * ray.x() + margin_mm) * pixels_per_mm - 0.5);
          sy = static_cast<float>((origin.y() + s * ray.y() + margin_mm) * pixels_per_mm - 0.5);
        }
      }
      row_x[x] = sx;
      row_y[x] = sy;
    }
  }
  cv::Mat fine;
  cv::remap(texture, fine, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT,
            cv::Scalar(background));
  if (supersample == 1) return fine;
  cv::Mat image;
  cv::resize(fine, image, cv::Size(camera.width_px, camera.height_px), 0, 0, cv::INTER_AREA);
  return image;
}

cv::Mat RenderPlanarView(const cv::Mat& texture, double pixels_per_mm, double margin_mm,
                         const Camera& camera, const Rigid3& world_from_board, int supersample,
                         unsigned char background) {
  return RenderPlanarView(texture, pixels_per_mm, margin_mm, MakeCameraRays(camera, supersample),
                          world_from_board, background);
}

cv::Mat RenderPolygons(int width_px, int height_px,
                       const std::vector<std::vector<Eigen::Vector2d>>& polygons,
                       unsigned char background, unsigned char ink, int supersample) {
  constexpr int kShift = 4;  // cv::fillPoly sub-pixel bits
  cv::Mat fine(height_px * supersample, width_px * supersample, CV_8UC1, cv::Scalar(background));
  std::vector<std::vector<cv::Point>> contours;
  for (const auto& polygon : polygons) {
    if (polygon.size() < 3) continue;
    std::vector<cv::Point> contour;
    for (const Eigen::Vector2d& p : polygon) {
      // Coarse pixel centre u maps to fine coordinate s u + (s - 1) / 2.
      const double fx = supersample * p.x() + 0.5 * (supersample - 1);
      const double fy = supersample * p.y() + 0.5 * (supersample - 1);
      contour.emplace_back(static_cast<int>(std::lround(fx * (1 << kShift))),
                           static_cast<int>(std::lround(fy * (1 << kShift))));
    }
    contours.push_back(std::move(contour));
  }
  if (!contours.empty()) {
    cv::fillPoly(fine, contours, cv::Scalar(ink), cv::LINE_8, kShift);
  }
  if (supersample == 1) return fine;
  cv::Mat image;
  cv::resize(fine, image, cv::Size(width_px, height_px), 0, 0, cv::INTER_AREA);
  return image;
}

std::vector<Eigen::Vector2d> CircleOutline(const Eigen::Vector2d& center_px, double radius_px,
                                           int vertex_count) {
  std::vector<Eigen::Vector2d> outline;
  for (int k = 0; k < vertex_count; ++k) {
    const double angle = 2.0 * M_PI * k / vertex_count;
    outline.push_back(center_px + radius_px * Eigen::Vector2d(std::cos(angle), std::sin(angle)));
  }
  return outline;
}

std::vector<Eigen::Vector2d> ProjectDiskOutline(const Camera& camera,
                                                const Eigen::Vector3d& center_in_world,
                                                const Eigen::Vector3d& normal_in_world,
                                                double radius_mm, int vertex_count) {
  if (normal_in_world.dot(camera.CenterInWorld() - center_in_world) <= 0) return {};
  const Eigen::Vector3d n = normal_in_world.normalized();
  const Eigen::Vector3d u = n.unitOrthogonal();
  const Eigen::Vector3d v = n.cross(u);
  std::vector<Eigen::Vector2d> outline;
  for (int k = 0; k < vertex_count; ++k) {
    const double angle = 2.0 * M_PI * k / vertex_count;
    Eigen::Vector2d pixel;
    if (!camera.Project(center_in_world + radius_mm * (std::cos(angle) * u + std::sin(angle) * v),
                        &pixel)) {
      return {};
    }
    outline.push_back(pixel);
  }
  return outline;
}

Eigen::Matrix3Xd MarkerPositions(const FaceRig& rig, const Eigen::Matrix3Xd& skin_in_world) {
  Eigen::Matrix3Xd markers(3, rig.markers.size());
  for (size_t m = 0; m < rig.markers.size(); ++m) {
    markers.col(m) = rig.markers[m].point.Evaluate(skin_in_world);
  }
  return markers;
}

Eigen::Matrix3Xd MarkerNormals(const FaceRig& rig, const Eigen::Matrix3Xd& skin_in_world) {
  const Eigen::Matrix3Xd vertex_normals = VertexNormals(rig.neutral, skin_in_world);
  Eigen::Matrix3Xd normals(3, rig.markers.size());
  for (size_t m = 0; m < rig.markers.size(); ++m) {
    normals.col(m) = rig.markers[m].point.Evaluate(vertex_normals).normalized();
  }
  return normals;
}

MarkerViews ProjectMarkers(const std::vector<Camera>& cameras, const Eigen::Matrix3Xd& markers,
                           const Eigen::Matrix3Xd& normals, double sigma_px, std::mt19937* rng,
                           double min_cos) {
  std::normal_distribution<double> noise(0.0, sigma_px);
  MarkerViews views;
  for (size_t c = 0; c < cameras.size(); ++c) {
    std::vector<std::pair<ImageObservation, int>> seen;
    const Eigen::Vector3d center = cameras[c].CenterInWorld();
    for (int m = 0; m < markers.cols(); ++m) {
      const Eigen::Vector3d to_camera = (center - markers.col(m)).normalized();
      if (normals.col(m).dot(to_camera) < min_cos) continue;
      Eigen::Vector2d pixel;
      if (!cameras[c].Project(markers.col(m), &pixel) || !cameras[c].InImage(pixel, 4)) continue;
      ImageObservation o;
      o.camera = static_cast<int>(c);
      o.pixel = pixel + Eigen::Vector2d(noise(*rng), noise(*rng));
      seen.emplace_back(o, m);
    }
    std::shuffle(seen.begin(), seen.end(), *rng);
    views.detections.emplace_back();
    views.truth.emplace_back();
    for (size_t i = 0; i < seen.size(); ++i) {
      seen[i].first.detection = static_cast<int>(i);
      views.detections.back().push_back(seen[i].first);
      views.truth.back().push_back(seen[i].second);
    }
  }
  return views;
}

void AddImageNoise(double sigma, std::mt19937* rng, cv::Mat* image) {
  std::normal_distribution<double> noise(0.0, sigma);
  for (int y = 0; y < image->rows; ++y) {
    auto* row = image->ptr<unsigned char>(y);
    for (int x = 0; x < image->cols; ++x) {
      row[x] = cv::saturate_cast<unsigned char>(row[x] + noise(*rng));
    }
  }
}

}  // namespace facedyn::reconstruct
