// Calibration targets filmed by the virtual cameras: a chessboard or a ChArUco board at given
// poses, rendered by ray casting so the lens distortion and the pattern's edges are exact.
//
// Board frame (mm): origin at the outer corner of square (0, 0), +X along the squares_x
// direction, +Y along squares_y, the pattern in the plane Z = 0 (visible from both sides).
// The chessboard's inner corners, the points calibration detects, are at
// (i * square_mm, j * square_mm, 0) for i = 1..squares_x-1, j = 1..squares_y-1; square (0,0) is
// black. A ChArUco board uses cv::aruco::CharucoBoard's own drawing as its texture (same
// squares and inner corners; the markers sit in the white squares).
//
// Per pixel, `supersample` x `supersample` sub-pixel rays are undistorted (the inverse of the
// camera's distortion), intersected with the board plane and shaded (the pattern's albedo
// times an ambient + ring-light Lambert term); the sensor stage (PSF, noise, quantisation)
// is the face renderer's (sim/virtual_camera.h FinishRadiance).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "capture/camera_model.h"
#include "core/rigid3.h"
#include "core/status.h"
#include "sim/virtual_camera.h"

namespace facedyn::sim {

enum class BoardKind { kChessboard, kCharuco };

struct CalibrationBoard {
  BoardKind kind = BoardKind::kChessboard;
  int squares_x = 10;  // squares along X (inner corners: squares_x - 1)
  int squares_y = 7;
  double square_mm = 20.0;
  double marker_mm = 14.0;   // ChArUco marker side
  int aruco_dictionary = 0;  // cv::aruco::PREDEFINED_DICTIONARY_NAME, 0 = DICT_4X4_50
  double margin_mm = 15.0;   // white border around the squares
  double white_albedo = 0.85;
  double black_albedo = 0.04;

  Status Check() const;
  // Inner corners in the board frame, row by row (j outer, i inner).
  std::vector<Eigen::Vector3d> InnerCornersInBoard() const;
};

class BoardRenderer {
 public:
  // `options` supplies ambient, background, noise, PSF and supersampling.
  BoardRenderer(const CalibrationBoard& board, const RenderOptions& options);

  // Renders the board at `world_from_board` into `out` (camera size, mono8).
  void Render(const capture::CameraModel& camera, const Rigid3& world_from_board,
              uint64_t noise_key, uint8_t* out) const;
  // Ground truth: the inner corners' pixels (NaN when behind the camera or off the image).
  std::vector<Eigen::Vector2d> ProjectInnerCorners(const capture::CameraModel& camera,
                                                   const Rigid3& world_from_board) const;

  const CalibrationBoard& board() const { return board_; }

 private:
  float Albedo(double u_mm, double v_mm) const;

  CalibrationBoard board_;
  RenderOptions options_;
  std::vector<uint8_t> texture_;  // ChArUco drawing (kCharuco only)
  int texture_width_ = 0;
  int texture_height_ = 0;
  double texture_px_per_mm_ = 0.0;
};

}  // namespace facedyn::sim
