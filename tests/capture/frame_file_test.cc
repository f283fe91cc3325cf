#include "capture/frame_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tests/support/test_support.h"

namespace facedyn::capture {
namespace {

Frame MakeFrame(int64_t trigger, int width = 32, int height = 16) {
  Frame frame;
  frame.camera_index = 2;
  frame.trigger_index = trigger;
  frame.timestamp_ns = trigger * 7812500;
  frame.exposure_us = 1500;
  frame.width_px = width;
  frame.height_px = height;
  frame.pixels.resize(frame.ExpectedBytes());
  for (size_t i = 0; i < frame.pixels.size(); ++i)
    frame.pixels[i] = static_cast<uint8_t>(i * 7 + trigger);
  return frame;
}

TEST(FrameFile, RoundTrip) {
  testing::TempDir dir;
  const std::string path = dir.Join(kFrameFileName);
  {
    auto writer = FrameFileWriter::Create(path);
    ASSERT_TRUE(writer.ok());
    for (int k = 0; k < 5; ++k) ASSERT_TRUE((*writer)->Append(MakeFrame(k)).ok());
    EXPECT_EQ((*writer)->frames_written(), 5);
    ASSERT_TRUE((*writer)->Close().ok());
  }
  auto reader = FrameFileReader::Open(path);
  ASSERT_TRUE(reader.ok());
  ASSERT_EQ((*reader)->frame_count(), 5);
  EXPECT_TRUE((*reader)->scan().tail_problem.empty());
  for (int k = 0; k < 5; ++k) {
    Frame frame;
    ASSERT_TRUE((*reader)->Read(k, &frame).ok());
    const Frame expected = MakeFrame(k);
    EXPECT_EQ(frame.trigger_index, k);
    EXPECT_EQ(frame.timestamp_ns, expected.timestamp_ns);
    EXPECT_EQ(frame.exposure_us, 1500);
    EXPECT_EQ(frame.camera_index, 2);
    EXPECT_EQ(frame.pixels, expected.pixels);
  }
  EXPECT_EQ((*reader)->FindTrigger(3), 3);
  EXPECT_EQ((*reader)->FindTrigger(9), -1);
}

TEST(FrameFile, RefusesToOverwrite) {
  testing::TempDir dir;
  testing::WriteBytes(dir.Join("f.fdr"), "x");
  EXPECT_FALSE(FrameFileWriter::Create(dir.Join("f.fdr")).ok());
}

TEST(FrameFile, TruncatedTailKeepsCompleteRecords) {
  testing::TempDir dir;
  const std::string path = dir.Join(kFrameFileName);
  {
    auto writer = FrameFileWriter::Create(path);
    ASSERT_TRUE(writer.ok());
    for (int k = 0; k < 3; ++k) ASSERT_TRUE((*writer)->Append(MakeFrame(k)).ok());
  }
  const std::string bytes = testing::ReadBytes(path);
  const size_t record = bytes.size() / 3;
  for (size_t cut : {record * 2 + 10, record * 2 + kFrameHeaderBytes + 5}) {
    testing::WriteBytes(dir.Join("cut.fdr"), bytes.substr(0, cut));
    auto reader = FrameFileReader::Open(dir.Join("cut.fdr"));
    ASSERT_TRUE(reader.ok());
    EXPECT_EQ((*reader)->frame_count(), 2);
    EXPECT_FALSE((*reader)->scan().tail_problem.empty());
    EXPECT_EQ((*reader)->scan().valid_bytes, static_cast<int64_t>(record * 2));
  }
}

TEST(FrameFile, CorruptHeaderStopsTheScanThere) {
  testing::TempDir dir;
  const std::string path = dir.Join(kFrameFileName);
  {
    auto writer = FrameFileWriter::Create(path);
    ASSERT_TRUE(writer.ok());
    for (int k = 0; k < 3; ++k) ASSERT_TRUE((*writer)->Append(MakeFrame(k)).ok());
  }
  std::string bytes = testing::ReadBytes(path);
  const size_t record = bytes.size() / 3;
  bytes[record + 9] ^= 0x40;  // flips a bit of the second record's trigger index
  testing::WriteBytes(path, bytes);
  auto reader = FrameFileReader::Open(path);
  ASSERT_TRUE(reader.ok());
  EXPECT_EQ((*reader)->frame_count(), 1);
  EXPECT_NE((*reader)->scan().tail_problem.find("checksum"), std::string::npos)
      << (*reader)->scan().tail_problem;
}

TEST(FrameFile, MissingFileIsNotFound) {
  auto reader = FrameFileReader::Open("/nonexistent/frames.fdr");
  ASSERT_FALSE(reader.ok());
  EXPECT_EQ(reader.status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace facedyn::capture
