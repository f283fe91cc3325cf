#include "capture/recorder.h"

#include <gtest/gtest.h>
#include <sys/mount.h>
#include <unistd.h>

#include <filesystem>
#include <thread>

#include "capture/frame_file.h"
#include "tests/support/test_support.h"

namespace facedyn::capture {
namespace {

Frame MakeFrame(int camera, int64_t trigger, int width, int height) {
  Frame frame;
  frame.camera_index = camera;
  frame.trigger_index = trigger;
  frame.timestamp_ns = trigger * 1000;
  frame.exposure_us = 100;
  frame.width_px = width;
  frame.height_px = height;
  frame.pixels.assign(frame.ExpectedBytes(), static_cast<uint8_t>(trigger + 31 * camera));
  return frame;
}

std::vector<std::string> FramePaths(const std::string& dir, int cameras) {
  std::vector<std::string> paths;
  for (int k = 0; k < cameras; ++k) {
    std::filesystem::create_directories(dir + "/cam" + std::to_string(k));
    paths.push_back(dir + "/cam" + std::to_string(k) + "/" + kFrameFileName);
  }
  return paths;
}

TEST(Recorder, BlockPolicyWritesEveryFrameInOrder) {
  testing::TempDir dir;
  RecorderOptions options;
  options.queue_frames = 2;
  BufferPool pool;
  auto recorder = Recorder::Start(options, FramePaths(dir.path(), 3), &pool);
  ASSERT_TRUE(recorder.ok()) << recorder.status().message();
  std::vector<std::thread> producers;
  for (int camera = 0; camera < 3; ++camera) {
    producers.emplace_back([&, camera] {
      for (int k = 0; k < 50; ++k)
        EXPECT_EQ((*recorder)->Push(camera, MakeFrame(camera, k, 64, 48)), PushResult::kQueued);
    });
  }
  for (auto& t : producers) t.join();
  ASSERT_TRUE((*recorder)->Finish().ok());
  const auto stats = (*recorder)->stats();
  for (int camera = 0; camera < 3; ++camera) {
    EXPECT_EQ(stats[camera].frames_written, 50);
    EXPECT_EQ(stats[camera].dropped_queue_full, 0);
    EXPECT_LE(stats[camera].max_queue_depth, 2);
    auto reader =
        FrameFileReader::Open(dir.path() + "/cam" + std::to_string(camera) + "/" + kFrameFileName);
    ASSERT_TRUE(reader.ok());
    ASSERT_EQ((*reader)->frame_count(), 50);
    for (int k = 0; k < 50; ++k) EXPECT_EQ((*reader)->scan().records[k].trigger_index, k);
    Frame frame;
    ASSERT_TRUE((*reader)->Read(7, &frame).ok());
    EXPECT_EQ(frame.pixels[0], static_cast<uint8_t>(7 + 31 * camera));
  }
  EXPECT_EQ((*recorder)->Push(0, MakeFrame(0, 51, 64, 48)), PushResult::kFailed);  // finished
}

TEST(Recorder, DropNewestCountsEveryDrop) {
  testing::TempDir dir;
  RecorderOptions options;
  options.queue_frames = 1;
  options.policy = BackpressurePolicy::kDropNewest;
  options.sync_on_close = false;
  auto recorder = Recorder::Start(options, FramePaths(dir.path(), 1));
  ASSERT_TRUE(recorder.ok());
  int queued = 0, dropped = 0;
  for (int k = 0; k < 200; ++k) {
    const PushResult result = (*recorder)->Push(0, MakeFrame(0, k, 1024, 1024));
    (result == PushResult::kQueued ? queued : dropped) += 1;
  }
  ASSERT_TRUE((*recorder)->Finish().ok());
  const auto stats = (*recorder)->stats();
  EXPECT_EQ(stats[0].frames_written, queued);
  EXPECT_EQ(stats[0].dropped_queue_full, dropped);
  EXPECT_EQ(queued + dropped, 200);
  auto reader = FrameFileReader::Open(dir.path() + "/cam0/" + kFrameFileName);
  ASSERT_TRUE(reader.ok());
  EXPECT_EQ((*reader)->frame_count(), queued);
}

TEST(RecorderOptions, CheckNamesField) {
  RecorderOptions options;
  options.queue_frames = 0;
  EXPECT_NE(options.Check().message().find("queue_frames"), std::string::npos);
  EXPECT_FALSE(ParseBackpressurePolicy("wait").ok());
}

// A filesystem too small for the take: the recorder stops with a clear error and every
// frame it reports written is intact on disk.
TEST(Recorder, DiskFullStopsCleanly) {
  testing::TempDir dir;
  const std::string mount_point = dir.Join("small");
  std::filesystem::create_directories(mount_point);
  if (::mount("tmpfs", mount_point.c_str(), "tmpfs", 0, "size=2m") != 0) {
    if (testing::InCi()) FAIL() << "cannot mount a tmpfs (needs root) and CI=true";
    GTEST_SKIP() << "cannot mount a tmpfs (needs root)";
  }
  struct Unmount {
    std::string path;
    ~Unmount() { ::umount2(path.c_str(), MNT_DETACH); }
  } unmount{mount_point};
  auto recorder = Recorder::Start(RecorderOptions(), FramePaths(mount_point, 3));
  ASSERT_TRUE(recorder.ok());
  Status callback_status;
  (*recorder)->SetErrorCallback([&](const Status& s) { callback_status = s; });
  int64_t pushed = 0;
  for (int k = 0; k < 100 && !(*recorder)->failed(); ++k) {
    for (int camera = 0; camera < 3; ++camera) {
      if ((*recorder)->Push(camera, MakeFrame(camera, k, 320, 256)) == PushResult::kQueued)
        ++pushed;
    }
  }
  const Status status = (*recorder)->Finish();
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find("disk full"), std::string::npos) << status.message();
  EXPECT_EQ(callback_status.message(), status.message());
  const auto stats = (*recorder)->stats();
  int64_t accounted = 0;
  for (int camera = 0; camera < 3; ++camera) {
    auto reader =
        FrameFileReader::Open(mount_point + "/cam" + std::to_string(camera) + "/" + kFrameFileName);
    ASSERT_TRUE(reader.ok());
    EXPECT_TRUE((*reader)->scan().tail_problem.empty()) << (*reader)->scan().tail_problem;
    EXPECT_EQ((*reader)->frame_count(), stats[camera].frames_written);
    accounted += stats[camera].frames_written + stats[camera].discarded_after_error;
  }
  EXPECT_EQ(accounted, pushed);
  EXPECT_GT(stats[0].frames_written + stats[1].frames_written + stats[2].frames_written, 0);
}

}  // namespace
}  // namespace facedyn::capture
