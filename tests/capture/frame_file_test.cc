#include "capture/frame_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstring>

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

// Overwrites one header field of the record at `record_offset` and re-signs the header, the way
// a hostile or buggy writer would: the checksum alone then cannot catch it. FNV-1a-64 over bytes
// 0..55, as documented in capture/frame_file.h.
template <typename T>
void PatchHeader(std::string* bytes, size_t record_offset, int field_offset, T value) {
  std::memcpy(&(*bytes)[record_offset + field_offset], &value, sizeof(T));
  uint64_t hash = 1469598103934665603ull;
  for (int i = 0; i < 56; ++i) {
    hash ^= static_cast<uint8_t>((*bytes)[record_offset + i]);
    hash *= 1099511628211ull;
  }
  std::memcpy(&(*bytes)[record_offset + 56], &hash, sizeof(hash));
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

// trigger_index 2^40 once passed the scan, and reconstruct sized its per-trigger arrays by the
// largest index seen: 2^40 entries, bad_alloc.
TEST(FrameFile, ImpossibleTriggerIndexIsNamedAndLeftOut) {
  testing::TempDir dir;
  const std::string path = dir.Join(kFrameFileName);
  {
    auto writer = FrameFileWriter::Create(path);
    ASSERT_TRUE(writer.ok());
    for (int k = 0; k < 4; ++k) ASSERT_TRUE((*writer)->Append(MakeFrame(k)).ok());
  }
  std::string bytes = testing::ReadBytes(path);
  const size_t record = bytes.size() / 4;
  PatchHeader<int64_t>(&bytes, record, 8, int64_t{1} << 40);
  PatchHeader<int64_t>(&bytes, 2 * record, 8, -3);
  testing::WriteBytes(path, bytes);
  auto reader = FrameFileReader::Open(path);
  ASSERT_TRUE(reader.ok());
  const FrameFileScan& scan = (*reader)->scan();
  // The records around the bad ones are kept: nothing already recorded is lost.
  ASSERT_EQ((*reader)->frame_count(), 2);
  EXPECT_EQ(scan.records[0].trigger_index, 0);
  EXPECT_EQ(scan.records[1].trigger_index, 3);
  EXPECT_TRUE(scan.tail_problem.empty()) << scan.tail_problem;
  ASSERT_EQ(scan.record_problems.size(), 2u);
  EXPECT_NE(scan.record_problems[0].find(path), std::string::npos) << scan.record_problems[0];
  EXPECT_NE(scan.record_problems[0].find("record 1 "), std::string::npos)
      << scan.record_problems[0];
  EXPECT_NE(scan.record_problems[0].find("trigger_index 1099511627776"), std::string::npos)
      << scan.record_problems[0];
  EXPECT_NE(scan.record_problems[1].find("record 2 "), std::string::npos)
      << scan.record_problems[1];
  EXPECT_NE(scan.record_problems[1].find("trigger_index -3"), std::string::npos)
      << scan.record_problems[1];
  // The last legal index is still read.
  PatchHeader<int64_t>(&bytes, record, 8, kMaxTriggersPerTake - 1);
  testing::WriteBytes(path, bytes);
  reader = FrameFileReader::Open(path);
  ASSERT_TRUE(reader.ok());
  EXPECT_EQ((*reader)->frame_count(), 3);
  EXPECT_EQ((*reader)->FindTrigger(kMaxTriggersPerTake - 1), 1);
}

// A header whose width x height x bytes-per-pixel wraps 64 bits must not match a small payload:
// 0xFFFFFFFF x 0xFFFFFFFF x 1 is 1 modulo 2^64, and such a record once scanned as a frame of
// -1 x -1 pixels. Sizes beyond the caps are as corrupt as a bad checksum: the scan stops there.
TEST(FrameFile, WrappingOrHugeFrameSizeStopsTheScan) {
  struct Case {
    uint32_t width, height, format;
    uint64_t payload;
    const char* expected;
  };
  const Case cases[] = {
      {0xFFFFFFFFu, 0xFFFFFFFFu, 1, 1, "frame size 4294967295x4294967295 px is outside"},
      {0x80000000u, 2, 1, 0, "frame size 2147483648x2 px is outside"},
      {0, 16, 1, 0, "frame size 0x16 px is outside"},
      {65536, 65536, 3, uint64_t{65536} * 65536 * 3, "more than the 1073741824-byte limit"},
      {32, 16, 3, 512, "payload size 512 disagrees with 32x16 bgr8 (1536 bytes)"},
  };
  for (const Case& c : cases) {
    testing::TempDir dir;
    const std::string path = dir.Join(kFrameFileName);
    {
      auto writer = FrameFileWriter::Create(path);
      ASSERT_TRUE(writer.ok());
      for (int k = 0; k < 2; ++k) ASSERT_TRUE((*writer)->Append(MakeFrame(k)).ok());
    }
    std::string bytes = testing::ReadBytes(path);
    const size_t record = bytes.size() / 2;
    // The second header claims the hostile size; keep the file long enough that a wrapped size
    // would "fit" (1 byte of payload is there).
    PatchHeader<uint32_t>(&bytes, record, 28, c.width);
    PatchHeader<uint32_t>(&bytes, record, 32, c.height);
    PatchHeader<uint32_t>(&bytes, record, 36, c.format);
    PatchHeader<uint64_t>(&bytes, record, 40, c.payload);
    testing::WriteBytes(path, bytes);
    auto reader = FrameFileReader::Open(path);
    ASSERT_TRUE(reader.ok());
    const FrameFileScan& scan = (*reader)->scan();
    EXPECT_EQ((*reader)->frame_count(), 1) << c.expected;
    EXPECT_NE(scan.tail_problem.find(c.expected), std::string::npos) << scan.tail_problem;
    EXPECT_NE(scan.tail_problem.find("(record 1)"), std::string::npos) << scan.tail_problem;
    EXPECT_EQ(scan.valid_bytes, static_cast<int64_t>(record));
  }
}

TEST(FrameFile, MissingFileIsNotFound) {
  auto reader = FrameFileReader::Open("/nonexistent/frames.fdr");
  ASSERT_FALSE(reader.ok());
  EXPECT_EQ(reader.status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace facedyn::capture
