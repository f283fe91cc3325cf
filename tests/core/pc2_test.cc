// PC2 point caches: round trips, the byte layout checked independently of the reader, and
// every corrupt-input path of ReadPc2.
#include "core/pc2.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::ReadBytes;
using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

// Little-endian encoders written for the test, independent of pc2.cc.
void PutInt32(std::string* bytes, int32_t value) {
  const uint32_t u = static_cast<uint32_t>(value);
  for (int i = 0; i < 4; ++i) bytes->push_back(static_cast<char>((u >> (8 * i)) & 0xff));
}
void PutFloat(std::string* bytes, float value) {
  uint32_t u;
  std::memcpy(&u, &value, 4);
  PutInt32(bytes, static_cast<int32_t>(u));
}
int32_t GetInt32(const std::string& bytes, size_t offset) {
  uint32_t u = 0;
  for (int i = 0; i < 4; ++i)
    u |= uint32_t(static_cast<unsigned char>(bytes[offset + i])) << (8 * i);
  return static_cast<int32_t>(u);
}
float GetFloat(const std::string& bytes, size_t offset) {
  const uint32_t u = static_cast<uint32_t>(GetInt32(bytes, offset));
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

// A complete PC2 file as bytes: header fields given explicitly, then `values` as float32.
std::string Pc2Bytes(int32_t version, int32_t vertex_count, float start, float sampling,
                     int32_t frame_count, const std::vector<float>& values) {
  std::string bytes("POINTCACHE2", 11);
  bytes.push_back('\0');
  PutInt32(&bytes, version);
  PutInt32(&bytes, vertex_count);
  PutFloat(&bytes, start);
  PutFloat(&bytes, sampling);
  PutInt32(&bytes, frame_count);
  for (float v : values) PutFloat(&bytes, v);
  return bytes;
}

std::vector<float> Ramp(int n, float scale = 0.5f) {
  std::vector<float> values(n);
  for (int i = 0; i < n; ++i) values[i] = scale * i - 3.25f;
  return values;
}

PointCache MakeCache(int vertex_count, int frame_count, float start = 0.0f, float sampling = 1.0f) {
  PointCache cache;
  cache.vertex_count = vertex_count;
  cache.start_frame = start;
  cache.sampling = sampling;
  cache.positions.resize(3 * vertex_count, frame_count);
  for (int f = 0; f < frame_count; ++f) {
    for (int v = 0; v < vertex_count; ++v) {
      cache.Frame(f).col(v) << 100.0f * f + v, -0.125f * v + f, 1e-3f * (v + 1) * (f + 1);
    }
  }
  return cache;
}

TEST(WritePc2, RoundTripKeepsValuesExactly) {
  TempDir dir;
  const std::string path = dir.Join("cache.pc2");
  const PointCache cache = MakeCache(7, 5, 12.0f, 0.5f);
  ASSERT_TRUE(WritePc2(path, cache).ok());
  const auto read = ReadPc2(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->vertex_count, 7);
  EXPECT_EQ(read->frame_count(), 5);
  EXPECT_EQ(read->start_frame, 12.0f);
  EXPECT_EQ(read->sampling, 0.5f);
  EXPECT_TRUE(read->positions == cache.positions);  // bit-exact floats
  EXPECT_EQ(read->Frame(3).col(4), cache.Frame(3).col(4));
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
}

TEST(WritePc2, RoundTripZeroFrames) {
  TempDir dir;
  const std::string path = dir.Join("empty.pc2");
  const PointCache cache = MakeCache(4, 0);
  ASSERT_TRUE(WritePc2(path, cache).ok());
  EXPECT_EQ(ReadBytes(path).size(), static_cast<size_t>(kPc2HeaderBytes));
  const auto read = ReadPc2(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->vertex_count, 4);
  EXPECT_EQ(read->frame_count(), 0);
  EXPECT_EQ(read->positions.rows(), 12);
}

TEST(WritePc2, OverwritesAnExistingFile) {
  TempDir dir;
  const std::string path = dir.Join("cache.pc2");
  ASSERT_TRUE(WritePc2(path, MakeCache(10, 10)).ok());
  const PointCache small = MakeCache(2, 1);
  ASSERT_TRUE(WritePc2(path, small).ok());
  const auto read = ReadPc2(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->vertex_count, 2);
  EXPECT_TRUE(read->positions == small.positions);
}

TEST(WritePc2, HeaderAndPayloadBytes) {
  TempDir dir;
  const std::string path = dir.Join("cache.pc2");
  const PointCache cache = MakeCache(3, 2, -4.0f, 2.0f);
  ASSERT_TRUE(WritePc2(path, cache).ok());
  const std::string bytes = ReadBytes(path);
  ASSERT_EQ(bytes.size(), 32u + 2 * 3 * 3 * 4);
  const char magic[12] = {'P', 'O', 'I', 'N', 'T', 'C', 'A', 'C', 'H', 'E', '2', '\0'};
  for (int i = 0; i < 12; ++i) EXPECT_EQ(bytes[i], magic[i]) << "magic byte " << i;
  // int32 version = 1, little-endian.
  EXPECT_EQ(bytes[12], '\x01');
  EXPECT_EQ(bytes[13], '\0');
  EXPECT_EQ(bytes[14], '\0');
  EXPECT_EQ(bytes[15], '\0');
  EXPECT_EQ(GetInt32(bytes, 16), 3);      // vertex count
  EXPECT_EQ(GetFloat(bytes, 20), -4.0f);  // start frame
  EXPECT_EQ(GetFloat(bytes, 24), 2.0f);   // sampling
  EXPECT_EQ(GetInt32(bytes, 28), 2);      // frame count
  // Then x y z of every vertex, frame-major.
  size_t offset = 32;
  for (int f = 0; f < 2; ++f) {
    for (int v = 0; v < 3; ++v) {
      for (int k = 0; k < 3; ++k) {
        EXPECT_EQ(GetFloat(bytes, offset), cache.Frame(f)(k, v))
            << "frame " << f << " vertex " << v;
        offset += 4;
      }
    }
  }
  // Known bytes for a known value: frame 0 vertex 0 x is 0.0f, frame 1 vertex 0 x is 100.0f.
  EXPECT_EQ(bytes.substr(32, 4), std::string(4, '\0'));
  EXPECT_EQ(bytes.substr(32 + 36, 4), std::string("\x00\x00\xc8\x42", 4));
}

TEST(ReadPc2, HandCraftedFile) {
  TempDir dir;
  const std::string path = dir.Join("hand.pc2");
  // 2 vertices, 2 frames, start 1, sampling 1.
  WriteBytes(path,
             Pc2Bytes(1, 2, 1.0f, 1.0f, 2, {1, 2, 3, 4, 5, 6, -1, -2, -3, 0.5f, 0.25f, 0.125f}));
  const auto read = ReadPc2(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->vertex_count, 2);
  EXPECT_EQ(read->frame_count(), 2);
  EXPECT_EQ(read->start_frame, 1.0f);
  EXPECT_EQ(read->sampling, 1.0f);
  EXPECT_EQ(read->Frame(0).col(0), Eigen::Vector3f(1, 2, 3));
  EXPECT_EQ(read->Frame(0).col(1), Eigen::Vector3f(4, 5, 6));
  EXPECT_EQ(read->Frame(1).col(0), Eigen::Vector3f(-1, -2, -3));
  EXPECT_EQ(read->Frame(1).col(1), Eigen::Vector3f(0.5f, 0.25f, 0.125f));
}

TEST(ReadPc2, MissingFile) {
  TempDir dir;
  const auto read = ReadPc2(dir.Join("nope.pc2"));
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(read.status().message(), HasSubstr("nope.pc2"));
}

TEST(ReadPc2, TooShortHeader) {
  TempDir dir;
  const std::string path = dir.Join("short.pc2");
  WriteBytes(path, Pc2Bytes(1, 2, 0.0f, 1.0f, 0, {}).substr(0, 20));
  const auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr(path));
  EXPECT_THAT(read.status().message(), HasSubstr("truncated PC2 header"));
  EXPECT_THAT(read.status().message(), HasSubstr("20 bytes"));
}

TEST(ReadPc2, EmptyFile) {
  TempDir dir;
  const std::string path = dir.Join("empty.pc2");
  WriteBytes(path, "");
  const auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr("truncated PC2 header"));
}

TEST(ReadPc2, WrongMagic) {
  TempDir dir;
  const std::string path = dir.Join("magic.pc2");
  std::string bytes = Pc2Bytes(1, 1, 0.0f, 1.0f, 1, {1, 2, 3});
  bytes[0] = 'X';
  WriteBytes(path, bytes);
  const auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr(path));
  EXPECT_THAT(read.status().message(), HasSubstr("not a PC2 file"));

  // The terminating NUL is part of the signature.
  bytes = Pc2Bytes(1, 1, 0.0f, 1.0f, 1, {1, 2, 3});
  bytes[11] = '!';
  WriteBytes(path, bytes);
  EXPECT_THAT(ReadPc2(path).status().message(), HasSubstr("not a PC2 file"));
}

TEST(ReadPc2, UnsupportedVersion) {
  TempDir dir;
  const std::string path = dir.Join("v2.pc2");
  WriteBytes(path, Pc2Bytes(2, 1, 0.0f, 1.0f, 1, {1, 2, 3}));
  const auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr(path));
  EXPECT_THAT(read.status().message(), HasSubstr("unsupported PC2 version 2"));
}

TEST(ReadPc2, NegativeVertexCount) {
  TempDir dir;
  const std::string path = dir.Join("negv.pc2");
  WriteBytes(path, Pc2Bytes(1, -3, 0.0f, 1.0f, 1, {}));
  const auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr(path));
  EXPECT_THAT(read.status().message(), HasSubstr("negative vertex count -3"));
}

TEST(ReadPc2, NegativeFrameCount) {
  TempDir dir;
  const std::string path = dir.Join("negf.pc2");
  WriteBytes(path, Pc2Bytes(1, 1, 0.0f, 1.0f, -1, {1, 2, 3}));
  const auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr(path));
  EXPECT_THAT(read.status().message(), HasSubstr("negative frame count -1"));
}

TEST(ReadPc2, BadSampling) {
  TempDir dir;
  const std::string path = dir.Join("sampling.pc2");
  WriteBytes(path, Pc2Bytes(1, 1, 0.0f, 0.0f, 1, {1, 2, 3}));
  auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr("sampling"));
  WriteBytes(path, Pc2Bytes(1, 1, std::numeric_limits<float>::quiet_NaN(), 1.0f, 1, {1, 2, 3}));
  read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr("start frame"));
}

TEST(ReadPc2, TruncatedPayloadNamesTheIncompleteFrame) {
  TempDir dir;
  const std::string path = dir.Join("trunc.pc2");
  // 2 vertices x 4 frames declared = 24 floats; only 2 full frames + 1 float of frame 2.
  const std::string bytes = Pc2Bytes(1, 2, 0.0f, 1.0f, 4, Ramp(24));
  WriteBytes(path, bytes.substr(0, 32 + (2 * 6 + 1) * 4));
  const auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr(path));
  EXPECT_THAT(read.status().message(), HasSubstr("truncated"));
  EXPECT_THAT(read.status().message(), HasSubstr("4 frames of 2 vertices"));
  EXPECT_THAT(read.status().message(), HasSubstr("frame 2 is incomplete"));
}

TEST(ReadPc2, TruncatedAtAFrameBoundary) {
  TempDir dir;
  const std::string path = dir.Join("trunc.pc2");
  const std::string bytes = Pc2Bytes(1, 2, 0.0f, 1.0f, 4, Ramp(24));
  WriteBytes(path, bytes.substr(0, 32 + 3 * 6 * 4));
  const auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr("frame 3 is incomplete"));
}

TEST(ReadPc2, ExtraTrailingBytes) {
  TempDir dir;
  const std::string path = dir.Join("extra.pc2");
  WriteBytes(path, Pc2Bytes(1, 1, 0.0f, 1.0f, 1, {1, 2, 3}) + "junk");
  const auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr(path));
  EXPECT_THAT(read.status().message(), HasSubstr("size mismatch"));
  EXPECT_THAT(read.status().message(), HasSubstr("48 bytes"));  // 32 + 12 + 4
}

TEST(ReadPc2, NonFiniteValueNamesFrameAndVertex) {
  TempDir dir;
  const std::string path = dir.Join("nan.pc2");
  std::vector<float> values = Ramp(3 * 4 * 3);                            // 4 vertices, 3 frames
  values[(1 * 4 + 2) * 3 + 1] = std::numeric_limits<float>::quiet_NaN();  // frame 1 vertex 2 y
  WriteBytes(path, Pc2Bytes(1, 4, 0.0f, 1.0f, 3, values));
  auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr(path));
  EXPECT_THAT(read.status().message(), HasSubstr("frame 1 vertex 2"));

  values = Ramp(3 * 4 * 3);
  values[(2 * 4 + 3) * 3 + 2] = -std::numeric_limits<float>::infinity();  // frame 2 vertex 3 z
  WriteBytes(path, Pc2Bytes(1, 4, 0.0f, 1.0f, 3, values));
  read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr("frame 2 vertex 3"));
}

// Issue 18, item 7: a 64-byte file whose header sizes make 32 + 12·V·F wrap past 2^64 to 64
// (V = 1824726041, F = 842443544: 12·V·F = 2^64 + 32) was accepted and then asked for 2^64
// bytes (bad_alloc). It is a truncated file and the error says so.
TEST(ReadPc2, HeaderWhoseSizeWrapsIsTruncatedNotAnAllocation) {
  TempDir dir;
  const std::string path = dir.Join("wrap.pc2");
  WriteBytes(path, Pc2Bytes(1, 1824726041, 0.0f, 1.0f, 842443544, std::vector<float>(8, 0.0f)));
  ASSERT_EQ(ReadBytes(path).size(), 64u);
  const auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr("truncated"));
}

// Zero points make frames zero bytes long: a 32-byte header claiming 2^31 - 1 frames passed the
// size check and every reader then looped over two billion empty frames (fuzz/pc2).
TEST(ReadPc2, FramesOfZeroVerticesAreRefused) {
  TempDir dir;
  const std::string path = dir.Join("zero.pc2");
  WriteBytes(path, Pc2Bytes(1, 0, 0.0f, 1.0f, 2147483647, {}));
  const auto read = ReadPc2(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr("2147483647 frames of 0 vertices"));
}

}  // namespace
}  // namespace facedyn
