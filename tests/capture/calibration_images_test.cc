// `facedyn sim calibration-images`: rendered boards are found by OpenCV where the ground truth
// says their corners are.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "capture/camera_model.h"
#include "tests/capture/cli_helpers.h"
#include "tests/support/test_support.h"

namespace facedyn::capture {
namespace {

TEST(CalibrationImages, BoardsAreDetectedAtTheirTrueCorners) {
  testing::TempDir dir;
  std::string output;
  ASSERT_EQ(testing::RunCommand(Facedyn() + " -q sim calibration-images --config " + kSource +
                                    "/config/capture/sim3.yaml --out " + dir.Join("calib") +
                                    " --poses 3 --seed 4",
                                &output),
            0)
      << output;
  auto cameras = ReadCameraModels(dir.Join("calib/cameras.yaml"));
  ASSERT_TRUE(cameras.ok()) << cameras.status().message();
  ASSERT_EQ(cameras->size(), 3u);
  // corners.csv: camera,pose,corner,u,v,visible
  std::map<std::pair<int, int>, std::vector<cv::Point2f>> truth;
  std::ifstream csv(dir.Join("calib/corners.csv"));
  std::string line;
  std::getline(csv, line);
  ASSERT_EQ(line, "camera,pose,corner,u,v,visible");
  while (std::getline(csv, line)) {
    std::stringstream row(line);
    int camera, pose, corner, visible;
    float u, v;
    char comma;
    row >> camera >> comma >> pose >> comma >> corner >> comma >> u >> comma >> v >> comma >>
        visible;
    if (visible) truth[{camera, pose}].emplace_back(u, v);
  }
  int found = 0;
  for (int camera = 0; camera < 3; ++camera) {
    for (int pose = 0; pose < 3; ++pose) {
      const cv::Mat image = cv::imread(dir.Join("calib/cam" + std::to_string(camera) + "/pose00" +
                                                std::to_string(pose) + ".png"),
                                       cv::IMREAD_GRAYSCALE);
      ASSERT_FALSE(image.empty());
      EXPECT_EQ(image.cols, 320);
      std::vector<cv::Point2f> corners;
      if (!cv::findChessboardCorners(image, cv::Size(9, 6), corners)) continue;
      cv::cornerSubPix(image, corners, cv::Size(3, 3), cv::Size(-1, -1),
                       cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-3));
      ++found;
      const auto& expected = truth[{camera, pose}];
      ASSERT_EQ(expected.size(), 54u);
      for (const cv::Point2f& p : corners) {
        double best = 1e9;
        for (const cv::Point2f& t : expected)
          best = std::min(best, static_cast<double>(std::hypot(p.x - t.x, p.y - t.y)));
        EXPECT_LT(best, 0.35);
      }
    }
  }
  EXPECT_GE(found, 5);
}

TEST(CalibrationImages, BadBoardIsRefused) {
  testing::TempDir dir;
  std::string output;
  EXPECT_EQ(testing::RunCommand(Facedyn() + " sim calibration-images --config " + kSource +
                                    "/config/capture/sim3.yaml --out " + dir.Join("c") +
                                    " --board circles",
                                &output),
            1);
  EXPECT_NE(output.find("circles"), std::string::npos) << output;
}

}  // namespace
}  // namespace facedyn::capture
