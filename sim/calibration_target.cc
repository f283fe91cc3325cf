#include "sim/calibration_target.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/core.hpp>

namespace facedyn::sim {

Status CalibrationBoard::Check() const {
  if (squares_x < 3 || squares_x > 64 || squares_y < 3 || squares_y > 64) {
    return InvalidArgumentError("board squares_x and squares_y must be in 3..64");
  }
  if (!(square_mm > 0 && square_mm < 1000))
    return InvalidArgumentError("board square_mm must be in (0, 1000)");
  if (kind == BoardKind::kCharuco && !(marker_mm > 0 && marker_mm < square_mm)) {
    return InvalidArgumentError("board marker_mm must be in (0, square_mm)");
  }
  if (!(margin_mm >= 0)) return InvalidArgumentError("board margin_mm must be >= 0");
  if (aruco_dictionary < 0 || aruco_dictionary > 20)
    return InvalidArgumentError("board aruco_dictionary must be 0..20");
  return Status::Ok();
}

std::vector<Eigen::Vector3d> CalibrationBoard::InnerCornersInBoard() const {
  std::vector<Eigen::Vector3d> corners;
  for (int j = 1; j < squares_y; ++j) {
    for (int i = 1; i < squares_x; ++i) corners.emplace_back(i * square_mm, j * square_mm, 0.0);
  }
  return corners;
}

BoardRenderer::BoardRenderer(const CalibrationBoard& board, const RenderOptions& options)
    : board_(board), options_(options) {
  FACEDYN_CHECK(board.Check().ok(), "BoardRenderer: " + board.Check().message());
  FACEDYN_CHECK(options.Check().ok(), "BoardRenderer: " + options.Check().message());
  if (board.kind == BoardKind::kCharuco) {
    texture_px_per_mm_ = 8.0;
    texture_width_ =
        static_cast<int>(std::lround(board.squares_x * board.square_mm * texture_px_per_mm_));
    texture_height_ =
        static_cast<int>(std::lround(board.squares_y * board.square_mm * texture_px_per_mm_));
    cv::Ptr<cv::aruco::Dictionary> dictionary =
        cv::aruco::getPredefinedDictionary(board.aruco_dictionary);
    cv::Ptr<cv::aruco::CharucoBoard> charuco = cv::aruco::CharucoBoard::create(
        board.squares_x, board.squares_y, static_cast<float>(board.square_mm),
        static_cast<float>(board.marker_mm), dictionary);
    cv::Mat image;
    charuco->draw(cv::Size(texture_width_, texture_height_), image, 0, 1);
    texture_.assign(image.datastart, image.dataend);
  }
}

float BoardRenderer::Albedo(double u, double v) const {
  const double width = board_.squares_x * board_.square_mm,
               height = board_.squares_y * board_.square_mm;
  if (u < 0 || v < 0 || u >= width || v >= height)
    return static_cast<float>(board_.white_albedo);  // margin
  if (board_.kind == BoardKind::kChessboard) {
    const int i = static_cast<int>(u / board_.square_mm),
              j = static_cast<int>(v / board_.square_mm);
    return static_cast<float>(((i + j) % 2 == 0) ? board_.black_albedo : board_.white_albedo);
  }
  const int tx = std::min(texture_width_ - 1, static_cast<int>(u * texture_px_per_mm_));
  const int ty = std::min(texture_height_ - 1, static_cast<int>(v * texture_px_per_mm_));
  const float t = texture_[static_cast<size_t>(ty) * texture_width_ + tx] / 255.0f;
  return static_cast<float>(board_.black_albedo + (board_.white_albedo - board_.black_albedo) * t);
}

std::vector<Eigen::Vector2d> BoardRenderer::ProjectInnerCorners(
    const capture::CameraModel& camera, const Rigid3& world_from_board) const {
  std::vector<Eigen::Vector2d> pixels;
  for (const Eigen::Vector3d& corner : board_.InnerCornersInBoard()) {
    Eigen::Vector2d pixel;
    if (!camera.Project(world_from_board * corner, &pixel) || !camera.InImage(pixel)) {
      pixel.setConstant(std::numeric_limits<double>::quiet_NaN());
    }
    pixels.push_back(pixel);
  }
  return pixels;
}

void BoardRenderer::Render(const capture::CameraModel& camera, const Rigid3& world_from_board,
                           uint64_t noise_key, uint8_t* out) const {
  const int width = camera.width_px, height = camera.height_px, s = options_.supersample;
  std::vector<float> radiance(static_cast<size_t>(width) * height * s * s,
                              static_cast<float>(options_.background));
  const Rigid3 board_from_cam = (camera.cam_from_world * world_from_board).Inverse();
  const Eigen::Vector3d origin = board_from_cam.translation();  // camera centre in the board frame
  const Eigen::Matrix3d rotation = board_from_cam.RotationMatrix();
  const Eigen::Vector3d normal_in_cam = board_from_cam.Inverse().RotationMatrix().col(2);
  // Pixels the board can cover: the projected outline (sampled edges, distortion included).
  const double w_mm = board_.squares_x * board_.square_mm,
               h_mm = board_.squares_y * board_.square_mm;
  double min_x = 1e30, min_y = 1e30, max_x = -1e30, max_y = -1e30;
  bool any_behind = false;
  for (int i = 0; i <= 32; ++i) {
    const double a = i / 32.0;
    const Eigen::Vector3d edge_points[4] = {
        {-board_.margin_mm + a * (w_mm + 2 * board_.margin_mm), -board_.margin_mm, 0},
        {-board_.margin_mm + a * (w_mm + 2 * board_.margin_mm), h_mm + board_.margin_mm, 0},
        {-board_.margin_mm, -board_.margin_mm + a * (h_mm + 2 * board_.margin_mm), 0},
        {w_mm + board_.margin_mm, -board_.margin_mm + a * (h_mm + 2 * board_.margin_mm), 0}};
    for (const Eigen::Vector3d& p : edge_points) {
      Eigen::Vector2d pixel;
      if (!camera.Project(world_from_board * p, &pixel)) {
        any_behind = true;
        continue;
      }
      min_x = std::min(min_x, pixel.x());
      max_x = std::max(max_x, pixel.x());
      min_y = std::min(min_y, pixel.y());
      max_y = std::max(max_y, pixel.y());
    }
  }
  int x0 = 0, x1 = width - 1, y0 = 0, y1 = height - 1;
  if (!any_behind) {
    x0 = std::max(0, static_cast<int>(std::floor(min_x)) - 2);
    x1 = std::min(width - 1, static_cast<int>(std::ceil(max_x)) + 2);
    y0 = std::max(0, static_cast<int>(std::floor(min_y)) - 2);
    y1 = std::min(height - 1, static_cast<int>(std::ceil(max_y)) + 2);
  }
  const double ambient = options_.ambient;
  const int hi_width = width * s;
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) {
      for (int sy = 0; sy < s; ++sy) {
        for (int sx = 0; sx < s; ++sx) {
          const Eigen::Vector2d pixel(x + (sx + 0.5) / s - 0.5, y + (sy + 0.5) / s - 0.5);
          const Eigen::Vector2d n = camera.Undistort(pixel);
          const Eigen::Vector3d ray_in_cam(n.x(), n.y(), 1.0);
          const Eigen::Vector3d direction = rotation * ray_in_cam;
          if (std::abs(direction.z()) < 1e-12) continue;
          const double lambda = -origin.z() / direction.z();
          if (lambda <= 0) continue;
          const Eigen::Vector3d hit = origin + lambda * direction;
          if (hit.x() < -board_.margin_mm || hit.y() < -board_.margin_mm ||
              hit.x() > w_mm + board_.margin_mm || hit.y() > h_mm + board_.margin_mm) {
            continue;
          }
          const double ndl = std::abs(normal_in_cam.dot(ray_in_cam.normalized()));
          radiance[static_cast<size_t>(y * s + sy) * hi_width + x * s + sx] =
              Albedo(hit.x(), hit.y()) * static_cast<float>(ambient + (1.0 - ambient) * ndl);
        }
      }
    }
  }
  FinishRadiance(options_, width, height, s, noise_key, &radiance, out);
}

}  // namespace facedyn::sim
