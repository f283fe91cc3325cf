// `facedyn calibrate` end to end: real photographs, rendered multi-camera ChArUco views, and
// bad input (corrupt image, bad board spec, no images).

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "reconstruct/board.h"
#include "reconstruct/calibration.h"
#include "reconstruct/calibration_images.h"
#include "reconstruct/synthetic_views.h"
#include "tests/support/test_support.h"

namespace facedyn::reconstruct {
namespace {

using ::facedyn::testing::FacedynExecutable;
using ::facedyn::testing::RunCommand;
using ::facedyn::testing::TempDir;
using ::testing::HasSubstr;

TEST(CalibrateCommand, RealPhotographsWithACorruptOne) {
  FACEDYN_REQUIRE_SHARED_ASSET(dir, "opencv-calib");
  TempDir temp;
  std::filesystem::create_directories(temp.Join("left"));
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (name.size() == 10 && name.rfind("left", 0) == 0) {  // leftNN.jpg
      std::filesystem::copy_file(entry.path(), temp.Join("left/" + name));
    }
  }
  testing::WriteBytes(temp.Join("left/left99.jpg"), "\xff\xd8\xff\xe0 not really a jpeg");
  std::string out;
  const int rc = RunCommand(FacedynExecutable() + " --quiet calibrate --images '" +
                                temp.Join("left/*.jpg") + "' --board chessboard:9x6:1 --out " +
                                temp.Join("calibration.yaml") + " --json",
                            &out);
  ASSERT_EQ(rc, 0) << out;
  const auto json = nlohmann::json::parse(out.substr(out.find('{')));
  EXPECT_LE(json["rms_px"].get<double>(), 0.45);
  ASSERT_EQ(json["cameras"].size(), 1u);
  EXPECT_EQ(json["cameras"][0]["name"], "left");
  EXPECT_NEAR(json["cameras"][0]["fx"].get<double>(), 536.0, 0.02 * 536.0);
  ASSERT_EQ(json["skipped"].size(), 1u);
  EXPECT_THAT(json["skipped"][0]["image"].get<std::string>(), HasSubstr("left99.jpg"));
  EXPECT_EQ(json["views"].size(), 13u);
  const auto loaded = LoadCalibration(temp.Join("calibration.yaml"));
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_NEAR(loaded->rms_px, json["rms_px"].get<double>(), 1e-9);
}

// Three cameras in folders cam0..cam2 photograph a ChArUco board at the same instants.
TEST(CalibrateCommand, RenderedMultiCameraCharuco) {
  TempDir temp;
  CameraRingOptions ring;
  ring.camera_count = 3;
  ring.width_px = 800;
  ring.height_px = 600;
  ring.focal_px = 800.0;
  ring.radius_mm = 600.0;
  ring.arc_deg = 60.0;
  std::vector<Camera> cameras = MakeCameraRing(ring);
  for (auto& camera : cameras) camera.intrinsics[4] = -0.05;
  const BoardSpec board = *BoardSpec::Parse("charuco:9x6:30:22");
  const cv::Mat texture = RenderBoard(board, 6.0, 10.0);
  std::vector<CameraRays> rays;
  for (const Camera& camera : cameras) rays.push_back(MakeCameraRays(camera, 2));
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (int v = 0; v < 12; ++v) {
    const Rigid3 world_from_board =
        Rigid3::FromTranslation(
            Eigen::Vector3d(40 * uniform(rng), 30 * uniform(rng), 60 * uniform(rng))) *
        Rigid3::FromAxisAngle(Eigen::Vector3d(uniform(rng), uniform(rng), 0).normalized(),
                              0.5 * std::abs(uniform(rng))) *
        Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), M_PI) *
        Rigid3::FromTranslation(-Eigen::Vector3d(135, 90, 0));
    for (const CameraRays& camera_rays : rays) {
      const Camera& camera = camera_rays.camera;
      std::filesystem::create_directories(temp.Join(camera.name));
      cv::Mat image = RenderPlanarView(texture, 6.0, 10.0, camera_rays, world_from_board, 160);
      AddImageNoise(1.5, &rng, &image);
      char name[32];
      std::snprintf(name, sizeof(name), "/%04d.png", v);
      cv::imwrite(temp.Join(camera.name) + name, image);
    }
  }
  std::string out;
  const int rc =
      RunCommand(FacedynExecutable() + " --quiet calibrate --images '" + temp.Join("cam*/*.png") +
                     "' --board charuco:9x6:30:22 --out " + temp.Join("rig.yaml") + " --json",
                 &out);
  ASSERT_EQ(rc, 0) << out;
  const auto json = nlohmann::json::parse(out.substr(out.find('{')));
  EXPECT_LT(json["rms_px"].get<double>(), 0.3);
  const auto loaded = LoadCalibration(temp.Join("rig.yaml"));
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  ASSERT_EQ(loaded->cameras.size(), 3u);
  // Baselines (gauge-free) against the truth.
  for (int c = 1; c < 3; ++c) {
    const double truth = (cameras[c].CenterInWorld() - cameras[0].CenterInWorld()).norm();
    const double estimate = loaded->cameras[c].CenterInWorld().norm();  // camera 0 is the origin
    EXPECT_NEAR(estimate, truth, 1.0) << "camera " << c;
    EXPECT_EQ(loaded->cameras[c].name, cameras[c].name);
  }
}

TEST(CalibrateCommand, BadInputIsReportedByName) {
  TempDir temp;
  std::string out;
  EXPECT_EQ(RunCommand(FacedynExecutable() + " calibrate --images '" + temp.Join("*.png") +
                           "' --board chessboard:9x6:25 --out " + temp.Join("x.yaml"),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("no image matches"));
  testing::WriteBytes(temp.Join("a.png"), "garbage");
  EXPECT_EQ(RunCommand(FacedynExecutable() + " calibrate --images " + temp.Join("a.png") +
                           " --board chessboard:9x6x:25 --out " + temp.Join("x.yaml"),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("board spec 'chessboard:9x6x:25'"));
  EXPECT_EQ(RunCommand(FacedynExecutable() + " --quiet calibrate --images " + temp.Join("a.png") +
                           " --board chessboard:9x6:25 --out " + temp.Join("x.yaml"),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("found in none"));
  EXPECT_THAT(out, HasSubstr("a.png"));
  EXPECT_FALSE(std::filesystem::exists(temp.Join("x.yaml")));
}

}  // namespace
}  // namespace facedyn::reconstruct
