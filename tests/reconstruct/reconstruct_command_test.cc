// `facedyn reconstruct` end to end: a capture session written with capture/'s writers, holding
// rendered marker images of a simulated take from 8 cameras, with a dropped frame, a camera out
// of sync for one frame and a camera missing from the calibration.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <random>

#include "capture/frame_file.h"
#include "capture/session.h"
#include "core/json_io.h"
#include "core/take.h"
#include "reconstruct/calibration.h"
#include "reconstruct/session_input.h"
#include "reconstruct/synthetic_views.h"
#include "sim/performance.h"
#include "tests/reconstruct/reconstruct_test_util.h"
#include "tests/support/test_support.h"

namespace facedyn::reconstruct {
namespace {

using ::facedyn::testing::FacedynExecutable;
using ::facedyn::testing::RunCommand;
using ::facedyn::testing::TempDir;
using ::testing::HasSubstr;

constexpr int kDropCamera = 2, kDropTrigger = 2;
constexpr int kLateCamera = 5, kLateTrigger = 4;

// Writes DIR as a session with one take "smile" and returns the simulated truth.
Take WriteSession(const std::string& dir) {
  const FaceRig& rig = testing::ProceduralFace();
  sim::PerformanceOptions performance;
  performance.expression = "smile";
  performance.motion.kind = sim::MotionKind::kPlatform;
  performance.motion.platform_hz = 11.0;
  performance.seconds = 0.04;
  performance.fps = 128.0;
  Take take = sim::SimulatePerformance(rig, performance).value();
  const std::vector<Camera> cameras = testing::FaceCameraRing(8);
  std::vector<capture::SessionCameraInfo> infos;
  for (const Camera& c : cameras)
    infos.push_back({c.name, "sim", c.width_px, c.height_px, "mono8"});
  auto session = capture::SessionWriter::Open(dir, "virtual", infos, Json::object()).value();
  // Calibration without cam7: that camera is left out of the reconstruction.
  RigCalibration calibration;
  calibration.cameras.assign(cameras.begin(), cameras.end() - 1);
  EXPECT_TRUE(SaveCalibration(calibration, dir + "/calibration.yaml").ok());
  EXPECT_TRUE(session->SetCalibration("calibration.yaml").ok());
  const int frames = take.frame_count();
  const std::string take_dir = session->BeginTake("smile", 128.0, frames).value();
  std::mt19937 rng(3);
  capture::TakeResult result;
  result.status = "complete";
  result.fps = 128.0;
  result.triggers_requested = result.triggers_emitted = frames;
  // What `facedyn capture` records for a take on the platform.
  result.extra["platform"] = {{"target_hz", 11.0}, {"measured_hz_at_start", 10.998}};
  result.extra["hold_start_s"] = 0.125;  // when the prompted expression is held
  for (size_t c = 0; c < cameras.size(); ++c) {
    auto writer = capture::FrameFileWriter::Create(take_dir + "/cam" + std::to_string(c) + "/" +
                                                   capture::kFrameFileName)
                      .value();
    for (int t = 0; t < frames; ++t) {
      if (static_cast<int>(c) == kDropCamera && t == kDropTrigger) continue;
      const Eigen::Matrix3Xd skin = take.FramePositions(t);
      const Eigen::Matrix3Xd markers = MarkerPositions(rig, skin);
      const Eigen::Matrix3Xd normals = MarkerNormals(rig, skin);
      std::vector<std::vector<Eigen::Vector2d>> disks;
      for (int m = 0; m < markers.cols(); ++m) {
        auto outline = ProjectDiskOutline(cameras[c], markers.col(m), normals.col(m), 1.0);
        if (outline.size() >= 3) disks.push_back(outline);
      }
      cv::Mat image = RenderPolygons(cameras[c].width_px, cameras[c].height_px, disks, 170, 40, 2);
      cv::GaussianBlur(image, image, cv::Size(0, 0), 0.8);
      AddImageNoise(2.0, &rng, &image);
      capture::Frame frame;
      frame.camera_index = static_cast<int>(c);
      frame.trigger_index = t;
      frame.timestamp_ns = static_cast<int64_t>(t * 1e9 / 128.0) +
                           (static_cast<int>(c) == kLateCamera && t == kLateTrigger ? 5000000 : 0);
      frame.width_px = image.cols;
      frame.height_px = image.rows;
      frame.pixels.assign(image.data, image.data + image.total());
      EXPECT_TRUE(writer->Append(frame).ok());
    }
    EXPECT_TRUE(writer->Close().ok());
    capture::TakeCameraResult camera_result;
    camera_result.name = cameras[c].name;
    camera_result.dir = "cam" + std::to_string(c);
    result.cameras.push_back(camera_result);
  }
  EXPECT_TRUE(session->EndTake("smile", result).ok());
  return take;
}

TEST(ReconstructCommand, SessionWithDroppedLateAndUncalibratedCameras) {
  TempDir temp;
  const auto t0 = std::chrono::steady_clock::now();
  const Take truth = WriteSession(temp.Join("session"));
  if (getenv("DBG"))
    std::printf("write session %.2f s\n",
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  std::string out;
  const int rc =
      RunCommand(FacedynExecutable() + " --quiet reconstruct --session " + temp.Join("session") +
                     " --take smile --out " + temp.Join("take") + " --marker-diameter-px 7 --json",
                 &out);
  ASSERT_EQ(rc, 0) << out;
  if (getenv("DBG")) std::printf("%s\n", out.c_str());
  EXPECT_THAT(out, HasSubstr("cam7"));  // left out, and said so
  const auto take = LoadTake(temp.Join("take"));
  ASSERT_TRUE(take.ok()) << take.status().ToString();
  ASSERT_EQ(take->frame_count(), truth.frame_count());
  const Json report =
      Json::parse(::facedyn::testing::ReadBytes(temp.Join("take/reconstruction.json")));
  const Json& frames = report["per_frame"];
  EXPECT_THAT(frames[kDropTrigger]["problem"].get<std::string>(), HasSubstr("cam2: no frame"));
  EXPECT_THAT(frames[kLateTrigger]["problem"].get<std::string>(), HasSubstr("cam5: out of sync"));
  EXPECT_EQ(frames[0]["problem"].get<std::string>(), "");
  // The procedural face has a jaw: it is estimated, written (jaw.csv) and reported per frame.
  EXPECT_EQ(report["jaw"], "estimated");
  // The skull pose's deflection model is recorded in the report and the take (the default).
  EXPECT_EQ(report["skull_deflection_shape"], "tissue_model");
  EXPECT_EQ(take->info.metadata["skull_deflection_shape"], "tissue_model");
  // Where the stable markers' reference came from: this take is too short to re-estimate it
  // (SkullPoseEstimator::EstimateTake), and the report and the take say so.
  EXPECT_EQ(report["skull_reference"]["source"], "rig");
  EXPECT_THAT(report["skull_reference"]["reason"].get<std::string>(), HasSubstr("fewer than 32"));
  EXPECT_EQ(take->info.metadata["skull_reference"], report["skull_reference"]);
  // The platform frequency the rig measured goes into the take (for platform-synchronous
  // quasistatic extraction).
  ASSERT_TRUE(take->info.platform_hz.has_value());
  EXPECT_DOUBLE_EQ(*take->info.platform_hz, 10.998);
  // And so does the capture's held part (training and metrics use only frames after it).
  ASSERT_TRUE(take->info.hold_start_s.has_value());
  EXPECT_DOUBLE_EQ(*take->info.hold_start_s, 0.125);
  EXPECT_EQ(take->skull_from_jaw.size(), static_cast<size_t>(truth.frame_count()));
  EXPECT_GT(frames[0]["jaw_markers"].get<int>(), 0);
  EXPECT_TRUE(frames[0].contains("jaw_angle_rad"));
  const FaceRig& rig = testing::ProceduralFace();
  double sq = 0.0;
  int n = 0;
  for (int f = 0; f < truth.frame_count(); ++f) {
    const Eigen::Matrix3Xd error =
        rig.SamplePositions(take->FramePositions(f)) - rig.SamplePositions(truth.FramePositions(f));
    sq += error.colwise().squaredNorm().sum();
    n += static_cast<int>(error.cols());
  }
  const double rms = std::sqrt(sq / n);
  std::printf("from rendered images: 344-sample RMS %.3f mm over %d frames\n", rms,
              truth.frame_count());
  EXPECT_LT(rms, 0.5);
}

TEST(ReconstructCommand, BadSessionTakeAndCalibrationAreNamed) {
  TempDir temp;
  std::string out;
  EXPECT_EQ(RunCommand(FacedynExecutable() + " reconstruct --session " + temp.Join("nothing") +
                           " --take a --out " + temp.Join("x"),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("nothing"));
  auto session = capture::SessionWriter::Open(temp.Join("s"), "virtual",
                                              {{"cam0", "sim", 64, 48, "mono8"}}, Json::object());
  ASSERT_TRUE(session.ok());
  EXPECT_EQ(RunCommand(FacedynExecutable() + " reconstruct --session " + temp.Join("s") +
                           " --take missing --out " + temp.Join("x"),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("no take 'missing'"));
  // An unknown deflection model is refused by name before anything is read.
  EXPECT_NE(RunCommand(FacedynExecutable() + " reconstruct --session " + temp.Join("s") +
                           " --take missing --out " + temp.Join("x") + " --skull-deflection rigid",
                       &out),
            0);
  EXPECT_THAT(out, HasSubstr("--skull-deflection"));
}

}  // namespace
}  // namespace facedyn::reconstruct
