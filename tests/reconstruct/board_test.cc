#include "reconstruct/board.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "reconstruct/synthetic_views.h"
#include "tests/support/test_support.h"

namespace facedyn::reconstruct {
namespace {

using ::testing::HasSubstr;

TEST(BoardSpecParse, AcceptsBothKinds) {
  const auto chess = BoardSpec::Parse("chessboard:9x6:25");
  ASSERT_TRUE(chess.ok()) << chess.status().ToString();
  EXPECT_EQ(chess->kind, BoardSpec::Kind::kChessboard);
  EXPECT_EQ(chess->corner_count(), 54);
  EXPECT_DOUBLE_EQ(chess->square_mm, 25.0);
  const auto charuco = BoardSpec::Parse("charuco:7x4:30:22.5:DICT_5X5_100:legacy");
  ASSERT_TRUE(charuco.ok()) << charuco.status().ToString();
  EXPECT_EQ(charuco->kind, BoardSpec::Kind::kCharuco);
  EXPECT_EQ(charuco->corner_count(), 6 * 3);
  EXPECT_TRUE(charuco->legacy);
  EXPECT_EQ(charuco->dictionary, "DICT_5X5_100");
  EXPECT_EQ(BoardSpec::Parse(charuco->ToString())->ToString(), charuco->ToString());
}

TEST(BoardSpecParse, RejectsBadSpecsNamingThePart) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"chess:9x6:25", "unknown board kind"},
      {"chessboard:9by6:25", "is not COLSxROWS"},
      {"chessboard:9x6:abc", "square size 'abc'"},
      {"chessboard:9x6", "expected chessboard"},
      {"chessboard:1x6:25", "between 2 and 200"},
      {"charuco:5x4:30:40", "smaller than the square"},
      {"charuco:5x4:30:20:DICT_9X9_1", "neither an OpenCV dictionary"},
      {"charuco:20x20:30:20:DICT_4X4_50", "has 50 markers, the board needs 200"},
  };
  for (const auto& [spec, message] : cases) {
    const auto parsed = BoardSpec::Parse(spec);
    ASSERT_FALSE(parsed.ok()) << spec;
    EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidArgument) << spec;
    EXPECT_THAT(parsed.status().message(), HasSubstr(message)) << spec;
    EXPECT_THAT(parsed.status().message(), HasSubstr(spec)) << spec;
  }
}

TEST(BoardLayout, EvenRowsDifferBetweenLayoutsOddRowsDoNot) {
  BoardSpec spec = *BoardSpec::Parse("charuco:5x4:40:30");
  BoardSpec legacy = spec;
  legacy.legacy = true;
  EXPECT_FALSE(spec.SquareHasMarker(0, 0));   // 4.6: top-left black
  EXPECT_TRUE(legacy.SquareHasMarker(0, 0));  // pre-4.6, even rows: top-left white
  spec.rows = legacy.rows = 5;
  for (int y = 0; y < 5; ++y) {
    for (int x = 0; x < 5; ++x) EXPECT_EQ(spec.SquareHasMarker(x, y), legacy.SquareHasMarker(x, y));
  }
}

// The 4.6 layout as facedyn renders it is the board OpenCV 4.6 draws (and so detects).
TEST(RenderBoard, MatchesOpenCvCharucoDraw) {
  for (int rows : {4, 5}) {
    BoardSpec spec = *BoardSpec::Parse("charuco:5x" + std::to_string(rows) + ":40:30");
    const cv::Mat ours = RenderBoard(spec, 2.5);  // 100 px squares
    const auto board = cv::aruco::CharucoBoard::create(
        5, rows, 40.0f, 30.0f, cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50));
    cv::Mat theirs;
    board->draw(cv::Size(ours.cols, ours.rows), theirs, 0, 1);
    ASSERT_EQ(theirs.size(), ours.size());
    cv::Mat difference;
    cv::absdiff(ours, theirs, difference);
    // Marker bits are resampled differently (a few pixels along bit edges); squares agree.
    const double differing = cv::countNonZero(difference > 128) / double(ours.total());
    EXPECT_LT(differing, 0.02) << "rows " << rows;
    for (int y = 0; y < rows; ++y) {
      for (int x = 0; x < 5; ++x) {
        const cv::Rect square(x * 100, y * 100, 100, 100);
        EXPECT_NEAR(cv::mean(ours(square))[0], cv::mean(theirs(square))[0], 10.0)
            << "square " << x << "," << y << " rows " << rows;
      }
    }
    // And the corner geometry agrees with OpenCV's.
    for (int id = 0; id < spec.corner_count(); ++id) {
      const Eigen::Vector3d p = spec.CornerInBoard(id);
      EXPECT_NEAR(p.x(), board->chessboardCorners[id].x, 1e-4);
      EXPECT_NEAR(p.y(), board->chessboardCorners[id].y, 1e-4);
    }
  }
}

struct RenderedView {
  cv::Mat image;
  Camera camera;
  Rigid3 world_from_board;
};

RenderedView RenderView(const BoardSpec& spec, double tilt_rad, double noise, uint32_t seed) {
  Camera camera = Camera::LookAt("c", 800, 600, 900.0, Eigen::Vector3d(0, 0, -500),
                                 Eigen::Vector3d::Zero(), -Eigen::Vector3d::UnitY());
  camera.intrinsics[4] = -0.15;  // barrel distortion
  camera.intrinsics[5] = 0.05;
  const double width =
      (spec.kind == BoardSpec::Kind::kChessboard ? spec.cols + 1 : spec.cols) * spec.square_mm;
  const double height =
      (spec.kind == BoardSpec::Kind::kChessboard ? spec.rows + 1 : spec.rows) * spec.square_mm;
  const Rigid3 world_from_board =
      Rigid3::FromAxisAngle(Eigen::Vector3d(1, 0.3, 0).normalized(), tilt_rad) *
      Rigid3::FromTranslation(Eigen::Vector3d(-0.5 * width, -0.5 * height, 0));
  const double margin = 10.0;
  const cv::Mat texture = RenderBoard(spec, 8.0, margin);
  cv::Mat image = RenderPlanarView(texture, 8.0, margin, camera, world_from_board, 3, 200);
  std::mt19937 rng(seed);
  cv::GaussianBlur(image, image, cv::Size(0, 0), 0.7);
  AddImageNoise(noise, &rng, &image);
  return {image, camera, world_from_board};
}

double CornerErrorPx(const BoardSpec& spec, const RenderedView& view,
                     const BoardObservation& observation, bool reversed) {
  double worst = 0.0;
  for (int i = 0; i < observation.size(); ++i) {
    const int id =
        reversed ? spec.corner_count() - 1 - observation.corner_ids[i] : observation.corner_ids[i];
    Eigen::Vector2d truth;
    EXPECT_TRUE(view.camera.Project(view.world_from_board * spec.CornerInBoard(id), &truth));
    worst = std::max(worst, (truth - observation.pixels[i]).norm());
  }
  return worst;
}

TEST(DetectBoard, ChessboardCornersSubPixel) {
  const BoardSpec spec = *BoardSpec::Parse("chessboard:9x6:20");
  const RenderedView view = RenderView(spec, 0.5, 2.0, 1);
  const auto observation = DetectBoard(view.image, spec);
  ASSERT_TRUE(observation.ok()) << observation.status().ToString();
  ASSERT_EQ(observation->size(), 54);
  const double error = std::min(CornerErrorPx(spec, view, *observation, false),
                                CornerErrorPx(spec, view, *observation, true));
  EXPECT_LT(error, 0.15);
}

TEST(DetectBoard, CharucoBothLayoutsWithEvenRows) {
  for (bool legacy : {false, true}) {
    BoardSpec spec = *BoardSpec::Parse("charuco:8x6:30:22");
    spec.legacy = legacy;
    const RenderedView view = RenderView(spec, 0.6, 2.0, 2);
    const auto observation = DetectBoard(view.image, spec);
    ASSERT_TRUE(observation.ok()) << observation.status().ToString();
    EXPECT_GE(observation->size(), 0.95 * spec.corner_count()) << "legacy " << legacy;
    EXPECT_LT(CornerErrorPx(spec, view, *observation, false), 0.15) << "legacy " << legacy;

    // The other layout's reading of the same image is refused with a hint.
    BoardSpec wrong = spec;
    wrong.legacy = !legacy;
    const auto refused = DetectBoard(view.image, wrong);
    ASSERT_FALSE(refused.ok());
    EXPECT_EQ(refused.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_THAT(refused.status().message(), HasSubstr("legacy"));
  }
}

TEST(DetectBoard, CharucoPartlyOccluded) {
  const BoardSpec spec = *BoardSpec::Parse("charuco:8x5:30:22");
  RenderedView view = RenderView(spec, 0.4, 2.0, 3);
  cv::rectangle(view.image, cv::Rect(0, 0, view.image.cols / 2, view.image.rows), cv::Scalar(90),
                cv::FILLED);
  const auto observation = DetectBoard(view.image, spec);
  ASSERT_TRUE(observation.ok()) << observation.status().ToString();
  EXPECT_GT(observation->size(), 6);
  EXPECT_LT(observation->size(), spec.corner_count());
  EXPECT_LT(CornerErrorPx(spec, view, *observation, false), 0.15);
}

TEST(DetectBoard, NoBoardIsNotFound) {
  cv::Mat blank(480, 640, CV_8UC1, cv::Scalar(128));
  for (const char* text : {"chessboard:9x6:20", "charuco:5x4:30:22"}) {
    const auto observation = DetectBoard(blank, *BoardSpec::Parse(text));
    ASSERT_FALSE(observation.ok());
    EXPECT_EQ(observation.status().code(), StatusCode::kNotFound);
  }
  const auto wrong_type =
      DetectBoard(cv::Mat(10, 10, CV_32F), *BoardSpec::Parse("chessboard:9x6:20"));
  EXPECT_EQ(wrong_type.status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace facedyn::reconstruct
