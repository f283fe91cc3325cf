#include "reconstruct/board.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/aruco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

namespace facedyn::reconstruct {
namespace {

const std::map<std::string, int>& DictionaryNames() {
  static const std::map<std::string, int> names = {
      {"DICT_4X4_50", cv::aruco::DICT_4X4_50},
      {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
      {"DICT_4X4_250", cv::aruco::DICT_4X4_250},
      {"DICT_4X4_1000", cv::aruco::DICT_4X4_1000},
      {"DICT_5X5_50", cv::aruco::DICT_5X5_50},
      {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
      {"DICT_5X5_250", cv::aruco::DICT_5X5_250},
      {"DICT_5X5_1000", cv::aruco::DICT_5X5_1000},
      {"DICT_6X6_50", cv::aruco::DICT_6X6_50},
      {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
      {"DICT_6X6_250", cv::aruco::DICT_6X6_250},
      {"DICT_6X6_1000", cv::aruco::DICT_6X6_1000},
      {"DICT_7X7_50", cv::aruco::DICT_7X7_50},
      {"DICT_7X7_100", cv::aruco::DICT_7X7_100},
      {"DICT_7X7_250", cv::aruco::DICT_7X7_250},
      {"DICT_7X7_1000", cv::aruco::DICT_7X7_1000},
      {"DICT_ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL}};
  return names;
}

std::vector<std::string> Split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::stringstream stream(text);
  std::string part;
  while (std::getline(stream, part, separator)) parts.push_back(part);
  if (!text.empty() && text.back() == separator) parts.emplace_back();
  return parts;
}

bool ParseInt(const std::string& text, int* value) {
  if (text.empty()) return false;
  size_t used = 0;
  try {
    *value = std::stoi(text, &used);
  } catch (...) {
    return false;
  }
  return used == text.size();
}

bool ParseDouble(const std::string& text, double* value) {
  if (text.empty()) return false;
  size_t used = 0;
  try {
    *value = std::stod(text, &used);
  } catch (...) {
    return false;
  }
  return used == text.size() && std::isfinite(*value);
}

// Board-plane corners of the marker on square (x, y) (TL, TR, BR, BL as aruco reports them), mm.
std::array<cv::Point2f, 4> MarkerCornersInBoard(const BoardSpec& spec, int x, int y) {
  const double s = spec.square_mm;
  const double d = 0.5 * (spec.square_mm - spec.marker_mm);
  const double m = spec.marker_mm;
  const float x0 = static_cast<float>(x * s + d), y0 = static_cast<float>(y * s + d);
  return {cv::Point2f(x0, y0), cv::Point2f(x0 + m, y0), cv::Point2f(x0 + m, y0 + m),
          cv::Point2f(x0, y0 + m)};
}

// Marker squares (x, y) in id order.
std::vector<cv::Point> MarkerSquares(const BoardSpec& spec) {
  std::vector<cv::Point> squares;
  for (int y = 0; y < spec.rows; ++y) {
    for (int x = 0; x < spec.cols; ++x) {
      if (spec.SquareHasMarker(x, y)) squares.emplace_back(x, y);
    }
  }
  return squares;
}

int SubPixHalfWindow(double feature_px) {
  return std::clamp(static_cast<int>(std::floor(feature_px)), 2, 11);
}

StatusOr<BoardObservation> DetectChessboard(const cv::Mat& gray, const BoardSpec& spec) {
  std::vector<cv::Point2f> corners;
  const bool found =
      cv::findChessboardCorners(gray, cv::Size(spec.cols, spec.rows), corners,
                                cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
  if (!found || static_cast<int>(corners.size()) != spec.corner_count()) {
    return NotFoundError("no " + std::to_string(spec.cols) + "x" + std::to_string(spec.rows) +
                         " chessboard found");
  }
  // Window: as large as OpenCV's sample (11x11 half size) but within 40% of the corner spacing.
  double spacing_px = 1e9;
  for (int r = 0; r < spec.rows; ++r) {
    for (int c = 0; c + 1 < spec.cols; ++c) {
      const int i = r * spec.cols + c;
      spacing_px = std::min<double>(spacing_px, cv::norm(corners[i + 1] - corners[i]));
    }
  }
  const int half = SubPixHalfWindow(0.4 * spacing_px);
  cv::cornerSubPix(gray, corners, cv::Size(half, half), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 30, 0.01));
  BoardObservation observation;
  for (int i = 0; i < static_cast<int>(corners.size()); ++i) {
    observation.corner_ids.push_back(i);
    observation.pixels.emplace_back(corners[i].x, corners[i].y);
  }
  return observation;
}

// Keeps the corners that agree with a homography through their neighbours (within two
// squares): a corner that latched onto a marker edge does not. Local, so lens distortion
// does not enter; corners with fewer than 4 neighbours are kept as they are.
BoardObservation RejectInconsistentCorners(const BoardSpec& spec, const BoardObservation& in) {
  std::map<int, int> index_of_id;
  for (int i = 0; i < in.size(); ++i) index_of_id[in.corner_ids[i]] = i;
  BoardObservation out;
  for (int i = 0; i < in.size(); ++i) {
    const int id = in.corner_ids[i];
    const int c = id % spec.inner_cols(), r = id / spec.inner_cols();
    std::vector<cv::Point2f> board_points, image_points;
    double spacing_px = 0.0;
    for (int dr = -2; dr <= 2; ++dr) {
      for (int dc = -2; dc <= 2; ++dc) {
        if ((dr == 0 && dc == 0) || c + dc < 0 || r + dr < 0 || c + dc >= spec.inner_cols() ||
            r + dr >= spec.inner_rows()) {
          continue;
        }
        const auto other = index_of_id.find((r + dr) * spec.inner_cols() + c + dc);
        if (other == index_of_id.end()) continue;
        const Eigen::Vector3d p = spec.CornerInBoard(other->first);
        board_points.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
        const Eigen::Vector2d& q = in.pixels[other->second];
        image_points.emplace_back(static_cast<float>(q.x()), static_cast<float>(q.y()));
        spacing_px =
            std::max(spacing_px, (q - in.pixels[i]).norm() / std::hypot(double(dr), double(dc)));
      }
    }
    if (board_points.size() >= 5) {
      std::vector<unsigned char> mask;
      const cv::Mat local = cv::findHomography(board_points, image_points, cv::RANSAC,
                                               std::max(0.5, 0.015 * spacing_px), mask);
      if (!local.empty()) {
        const Eigen::Vector3d p = spec.CornerInBoard(id);
        std::vector<cv::Point2f> predicted;
        cv::perspectiveTransform(std::vector<cv::Point2f>{cv::Point2f(static_cast<float>(p.x()),
                                                                      static_cast<float>(p.y()))},
                                 predicted, local);
        const double error =
            std::hypot(predicted[0].x - in.pixels[i].x(), predicted[0].y - in.pixels[i].y());
        if (error > std::max(0.5, 0.015 * spacing_px)) continue;
      }
    }
    out.corner_ids.push_back(id);
    out.pixels.push_back(in.pixels[i]);
  }
  return out;
}

StatusOr<BoardObservation> DetectCharuco(const cv::Mat& gray, const BoardSpec& spec) {
  const cv::Ptr<cv::aruco::Dictionary> dictionary =
      cv::aruco::getPredefinedDictionary(DictionaryNames().at(spec.dictionary));
  std::vector<std::vector<cv::Point2f>> marker_corners, rejected;
  std::vector<int> marker_ids;
  const cv::Ptr<cv::aruco::DetectorParameters> parameters = cv::aruco::DetectorParameters::create();
  // No marker corner refinement: the marker corners only seed the chessboard corners, and a
  // sub-pixel search next to a chessboard saddle gets pulled onto it.
  parameters->cornerRefinementMethod = cv::aruco::CORNER_REFINE_NONE;
  cv::aruco::detectMarkers(gray, dictionary, marker_corners, marker_ids, parameters, rejected);
  const std::vector<cv::Point> squares = MarkerSquares(spec);
  // Markers of this board (ids beyond the board's count belong to something else).
  std::vector<int> kept;
  for (int i = 0; i < static_cast<int>(marker_ids.size()); ++i) {
    if (marker_ids[i] >= 0 && marker_ids[i] < static_cast<int>(squares.size())) kept.push_back(i);
  }
  if (kept.empty()) return NotFoundError("no ChArUco marker of the board found");

  double marker_side_px = 0.0;
  for (int i : kept) {
    marker_side_px += cv::norm(marker_corners[i][0] - marker_corners[i][1]) / kept.size();
  }
  const double square_px = marker_side_px * spec.square_mm / spec.marker_mm;
  std::map<int, int> detection_of_marker;  // marker id -> index into marker_corners
  for (int i : kept) detection_of_marker[marker_ids[i]] = i;
  std::map<std::pair<int, int>, int> marker_of_square;
  for (int k = 0; k < static_cast<int>(squares.size()); ++k) {
    marker_of_square[{squares[k].x, squares[k].y}] = k;
  }
  const double margin_px =
      marker_side_px * 0.5 * (spec.square_mm - spec.marker_mm) / spec.marker_mm;
  const int half = SubPixHalfWindow(0.8 * margin_px);

  // Every inner corner touches exactly two marker squares (diagonal neighbours). Each marker's
  // own homography predicts the corner; the two predictions must agree. That is local (lens
  // distortion does not matter) and catches a wrong layout: with the legacy/4.6 confusion,
  // neighbouring rows are displaced by one square in opposite directions.
  BoardObservation observation;
  std::vector<cv::Point2f> predicted;
  int pairs = 0, agreeing = 0;
  for (int r = 0; r < spec.inner_rows(); ++r) {
    for (int c = 0; c < spec.inner_cols(); ++c) {
      const std::vector<cv::Point2f> corner_in_board = {
          cv::Point2f(static_cast<float>((c + 1) * spec.square_mm),
                      static_cast<float>((r + 1) * spec.square_mm))};
      std::vector<cv::Point2f> local_board, local_image, predictions;
      for (int dy = 0; dy <= 1; ++dy) {
        for (int dx = 0; dx <= 1; ++dx) {
          const auto square = marker_of_square.find({c + dx, r + dy});
          if (square == marker_of_square.end()) continue;
          const auto detection = detection_of_marker.find(square->second);
          if (detection == detection_of_marker.end()) continue;
          const auto corners_in_board = MarkerCornersInBoard(spec, c + dx, r + dy);
          const std::vector<cv::Point2f> board4(corners_in_board.begin(), corners_in_board.end());
          const std::vector<cv::Point2f>& image4 = marker_corners[detection->second];
          const cv::Mat own = cv::findHomography(board4, image4, 0);
          if (own.empty()) continue;
          std::vector<cv::Point2f> prediction;
          cv::perspectiveTransform(corner_in_board, prediction, own);
          predictions.push_back(prediction[0]);
          local_board.insert(local_board.end(), board4.begin(), board4.end());
          local_image.insert(local_image.end(), image4.begin(), image4.end());
        }
      }
      // Both markers touching the corner must be seen (as OpenCV's minMarkers = 2): a corner
      // next to an occluded marker is likely occluded itself.
      if (predictions.size() < 2) continue;
      ++pairs;
      if (cv::norm(predictions[0] - predictions[1]) > std::max(2.0, 0.25 * square_px)) continue;
      ++agreeing;
      const cv::Mat local = cv::findHomography(local_board, local_image, 0);
      if (local.empty()) continue;
      std::vector<cv::Point2f> corner_in_image;
      cv::perspectiveTransform(corner_in_board, corner_in_image, local);
      const cv::Point2f p = corner_in_image[0];
      if (p.x < half || p.y < half || p.x >= gray.cols - half || p.y >= gray.rows - half) {
        continue;
      }
      observation.corner_ids.push_back(r * spec.inner_cols() + c);
      predicted.push_back(p);
    }
  }
  if (pairs >= 3 && agreeing < 0.5 * pairs) {
    return FailedPreconditionError(
        "ChArUco marker ids do not fit the " + spec.ToString() + " layout (the markers around " +
        std::to_string(pairs - agreeing) + " of " + std::to_string(pairs) + " corners disagree)" +
        (spec.rows % 2 == 0
             ? std::string("; for a board with an even row count printed before OpenCV 4.6 "
                           "add ':legacy' to the spec (or remove it if present)")
             : std::string("")));
  }
  if (predicted.empty()) return NotFoundError("no ChArUco corner between detected markers");
  std::vector<cv::Point2f> refined = predicted;
  cv::cornerSubPix(gray, refined, cv::Size(half, half), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 30, 0.01));
  BoardObservation result;
  for (size_t i = 0; i < refined.size(); ++i) {
    // A corner that walked out of its clean checker neighbourhood latched onto a marker edge.
    if (cv::norm(refined[i] - predicted[i]) > std::max(1.5, 0.7 * margin_px)) continue;
    result.corner_ids.push_back(observation.corner_ids[i]);
    result.pixels.emplace_back(refined[i].x, refined[i].y);
  }
  if (result.corner_ids.empty()) return NotFoundError("no ChArUco corner survived refinement");
  return RejectInconsistentCorners(spec, result);
}

}  // namespace

StatusOr<BoardSpec> BoardSpec::Parse(const std::string& text) {
  const std::string usage =
      "expected chessboard:COLSxROWS:SQUARE_MM (inner corners) or "
      "charuco:COLSxROWS:SQUARE_MM:MARKER_MM[:DICT][:legacy] (squares)";
  const std::vector<std::string> parts = Split(text, ':');
  if (parts.size() < 3) return InvalidArgumentError("board spec '" + text + "': " + usage);
  BoardSpec spec;
  if (parts[0] == "chessboard") {
    spec.kind = Kind::kChessboard;
    if (parts.size() != 3) return InvalidArgumentError("board spec '" + text + "': " + usage);
  } else if (parts[0] == "charuco") {
    spec.kind = Kind::kCharuco;
    if (parts.size() < 4 || parts.size() > 6) {
      return InvalidArgumentError("board spec '" + text + "': " + usage);
    }
  } else {
    return InvalidArgumentError("board spec '" + text + "': unknown board kind '" + parts[0] +
                                "'; " + usage);
  }
  const size_t x = parts[1].find('x');
  if (x == std::string::npos || !ParseInt(parts[1].substr(0, x), &spec.cols) ||
      !ParseInt(parts[1].substr(x + 1), &spec.rows)) {
    return InvalidArgumentError("board spec '" + text + "': size '" + parts[1] +
                                "' is not COLSxROWS");
  }
  if (!ParseDouble(parts[2], &spec.square_mm)) {
    return InvalidArgumentError("board spec '" + text + "': square size '" + parts[2] +
                                "' is not a number");
  }
  if (spec.kind == Kind::kCharuco) {
    if (!ParseDouble(parts[3], &spec.marker_mm)) {
      return InvalidArgumentError("board spec '" + text + "': marker size '" + parts[3] +
                                  "' is not a number");
    }
    for (size_t i = 4; i < parts.size(); ++i) {
      if (parts[i] == "legacy") {
        spec.legacy = true;
      } else if (DictionaryNames().count(parts[i]) != 0 && i == 4) {
        spec.dictionary = parts[i];
      } else {
        return InvalidArgumentError("board spec '" + text + "': '" + parts[i] +
                                    "' is neither an OpenCV dictionary (e.g. DICT_5X5_100) nor "
                                    "'legacy'");
      }
    }
  }
  const Status check = spec.Check();
  if (!check.ok()) return check.WithContext("board spec '" + text + "'");
  return spec;
}

std::string BoardSpec::ToString() const {
  std::ostringstream out;
  out << (kind == Kind::kChessboard ? "chessboard:" : "charuco:") << cols << "x" << rows << ":"
      << square_mm;
  if (kind == Kind::kCharuco) {
    out << ":" << marker_mm << ":" << dictionary << (legacy ? ":legacy" : "");
  }
  return out.str();
}

Status BoardSpec::Check() const {
  const int minimum = kind == Kind::kChessboard ? 2 : 3;
  if (cols < minimum || rows < minimum || cols > 200 || rows > 200) {
    return InvalidArgumentError("size " + std::to_string(cols) + "x" + std::to_string(rows) +
                                " must be between " + std::to_string(minimum) + " and 200 " +
                                (kind == Kind::kChessboard ? "inner corners" : "squares"));
  }
  if (!(square_mm > 0)) return InvalidArgumentError("square size must be > 0");
  if (kind == Kind::kCharuco) {
    if (!(marker_mm > 0) || !(marker_mm < square_mm)) {
      return InvalidArgumentError("marker size must be > 0 and smaller than the square size");
    }
    if (DictionaryNames().count(dictionary) == 0) {
      return InvalidArgumentError("unknown dictionary '" + dictionary + "'");
    }
    const cv::Ptr<cv::aruco::Dictionary> dict =
        cv::aruco::getPredefinedDictionary(DictionaryNames().at(dictionary));
    if (dict->bytesList.rows < MarkerCount()) {
      return InvalidArgumentError("dictionary " + dictionary + " has " +
                                  std::to_string(dict->bytesList.rows) +
                                  " markers, the board needs " + std::to_string(MarkerCount()));
    }
  }
  return Status::Ok();
}

Eigen::Vector3d BoardSpec::CornerInBoard(int id) const {
  FACEDYN_CHECK(id >= 0 && id < corner_count(), "corner id out of range");
  const int c = id % inner_cols();
  const int r = id / inner_cols();
  return {(c + 1) * square_mm, (r + 1) * square_mm, 0.0};
}

bool BoardSpec::SquareHasMarker(int x, int y) const {
  // 4.6: top-left black, markers where x + y is odd. Legacy with an even row count: top-left
  // white, markers where x + y is even.
  const bool flipped = legacy && rows % 2 == 0;
  return ((x + y) % 2 == 1) != flipped;
}

int BoardSpec::MarkerCount() const {
  int count = 0;
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < cols; ++x) count += SquareHasMarker(x, y) ? 1 : 0;
  }
  return count;
}

StatusOr<BoardObservation> DetectBoard(const cv::Mat& gray, const BoardSpec& spec) {
  if (gray.empty() || gray.type() != CV_8UC1) {
    return InvalidArgumentError("DetectBoard needs a non-empty 8-bit grayscale image");
  }
  return spec.kind == BoardSpec::Kind::kChessboard ? DetectChessboard(gray, spec)
                                                   : DetectCharuco(gray, spec);
}

cv::Mat RenderBoard(const BoardSpec& spec, double pixels_per_mm, double margin_mm) {
  const int squares_x = spec.kind == BoardSpec::Kind::kChessboard ? spec.cols + 1 : spec.cols;
  const int squares_y = spec.kind == BoardSpec::Kind::kChessboard ? spec.rows + 1 : spec.rows;
  const int margin_px = static_cast<int>(std::lround(margin_mm * pixels_per_mm));
  const int square_px = static_cast<int>(std::lround(spec.square_mm * pixels_per_mm));
  cv::Mat image(squares_y * square_px + 2 * margin_px, squares_x * square_px + 2 * margin_px,
                CV_8UC1, cv::Scalar(255));
  cv::Ptr<cv::aruco::Dictionary> dictionary;
  if (spec.kind == BoardSpec::Kind::kCharuco) {
    dictionary = cv::aruco::getPredefinedDictionary(DictionaryNames().at(spec.dictionary));
  }
  int marker_id = 0;
  for (int y = 0; y < squares_y; ++y) {
    for (int x = 0; x < squares_x; ++x) {
      const cv::Rect square(margin_px + x * square_px, margin_px + y * square_px, square_px,
                            square_px);
      if (spec.kind == BoardSpec::Kind::kChessboard) {
        if ((x + y) % 2 == 0) image(square).setTo(0);
        continue;
      }
      if (!spec.SquareHasMarker(x, y)) {
        image(square).setTo(0);
        continue;
      }
      const int marker_px = static_cast<int>(std::lround(spec.marker_mm * pixels_per_mm));
      const int offset = (square_px - marker_px) / 2;
      cv::Mat marker;
      dictionary->drawMarker(marker_id++, marker_px, marker, 1);
      marker.copyTo(image(cv::Rect(square.x + offset, square.y + offset, marker_px, marker_px)));
    }
  }
  return image;
}

}  // namespace facedyn::reconstruct
