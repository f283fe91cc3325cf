// Calibration targets: chessboards and ChArUco boards, their geometry and their detection.
//
// Board frame (mm): x to the right along the printed board's top edge, y down the board,
// z = x cross y (into the board); the board lies in z = 0 with its top-left square's outer
// corner at the origin. Corners are the inner chessboard corners, numbered row-major from the
// top-left: id = r * (inner columns) + c, at ((c+1) s, (r+1) s) for square size s (for a
// chessboard, the order is the one findChessboardCorners reports, which may be the board
// turned by 180 degrees; calibration resolves that per view).
//
// ChArUco layouts. OpenCV 4.6's contrib aruco changed CharucoBoard for boards with an EVEN
// number of square rows (opencv_contrib#3291): since 4.6 the top-left square is always black,
// before 4.6 it was white when the row count is even (the pattern was built bottom-up). Markers
// sit on the white squares, numbered row-major from the top in both cases. A board printed
// with an older OpenCV (or bought to that layout, e.g. many stock targets) therefore needs
// `:legacy`; odd row counts are the same in both. facedyn does not use
// interpolateCornersCharuco (which cannot express the legacy layout in 4.6 and misplaces
// corners there, opencv_contrib#3301/#3367): it predicts each corner from the two detected
// markers touching it (a local homography, so lens distortion does not matter; a corner
// whose markers are not both seen is left out, as it is likely occluded), refines it with
// cornerSubPix and keeps it when it agrees with its refined neighbours.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/status.h"

namespace facedyn::reconstruct {

struct BoardSpec {
  enum class Kind { kChessboard, kCharuco };
  Kind kind = Kind::kChessboard;
  // Chessboard: inner corners per row (cols) and per column (rows). ChArUco: squares.
  int cols = 9;
  int rows = 6;
  double square_mm = 1.0;
  double marker_mm = 0.0;                  // ChArUco only: marker side, < square_mm
  std::string dictionary = "DICT_4X4_50";  // ChArUco only: an OpenCV predefined dictionary
  bool legacy = false;                     // ChArUco only: the pre-4.6 layout (see above)

  // Parses "chessboard:COLSxROWS:SQUARE_MM" (inner corners) or
  // "charuco:COLSxROWS:SQUARE_MM:MARKER_MM[:DICT][:legacy]" (squares; DICT e.g. DICT_5X5_100).
  static StatusOr<BoardSpec> Parse(const std::string& spec);
  std::string ToString() const;
  // Sizes positive, marker smaller than square, enough markers in the dictionary.
  Status Check() const;

  int inner_cols() const { return kind == Kind::kChessboard ? cols : cols - 1; }
  int inner_rows() const { return kind == Kind::kChessboard ? rows : rows - 1; }
  int corner_count() const { return inner_cols() * inner_rows(); }
  Eigen::Vector3d CornerInBoard(int id) const;
  // ChArUco: true when square (x, y) (x = column from the left, y = row from the top) carries
  // a marker in this layout.
  bool SquareHasMarker(int x, int y) const;
  // ChArUco: number of markers; marker k sits on the k-th marker square in row-major order.
  int MarkerCount() const;
};

// Corners of one board seen in one image (pixels), ids as in BoardSpec.
struct BoardObservation {
  std::vector<int> corner_ids;
  std::vector<Eigen::Vector2d> pixels;
  int size() const { return static_cast<int>(corner_ids.size()); }
};

// Finds the board in an 8-bit grayscale image. A chessboard must be seen whole; a ChArUco
// board may be partly visible (every corner whose two markers are detected is returned). Returns
// NotFound when the board is not in the image, FailedPrecondition when ChArUco markers are
// found but their ids contradict the layout (with a hint about `:legacy`).
StatusOr<BoardObservation> DetectBoard(const cv::Mat& gray, const BoardSpec& spec);

// The board as it is printed, `pixels_per_mm` pixels per millimetre, with a white margin of
// `margin_mm`: for tests, simulated cameras and printing. The ChArUco rendering of the 4.6
// layout equals cv::aruco::CharucoBoard::draw.
cv::Mat RenderBoard(const BoardSpec& spec, double pixels_per_mm, double margin_mm = 0.0);

}  // namespace facedyn::reconstruct
