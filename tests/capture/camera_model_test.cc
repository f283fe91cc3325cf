#include "capture/camera_model.h"

#include <gtest/gtest.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <random>

#include "tests/support/test_support.h"

namespace facedyn::capture {
namespace {

CameraModel DistortedCamera(const std::string& name = "cam0") {
  CameraModel camera = CameraModel::LookAt(name, 1280, 1024, 3500.0, Eigen::Vector3d(200, 30, 750),
                                           Eigen::Vector3d(0, 0, 0), Eigen::Vector3d::UnitY());
  camera.intrinsics = {3510.0, 3490.0, 645.2, 508.7, -0.12, 0.08, 0.0012, -0.0007, -0.01};
  return camera;
}

TEST(CameraModel, ProjectionMatchesOpenCvProjectPoints) {
  const CameraModel camera = DistortedCamera();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> coordinate(-90.0, 90.0);
  std::vector<cv::Point3d> points;
  for (int i = 0; i < 50; ++i)
    points.emplace_back(coordinate(rng), coordinate(rng), coordinate(rng));
  const Eigen::Matrix3d r = camera.cam_from_world.RotationMatrix();
  cv::Mat rmat(3, 3, CV_64F), rvec, tvec(3, 1, CV_64F);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) rmat.at<double>(i, j) = r(i, j);
    tvec.at<double>(i) = camera.cam_from_world.translation()[i];
  }
  cv::Rodrigues(rmat, rvec);
  cv::Mat k =
      (cv::Mat_<double>(3, 3) << camera.fx(), 0, camera.cx(), 0, camera.fy(), camera.cy(), 0, 0, 1);
  cv::Mat dist = (cv::Mat_<double>(1, 5) << camera.intrinsics[4], camera.intrinsics[5],
                  camera.intrinsics[6], camera.intrinsics[7], camera.intrinsics[8]);
  std::vector<cv::Point2d> expected;
  cv::projectPoints(points, rvec, tvec, k, dist, expected);
  for (size_t i = 0; i < points.size(); ++i) {
    Eigen::Vector2d pixel;
    ASSERT_TRUE(camera.Project(Eigen::Vector3d(points[i].x, points[i].y, points[i].z), &pixel));
    EXPECT_NEAR(pixel.x(), expected[i].x, 1e-6);
    EXPECT_NEAR(pixel.y(), expected[i].y, 1e-6);
  }
}

TEST(CameraModel, LookAtPutsTargetAtPrincipalPointWithUpUp) {
  const CameraModel camera = CameraModel::LookAt("c", 640, 480, 800, Eigen::Vector3d(0, 0, 500),
                                                 Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY());
  Eigen::Vector2d centre, above;
  ASSERT_TRUE(camera.Project(Eigen::Vector3d::Zero(), &centre));
  EXPECT_NEAR(centre.x(), camera.cx(), 1e-9);
  EXPECT_NEAR(centre.y(), camera.cy(), 1e-9);
  ASSERT_TRUE(camera.Project(Eigen::Vector3d(0, 10, 0), &above));
  EXPECT_LT(above.y(), centre.y());  // world up is image up
  EXPECT_NEAR((camera.CenterInWorld() - Eigen::Vector3d(0, 0, 500)).norm(), 0.0, 1e-9);
  Eigen::Vector2d behind;
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(0, 0, 600), &behind));
}

TEST(CameraModel, UndistortInvertsDistortion) {
  const CameraModel camera = DistortedCamera();
  for (double u : {0.0, 300.0, 640.0, 1279.0}) {
    for (double v : {0.0, 500.0, 1023.0}) {
      const Eigen::Vector2d normalised = camera.Undistort(Eigen::Vector2d(u, v));
      Eigen::Vector2d back;
      ASSERT_TRUE(
          camera.ProjectFromCam(Eigen::Vector3d(normalised.x(), normalised.y(), 1.0), &back));
      EXPECT_NEAR(back.x(), u, 1e-8);
      EXPECT_NEAR(back.y(), v, 1e-8);
    }
  }
}

TEST(CameraModels, RoundTripThroughOpenCvYaml) {
  testing::TempDir dir;
  const std::vector<CameraModel> cameras = {DistortedCamera("cam0"), DistortedCamera("cam1")};
  ASSERT_TRUE(WriteCameraModels(dir.Join("cameras.yaml"), cameras).ok());
  // OpenCV itself reads the file.
  cv::FileStorage fs(dir.Join("cameras.yaml"), cv::FileStorage::READ);
  ASSERT_TRUE(fs.isOpened());
  cv::Mat k;
  fs["cameras"][1]["camera_matrix"] >> k;
  EXPECT_DOUBLE_EQ(k.at<double>(0, 0), 3510.0);
  auto read = ReadCameraModels(dir.Join("cameras.yaml"));
  ASSERT_TRUE(read.ok()) << read.status().message();
  ASSERT_EQ(read->size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ((*read)[i].name, cameras[i].name);
    EXPECT_EQ((*read)[i].width_px, 1280);
    EXPECT_EQ((*read)[i].height_px, 1024);
    for (int p = 0; p < kIntrinsicCount; ++p)
      EXPECT_DOUBLE_EQ((*read)[i].intrinsics[p], cameras[i].intrinsics[p]);
    EXPECT_TRUE((*read)[i].cam_from_world.IsApprox(cameras[i].cam_from_world, 1e-9));
  }
}

// OpenCV's FileStorage constructor threw std::length_error (not a cv::Exception) on a key line
// ": 5" inside a matrix, and the process terminated (fuzz/calibration). Now an error naming the
// file.
TEST(CameraModels, MalformedKeyIsAnErrorNotATermination) {
  testing::TempDir dir;
  const std::string path = dir.Join("calibration.yaml");
  testing::WriteBytes(path,
                      "%YAML:1.0\n---\ncamera_count: 7\ncameras:\n   -\n      name: cam0\n"
                      "      image_width: 320\n      image_height: 256\n"
                      "      camera_matrix: !!opencv-matrix\n         rows: 3\n      : 5\n"
                      "         dt: u\n         data: [ -0.05, 0., 0., 0., 0. ]\n");
  const auto read = ReadCameraModels(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(read.status().message().find(path + ": cannot parse"), std::string::npos)
      << read.status().message();
}

// OpenCV sized a matrix from its header before reading the data: rows 262144 x cols 262144 asked
// for 64 GiB (ASan: out of memory; fuzz/calibration). The size is checked against 3x3 first.
TEST(CameraModels, HugeMatrixHeaderIsRefusedBeforeAllocation) {
  testing::TempDir dir;
  const std::string path = dir.Join("calibration.yaml");
  testing::WriteBytes(path,
                      "%YAML:1.0\n---\ncameras:\n   -\n      name: cam0\n"
                      "      image_width: 320\n      image_height: 256\n"
                      "      camera_matrix: !!opencv-matrix\n         rows: 262144\n"
                      "         cols: 262144\n         dt: d\n         data: [ 1. ]\n");
  const auto read = ReadCameraModels(path);
  ASSERT_FALSE(read.ok());
  EXPECT_NE(read.status().message().find("'camera_matrix' must be an opencv-matrix of 3x3"),
            std::string::npos)
      << read.status().message();
}

TEST(CameraModels, TruncatedAndCorruptFilesNameTheProblem) {
  testing::TempDir dir;
  ASSERT_TRUE(WriteCameraModels(dir.Join("cameras.yaml"), {DistortedCamera()}).ok());
  const std::string text = testing::ReadBytes(dir.Join("cameras.yaml"));
  // Truncated in the middle of the distortion matrix.
  testing::WriteBytes(dir.Join("truncated.yaml"),
                      text.substr(0, text.find("distortion_coefficients") + 30));
  auto truncated = ReadCameraModels(dir.Join("truncated.yaml"));
  ASSERT_FALSE(truncated.ok());
  EXPECT_NE(truncated.status().message().find("truncated.yaml"), std::string::npos);
  // A pose that is not rigid.
  std::string corrupt = text;
  const size_t pose = corrupt.find("cam_from_world");
  const size_t data = corrupt.find("data: [", pose) + 7;
  corrupt.replace(data, corrupt.find(',', data) - data, "5.");
  testing::WriteBytes(dir.Join("corrupt.yaml"), corrupt);
  auto bad_pose = ReadCameraModels(dir.Join("corrupt.yaml"));
  ASSERT_FALSE(bad_pose.ok());
  EXPECT_NE(bad_pose.status().message().find("cam_from_world"), std::string::npos)
      << bad_pose.status().message();
  // A missing field.
  std::string missing = text;
  missing.replace(missing.find("image_width"), 11, "image_wodth");
  testing::WriteBytes(dir.Join("missing.yaml"), missing);
  auto no_width = ReadCameraModels(dir.Join("missing.yaml"));
  ASSERT_FALSE(no_width.ok());
  EXPECT_NE(no_width.status().message().find("image_width"), std::string::npos);
  EXPECT_FALSE(ReadCameraModels(dir.Join("absent.yaml")).ok());
}

// OpenCV's YAML reader never returned on a second directive glued to the document marker
// (fuzz/calibration); a calibration's outline is checked before OpenCV reads it.
TEST(CameraModels, SecondDirectiveOrDocumentIsRefusedBeforeOpenCvReadsIt) {
  testing::TempDir dir;
  struct Case {
    std::string text;
    std::string message;
  };
  const Case cases[] = {
      {"%YAML:1.0\n---%YAML:1\nc.0\n--a-", "calibration.yaml:2: expected '---'"},
      {"%YAML:1.0\n---\ncameras: []\n---\nmore: 1\n", "calibration.yaml:4: a calibration is one"},
      {"%YAML:1.0\n---\ncameras: []\n%YAML:1.0\n", "calibration.yaml:4:"},
      {"cameras: []\n", "calibration.yaml:1: a calibration starts with"},
      {"%YAML:1.0", "too short"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.text);
    testing::WriteBytes(dir.Join("calibration.yaml"), c.text);
    const auto read = ReadCameraModels(dir.Join("calibration.yaml"));
    ASSERT_FALSE(read.ok());
    EXPECT_NE(read.status().message().find(c.message), std::string::npos)
        << read.status().message();
  }
}

TEST(CameraModels, WriteRefusesInvalidCamera) {
  testing::TempDir dir;
  CameraModel camera = DistortedCamera();
  camera.intrinsics[0] = -1;
  const Status status = WriteCameraModels(dir.Join("c.yaml"), {camera});
  EXPECT_FALSE(status.ok());
  EXPECT_NE(status.message().find("fx"), std::string::npos);
}

}  // namespace
}  // namespace facedyn::capture
