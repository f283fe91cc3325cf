#include "reconstruct/synthetic_views.h"

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
    cameras.push_back(Camera::LookAt("cam" + std::to_string(i), options.width_px,
                                     options.height_px, options.focal_px,
                                     options.target_in_world + options.radius_mm * direction,
                                     options.target_in_world, Eigen::Vector3d::UnitY()));
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
