#include "reconstruct/calibration.h"

#include <ceres/ceres.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "reconstruct/synthetic_views.h"
#include "tests/support/test_support.h"

namespace facedyn::reconstruct {
namespace {

using ::testing::HasSubstr;

TEST(BoardCornerResidual, MatchesProjectionAndFiniteDifferences) {
  Camera camera = Camera::LookAt("c", 1280, 1024, 2000.0, Eigen::Vector3d(50, 80, 700),
                                 Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY());
  camera.intrinsics = {2000.0, 2010.0, 640.0, 512.0, -0.1, 0.05, 0.002, -0.001, 0.02};
  const Rigid3 world_from_board = Rigid3::FromAxisAngle(Eigen::Vector3d(0.2, 1, 0).normalized(),
                                                        0.4, Eigen::Vector3d(-60, -40, 10));
  const Eigen::Vector3d point_in_board(75, 50, 0);
  Eigen::Vector2d expected;
  ASSERT_TRUE(camera.Project(world_from_board * point_in_board, &expected));
  const Eigen::Vector2d observed = expected + Eigen::Vector2d(0.7, -0.3);
  const BoardCornerResidual functor(observed, point_in_board);
  Intrinsics intrinsics = camera.intrinsics;
  PoseBlock cam_from_world = ToPoseBlock(camera.cam_from_world);
  PoseBlock board = ToPoseBlock(world_from_board);
  double residual[2];
  functor(intrinsics.data(), cam_from_world.data(), board.data(), residual);
  EXPECT_NEAR(residual[0], 0.7, 1e-7);
  EXPECT_NEAR(residual[1], -0.3, 1e-7);

  // Autodiff Jacobians against central differences.
  ceres::AutoDiffCostFunction<BoardCornerResidual, 2, kIntrinsicCount, 6, 6> cost(
      new BoardCornerResidual(observed, point_in_board));
  double* parameters[3] = {intrinsics.data(), cam_from_world.data(), board.data()};
  std::vector<double> j0(2 * 9), j1(2 * 6), j2(2 * 6);
  double* jacobians[3] = {j0.data(), j1.data(), j2.data()};
  ASSERT_TRUE(cost.Evaluate(parameters, residual, jacobians));
  const int sizes[3] = {9, 6, 6};
  for (int block = 0; block < 3; ++block) {
    for (int k = 0; k < sizes[block]; ++k) {
      const double h = 1e-6 * std::max(1.0, std::abs(parameters[block][k]));
      const double saved = parameters[block][k];
      double plus[2], minus[2];
      parameters[block][k] = saved + h;
      functor(parameters[0], parameters[1], parameters[2], plus);
      parameters[block][k] = saved - h;
      functor(parameters[0], parameters[1], parameters[2], minus);
      parameters[block][k] = saved;
      for (int r = 0; r < 2; ++r) {
        const double numeric = (plus[r] - minus[r]) / (2 * h);
        const double analytic = jacobians[block][r * sizes[block] + k];
        EXPECT_NEAR(analytic, numeric, 1e-5 * std::max(1.0, std::abs(numeric)))
            << "block " << block << " parameter " << k << " residual " << r;
      }
    }
  }
}

TEST(PoseBlock, RoundTrip) {
  const Rigid3 t =
      Rigid3::FromAxisAngle(Eigen::Vector3d(1, 2, 3).normalized(), 2.5, Eigen::Vector3d(4, 5, 6));
  EXPECT_TRUE(FromPoseBlock(ToPoseBlock(t)).IsApprox(t, 1e-12));
}

// The 13 real OpenCV sample photographs: facedyn against cv::calibrateCamera on the same corners.
TEST(Calibrate, RealOpenCvSampleImagesMatchOpenCv) {
  FACEDYN_REQUIRE_SHARED_ASSET(dir, "opencv-calib");
  const BoardSpec board = *BoardSpec::Parse("chessboard:9x6:1");
  CalibrationInput input;
  input.board = board;
  input.cameras.push_back({"left", 640, 480});
  std::vector<std::vector<cv::Point3f>> object_points;
  std::vector<std::vector<cv::Point2f>> image_points;
  for (int i = 1; i <= 14; ++i) {
    if (i == 10) continue;  // not upstream
    char name[32];
    std::snprintf(name, sizeof(name), "left%02d.jpg", i);
    const cv::Mat gray = cv::imread(dir + "/" + name, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(gray.empty()) << name;
    ASSERT_EQ(gray.cols, 640);
    const auto corners = DetectBoard(gray, board);
    ASSERT_TRUE(corners.ok()) << name << ": " << corners.status().ToString();
    input.view_names.push_back(name);
    input.observations.push_back({0, static_cast<int>(input.view_names.size()) - 1, *corners});
    object_points.emplace_back();
    image_points.emplace_back();
    for (int k = 0; k < corners->size(); ++k) {
      const Eigen::Vector3d p = board.CornerInBoard(corners->corner_ids[k]);
      object_points.back().emplace_back(p.x(), p.y(), 0.0f);
      image_points.back().emplace_back(corners->pixels[k].x(), corners->pixels[k].y());
    }
  }
  ASSERT_EQ(input.view_names.size(), 13u);
  CalibrationSummary summary;
  const auto result = Calibrate(input, CalibrationOptions(), &summary);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  cv::Mat k, distortion;
  std::vector<cv::Mat> rvecs, tvecs;
  const double opencv_rms = cv::calibrateCamera(object_points, image_points, cv::Size(640, 480), k,
                                                distortion, rvecs, tvecs);
  const Camera& camera = result->cameras[0];
  RecordProperty("rms_px", std::to_string(result->rms_px));
  std::printf(
      "facedyn: rms %.4f px fx %.2f fy %.2f cx %.2f cy %.2f (outliers %d)\n"
      "opencv:  rms %.4f px fx %.2f fy %.2f cx %.2f cy %.2f\n",
      result->rms_px, camera.fx(), camera.fy(), camera.cx(), camera.cy(), summary.outliers,
      opencv_rms, k.at<double>(0, 0), k.at<double>(1, 1), k.at<double>(0, 2), k.at<double>(1, 2));
  EXPECT_TRUE(summary.converged);
  EXPECT_LE(result->rms_px, 0.45);
  EXPECT_NEAR(camera.fx(), k.at<double>(0, 0), 0.01 * k.at<double>(0, 0));
  EXPECT_NEAR(camera.cx(), k.at<double>(0, 2), 0.01 * k.at<double>(0, 2));
  EXPECT_NEAR(camera.cy(), k.at<double>(1, 2), 0.01 * k.at<double>(1, 2));
  EXPECT_EQ(result->view_errors.size(), 13u);
}

struct SyntheticRig {
  std::vector<Camera> cameras;
  CalibrationInput input;
  double injected_rms_px = 0.0;
};

// A 4-camera ring and a ChArUco board waved through the shared volume; corners projected
// through the true cameras with Gaussian noise of `sigma_px` per axis.
SyntheticRig MakeSyntheticRig(double sigma_px, int views, uint32_t seed) {
  SyntheticRig rig;
  CameraRingOptions ring;
  ring.camera_count = 4;
  ring.width_px = 1280;
  ring.height_px = 1024;
  ring.focal_px = 1800.0;
  ring.radius_mm = 700.0;
  ring.arc_deg = 90.0;
  rig.cameras = MakeCameraRing(ring);
  for (int c = 0; c < 4; ++c) {
    rig.cameras[c].intrinsics[4] = -0.08 + 0.02 * c;
    rig.cameras[c].intrinsics[5] = 0.03;
    rig.cameras[c].intrinsics[2] += 7.0 * c - 10.0;
  }
  rig.input.board = *BoardSpec::Parse("charuco:10x7:25:18");
  for (int c = 0; c < 4; ++c) rig.input.cameras.push_back({rig.cameras[c].name, 1280, 1024});
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma_px);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  double sq = 0.0;
  int n = 0;
  const Eigen::Vector3d board_centre(5.5 * 25, 4 * 25, 0);
  for (int v = 0; v < views; ++v) {
    // Board facing the rig (its z axis towards -Z), tilted up to ~35 degrees, moved around.
    const Rigid3 facing = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), M_PI);
    const Rigid3 tilt = Rigid3::FromAxisAngle(
        Eigen::Vector3d(uniform(rng), uniform(rng), 0.3 * uniform(rng)).normalized(),
        0.6 * std::abs(uniform(rng)));
    const Eigen::Vector3d position(80 * uniform(rng), 60 * uniform(rng), 80 * uniform(rng));
    const Rigid3 world_from_board =
        Rigid3::FromTranslation(position) * tilt * facing * Rigid3::FromTranslation(-board_centre);
    rig.input.view_names.push_back("view" + std::to_string(v));
    for (int c = 0; c < 4; ++c) {
      BoardObservation observation;
      for (int id = 0; id < rig.input.board.corner_count(); ++id) {
        const Eigen::Vector3d p = world_from_board * rig.input.board.CornerInBoard(id);
        // Seen only from the front.
        const Eigen::Vector3d normal = world_from_board.RotateVector(-Eigen::Vector3d::UnitZ());
        if (normal.dot(rig.cameras[c].CenterInWorld() - p) <= 0) continue;
        Eigen::Vector2d pixel;
        if (!rig.cameras[c].Project(p, &pixel) || !rig.cameras[c].InImage(pixel, 5)) continue;
        const Eigen::Vector2d e(noise(rng), noise(rng));
        sq += e.squaredNorm();
        ++n;
        observation.corner_ids.push_back(id);
        observation.pixels.push_back(pixel + e);
      }
      if (observation.size() > 0) rig.input.observations.push_back({c, v, observation});
    }
  }
  rig.injected_rms_px = std::sqrt(sq / n);
  return rig;
}

// |estimated - true| camera centre (mm) after the rigid alignment of estimated onto true centres.
std::vector<double> AlignedCentreErrorsMm(const std::vector<Camera>& truth,
                                          const std::vector<Camera>& estimate) {
  Eigen::Matrix3Xd a(3, truth.size()), b(3, truth.size());
  for (size_t c = 0; c < truth.size(); ++c) {
    a.col(c) = estimate[c].CenterInWorld();
    b.col(c) = truth[c].CenterInWorld();
  }
  const Eigen::Matrix4d b_from_a = Eigen::umeyama(a, b, false);
  std::vector<double> errors;
  for (size_t c = 0; c < truth.size(); ++c) {
    errors.push_back(
        ((b_from_a.topLeftCorner<3, 3>() * a.col(c) + b_from_a.topRightCorner<3, 1>()) - b.col(c))
            .norm());
  }
  return errors;
}

TEST(Calibrate, SyntheticRigRecoversCamerasWithinNoise) {
  const double sigma_px = 0.3;
  SyntheticRig rig = MakeSyntheticRig(sigma_px, 40, 7);
  // A few gross outliers (mis-detected corners), which must be rejected.
  for (int k = 0; k < 10; ++k)
    rig.input.observations[3 * k].corners.pixels[2] += Eigen::Vector2d(15, -9);
  CalibrationSummary summary;
  const auto result = Calibrate(rig.input, CalibrationOptions(), &summary);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  std::printf("injected rms %.3f px, calibration rms %.3f px, outliers %d\n", rig.injected_rms_px,
              result->rms_px, summary.outliers);
  EXPECT_TRUE(summary.converged);
  EXPECT_LE(result->rms_px, 1.5 * rig.injected_rms_px);
  EXPECT_GE(summary.outliers, 10);
  EXPECT_LE(summary.outliers, 40);
  // A calibration is defined up to a rigid motion of the whole rig (here the world is camera
  // 0, whose own intrinsic errors would tilt everything): compare centres after the best rigid
  // alignment (Umeyama, no scale: the board fixes the scale).
  const std::vector<double> errors = AlignedCentreErrorsMm(rig.cameras, result->cameras);
  for (int c = 0; c < 4; ++c) {
    std::printf("camera %d centre error %.3f mm, fx error %.2f px\n", c, errors[c],
                result->cameras[c].fx() - rig.cameras[c].fx());
    EXPECT_LT(errors[c], 0.5) << "camera " << c;
    EXPECT_NEAR(result->cameras[c].fx(), rig.cameras[c].fx(), 0.005 * rig.cameras[c].fx());
  }
}

TEST(Calibrate, ChessboardHalfTurnsAreResolvedAcrossCameras) {
  // A chessboard's corner order may come out reversed in one camera; the rig must still close.
  SyntheticRig rig = MakeSyntheticRig(0.2, 16, 11);
  rig.input.board = *BoardSpec::Parse("chessboard:9x6:25");
  const BoardSpec& board = rig.input.board;
  // Re-project chessboard corners (all must be visible to count as detected).
  CalibrationInput input = rig.input;
  input.observations.clear();
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.2);
  // Board poses: a simple set in front of the rig.
  for (int v = 0; v < 16; ++v) {
    const Rigid3 world_from_board =
        Rigid3::FromTranslation(
            Eigen::Vector3d(10 * (v % 4) - 15, 8 * (v / 4) - 12, 20 * (v % 3))) *
        Rigid3::FromAxisAngle(Eigen::Vector3d(std::cos(v), std::sin(v), 0), 0.35) *
        Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), M_PI) *
        Rigid3::FromTranslation(-Eigen::Vector3d(125, 87.5, 0));
    for (int c = 0; c < 4; ++c) {
      BoardObservation observation;
      bool all = true;
      for (int id = 0; id < board.corner_count() && all; ++id) {
        Eigen::Vector2d pixel;
        all = rig.cameras[c].Project(world_from_board * board.CornerInBoard(id), &pixel) &&
              rig.cameras[c].InImage(pixel, 5);
        observation.corner_ids.push_back(id);
        observation.pixels.push_back(pixel + Eigen::Vector2d(noise(rng), noise(rng)));
      }
      if (!all) continue;
      if ((v + c) % 3 == 0) std::reverse(observation.pixels.begin(), observation.pixels.end());
      input.observations.push_back({c, v, observation});
    }
  }
  const auto result = Calibrate(input, CalibrationOptions());
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  EXPECT_LT(result->rms_px, 0.4);
  const std::vector<double> errors = AlignedCentreErrorsMm(rig.cameras, result->cameras);
  for (int c = 0; c < 4; ++c) EXPECT_LT(errors[c], 0.5) << "camera " << c;
}

TEST(Calibrate, DisconnectedRigAndTooFewViewsAreReported) {
  SyntheticRig rig = MakeSyntheticRig(0.2, 12, 5);
  CalibrationInput few = rig.input;
  few.observations.erase(std::remove_if(few.observations.begin(), few.observations.end(),
                                        [](const auto& o) { return o.camera == 2 && o.view > 1; }),
                         few.observations.end());
  auto result = Calibrate(few, CalibrationOptions());
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result.status().message(), HasSubstr("camera cam2"));
  EXPECT_THAT(result.status().message(), HasSubstr("need at least 3"));

  // Camera 3's views exist but share no instant with the others.
  CalibrationInput disconnected = rig.input;
  for (auto& o : disconnected.observations) {
    if (o.camera == 3) o.view = static_cast<int>(disconnected.view_names.size());
  }
  disconnected.view_names.push_back("alone");
  // Give each of camera 3's observations its own view so it still has enough views.
  int extra = 0;
  for (auto& o : disconnected.observations) {
    if (o.camera != 3) continue;
    o.view = static_cast<int>(disconnected.view_names.size());
    disconnected.view_names.push_back("alone" + std::to_string(extra++));
  }
  result = Calibrate(disconnected, CalibrationOptions());
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result.status().message(), HasSubstr("not connected"));
  EXPECT_THAT(result.status().message(), HasSubstr("cam3"));
}

TEST(CalibrationFile, RoundTripTruncatedAndCorrupt) {
  SyntheticRig rig = MakeSyntheticRig(0.2, 10, 9);
  const auto result = Calibrate(rig.input, CalibrationOptions());
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  testing::TempDir dir;
  const std::string path = dir.Join("calibration.yaml");
  ASSERT_TRUE(SaveCalibration(*result, path).ok());
  const auto loaded = LoadCalibration(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  ASSERT_EQ(loaded->cameras.size(), 4u);
  for (int c = 0; c < 4; ++c) {
    for (int k = 0; k < kIntrinsicCount; ++k) {
      EXPECT_NEAR(loaded->cameras[c].intrinsics[k], result->cameras[c].intrinsics[k],
                  1e-9 * std::max(1.0, std::abs(result->cameras[c].intrinsics[k])));
    }
    EXPECT_TRUE(
        loaded->cameras[c].cam_from_world.IsApprox(result->cameras[c].cam_from_world, 1e-9));
    EXPECT_EQ(loaded->cameras[c].name, result->cameras[c].name);
  }
  const std::string text = testing::ReadBytes(path);
  // The file is readable by OpenCV's FileStorage with the documented names.
  cv::FileStorage fs(path, cv::FileStorage::READ);
  cv::Mat k;
  fs["cameras"][1]["camera_matrix"] >> k;
  EXPECT_NEAR(k.at<double>(0, 0), result->cameras[1].fx(), 1e-9);
  EXPECT_THAT(text, HasSubstr("views"));
  EXPECT_THAT(text, HasSubstr("rms_px"));

  testing::WriteBytes(dir.Join("truncated.yaml"), text.substr(0, text.size() / 3));
  EXPECT_FALSE(LoadCalibration(dir.Join("truncated.yaml")).ok());
  std::string corrupt = text;
  const size_t at = corrupt.find("cam_from_world");
  ASSERT_NE(at, std::string::npos);
  corrupt.replace(corrupt.find("data: [", at) + 7, 1, "9");  // R(0,0) no longer a rotation
  testing::WriteBytes(dir.Join("corrupt.yaml"), corrupt);
  const auto bad = LoadCalibration(dir.Join("corrupt.yaml"));
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("corrupt.yaml"));
  EXPECT_FALSE(LoadCalibration(dir.Join("missing.yaml")).ok());
}

}  // namespace
}  // namespace facedyn::reconstruct
