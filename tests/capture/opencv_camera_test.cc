// OpenCvCamera replaying a video file written losslessly (FFV1) by cv::VideoWriter.
#include "capture/opencv_camera.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "capture/frame_sync.h"
#include "capture/trigger.h"
#include "tests/support/test_support.h"

namespace facedyn::capture {
namespace {

cv::Mat Pattern(int k) {
  cv::Mat image(240, 320, CV_8UC1);
  for (int y = 0; y < 240; ++y) {
    for (int x = 0; x < 320; ++x)
      image.at<uint8_t>(y, x) = static_cast<uint8_t>((x + 3 * y + 7 * k) & 0xff);
  }
  return image;
}

std::string WriteVideo(const std::string& path, int frames) {
  cv::VideoWriter writer(path, cv::CAP_FFMPEG, cv::VideoWriter::fourcc('F', 'F', 'V', '1'), 30.0,
                         cv::Size(320, 240), true);
  if (!writer.isOpened()) return "";
  for (int k = 0; k < frames; ++k) {
    cv::Mat bgr;
    cv::cvtColor(Pattern(k), bgr, cv::COLOR_GRAY2BGR);
    writer.write(bgr);
  }
  return path;
}

TEST(OpenCvCamera, ReplaysAFileFrameExactAndCountsTheShortfall) {
  testing::TempDir dir;
  const std::string video = WriteVideo(dir.Join("take.mkv"), 20);
  ASSERT_FALSE(video.empty()) << "OpenCV cannot write FFV1 (ffmpeg backend missing)";
  OpenCvCamera camera(0, "cam0", video);
  ASSERT_TRUE(camera.Configure({320, 240, PixelFormat::kMono8, 1000, 30.0}).ok());
  EXPECT_TRUE(camera.is_file());
  ASSERT_TRUE(camera.Arm().ok());
  constexpr int kTriggers = 24;  // four more than the file has
  for (int k = 0; k < kTriggers; ++k)
    ASSERT_TRUE(camera.OnTrigger({k, VirtualTrigger::PulseTimeNs(k, 30.0)}).ok());
  ASSERT_TRUE(camera.Disarm().ok());
  FrameSyncChecker checker(1'000'000);
  Frame frame;
  int frames = 0;
  for (;;) {
    bool got = false;
    Status status = camera.NextFrame(0.5, &frame, &got);
    if (status.code() == StatusCode::kAborted) break;
    ASSERT_TRUE(status.ok()) << status.message();
    ASSERT_TRUE(got);  // disarmed: either a frame or the end
    ASSERT_EQ(frame.trigger_index, frames);
    const cv::Mat expected = Pattern(frames);
    EXPECT_EQ(0, std::memcmp(frame.pixels.data(), expected.data, frame.pixels.size()))
        << "frame " << frames;
    (void)checker.Observe(frame.trigger_index, frame.timestamp_ns,
                          VirtualTrigger::PulseTimeNs(frame.trigger_index, 30.0), kTriggers);
    ++frames;
  }
  EXPECT_EQ(frames, 20);
  EXPECT_EQ(camera.exhausted_triggers(), 4);
  checker.Finish(kTriggers);
  EXPECT_EQ(checker.counts().missing, 4);
  EXPECT_EQ(checker.counts().timestamp_mismatch, 0) << checker.counts().ToJson().dump();
}

// A GStreamer pipeline (gstreamer1.0-plugins-base: videotestsrc, appsink) as a live source:
// one grab per trigger, timestamps = trigger time + grab latency, the shortfall counted.
TEST(OpenCvCamera, GStreamerPipelineIsALiveSource) {
  const std::string pipeline =
      "videotestsrc num-buffers=12 pattern=ball ! video/x-raw,format=GRAY8,width=320,height=240,"
      "framerate=30/1 ! appsink";
  OpenCvCamera camera(0, "cam0", pipeline);
  const Status configured = camera.Configure({320, 240, PixelFormat::kMono8, 1000, 30.0});
  if (!configured.ok() && configured.message().find("cannot open") != std::string::npos) {
    if (testing::InCi())
      FAIL() << configured.message() << " (install gstreamer1.0-plugins-base) and CI=true";
    GTEST_SKIP() << configured.message() << " (install gstreamer1.0-plugins-base)";
  }
  ASSERT_TRUE(configured.ok()) << configured.message();
  EXPECT_FALSE(camera.is_file());
  ASSERT_TRUE(camera.Arm().ok());
  for (int k = 0; k < 15; ++k)
    ASSERT_TRUE(camera.OnTrigger({k, VirtualTrigger::PulseTimeNs(k, 30.0)}).ok());
  ASSERT_TRUE(camera.Disarm().ok());
  Frame frame;
  std::vector<Frame> frames;
  for (;;) {
    bool got = false;
    Status status = camera.NextFrame(0.5, &frame, &got);
    if (status.code() == StatusCode::kAborted) break;
    ASSERT_TRUE(status.ok()) << status.message();
    ASSERT_TRUE(got);  // disarmed: either a frame or the end
    frames.push_back(frame);
  }
  ASSERT_EQ(frames.size(), 12u);
  EXPECT_EQ(camera.exhausted_triggers(), 3);
  for (size_t k = 0; k < frames.size(); ++k) {
    EXPECT_EQ(frames[k].trigger_index, static_cast<int64_t>(k));
    EXPECT_GE(frames[k].timestamp_ns,
              VirtualTrigger::PulseTimeNs(k, 30.0));  // never before its trigger
  }
  EXPECT_NE(frames[0].pixels, frames[6].pixels);  // the ball moves
}

TEST(OpenCvCamera, WrongSizeAndMissingFileAreErrors) {
  testing::TempDir dir;
  const std::string video = WriteVideo(dir.Join("take.mkv"), 3);
  ASSERT_FALSE(video.empty());
  OpenCvCamera camera(0, "cam0", video);
  const Status status = camera.Configure({640, 480, PixelFormat::kMono8, 1000, 30.0});
  EXPECT_NE(status.message().find("320x240"), std::string::npos) << status.message();
  OpenCvCamera missing(1, "cam1", dir.Join("absent.mkv"));
  EXPECT_EQ(missing.Configure({320, 240, PixelFormat::kMono8, 1000, 30.0}).code(),
            StatusCode::kNotFound);
}

}  // namespace
}  // namespace facedyn::capture
