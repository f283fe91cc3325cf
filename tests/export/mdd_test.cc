// MDD point caches: the big-endian byte layout checked by hand and by an independent reader
// (Python's struct module), round trips, every corrupt-input path of ReadMdd, and the take
// export.
#include "export/mdd.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "core/mesh_primitives.h"
#include "export/take_export.h"
#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::ReadBytes;
using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

// Big-endian encoders written for the test, independent of mdd.cc.
void PutBig32(std::string* bytes, uint32_t u) {
  for (int i = 3; i >= 0; --i) bytes->push_back(static_cast<char>((u >> (8 * i)) & 0xff));
}
void PutBigFloat(std::string* bytes, float value) {
  uint32_t u;
  std::memcpy(&u, &value, 4);
  PutBig32(bytes, u);
}

PointCache SmallCache() {
  PointCache cache;
  cache.vertex_count = 2;
  cache.positions.resize(6, 3);
  for (int f = 0; f < 3; ++f)
    for (int i = 0; i < 6; ++i) cache.positions(i, f) = 0.5f * i - 1.25f * f + 1e-3f * (i * f);
  return cache;
}

TEST(WriteMdd, BytesAreBigEndianCountsTimesThenFrames) {
  TempDir dir;
  const PointCache cache = SmallCache();
  const std::vector<double> times = {0.0, 0.0078125, 0.015625};
  ASSERT_TRUE(WriteMdd(dir.Join("c.mdd"), cache, times).ok());
  std::string expected;
  PutBig32(&expected, 3);
  PutBig32(&expected, 2);
  for (const double t : times) PutBigFloat(&expected, static_cast<float>(t));
  for (int f = 0; f < 3; ++f)
    for (int i = 0; i < 6; ++i) PutBigFloat(&expected, cache.positions(i, f));
  EXPECT_EQ(ReadBytes(dir.Join("c.mdd")), expected);
  EXPECT_EQ(expected.size(), 8u + 4 * 3 + 12 * 2 * 3);
}

// An independent reader: Python's struct module, big-endian (">").
TEST(WriteMdd, PythonStructReadsWhatWeWrite) {
  if (std::system("python3 -c '' >/dev/null 2>&1") != 0) {
    if (testing::InCi()) FAIL() << "python3 is missing";
    GTEST_SKIP() << "python3 not installed";
  }
  TempDir dir;
  const PointCache cache = SmallCache();
  ASSERT_TRUE(WriteMdd(dir.Join("c.mdd"), cache, {0.0, 0.5, 1.0}).ok());
  const std::string script =
      "import struct,sys\n"
      "b=open(sys.argv[1],'rb').read()\n"
      "f,v=struct.unpack('>ii',b[:8])\n"
      "t=struct.unpack('>%df'%f,b[8:8+4*f])\n"
      "p=struct.unpack('>%df'%(3*v*f),b[8+4*f:])\n"
      "print(f,v,' '.join('%.9g'%x for x in t),'%.9g'%p[0],'%.9g'%p[-1],len(b))\n";
  WriteBytes(dir.Join("read_mdd.py"), script);
  std::string out;
  ASSERT_EQ(testing::RunCommand("python3 " + dir.Join("read_mdd.py") + " " + dir.Join("c.mdd"), &out),
            0)
      << out;
  char expected[200];
  std::snprintf(expected, sizeof(expected), "3 2 0 0.5 1 %.9g %.9g %d\n",
                cache.positions(0, 0), cache.positions(5, 2), 8 + 12 + 72);
  EXPECT_EQ(out, expected);
}

TEST(ReadMdd, RoundTripKeepsValuesAndTimesExactly) {
  TempDir dir;
  const PointCache cache = SmallCache();
  ASSERT_TRUE(WriteMdd(dir.Join("c.mdd"), cache, {0.0, 0.25, 0.25}).ok());
  const auto read = ReadMdd(dir.Join("c.mdd"));
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->points.vertex_count, 2);
  EXPECT_TRUE(read->points.positions == cache.positions);
  EXPECT_EQ(read->time_s, (std::vector<float>{0.0f, 0.25f, 0.25f}));
}

TEST(ReadMdd, CorruptFilesAreErrorsNamingTheProblem) {
  TempDir dir;
  struct Case {
    std::string bytes;
    std::string message;
  };
  std::string huge;  // 2^31 - 1 frames of 2^31 - 1 points in 8 bytes: no allocation
  PutBig32(&huge, 0x7fffffff);
  PutBig32(&huge, 0x7fffffff);
  std::string negative;
  PutBig32(&negative, 0xffffffff);
  PutBig32(&negative, 1);
  std::string empty_frames;
  PutBig32(&empty_frames, 1000);
  PutBig32(&empty_frames, 0);
  std::string extra;
  PutBig32(&extra, 0);
  PutBig32(&extra, 1);
  extra += "xx";
  std::string nan_point;
  PutBig32(&nan_point, 1);
  PutBig32(&nan_point, 1);
  PutBigFloat(&nan_point, 0.0f);
  PutBigFloat(&nan_point, 1.0f);
  PutBigFloat(&nan_point, std::numeric_limits<float>::quiet_NaN());
  PutBigFloat(&nan_point, 1.0f);
  std::string backwards;
  PutBig32(&backwards, 2);
  PutBig32(&backwards, 1);
  PutBigFloat(&backwards, 1.0f);
  PutBigFloat(&backwards, 0.5f);
  for (int i = 0; i < 6; ++i) PutBigFloat(&backwards, 0.0f);
  const Case cases[] = {
      {"abc", "truncated MDD header"},
      {huge, "truncated: header declares 2147483647 frames"},
      {negative, "negative count"},
      {empty_frames, "1000 frames of 0 points"},
      {extra, "size mismatch"},
      {nan_point, "frame 0 point 0 has a non-finite coordinate"},
      {backwards, "frame 1 has time 0.5 s"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.message);
    WriteBytes(dir.Join("bad.mdd"), c.bytes);
    const auto read = ReadMdd(dir.Join("bad.mdd"));
    ASSERT_FALSE(read.ok());
    EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
    EXPECT_THAT(read.status().message(), HasSubstr(dir.Join("bad.mdd")));
    EXPECT_THAT(read.status().message(), HasSubstr(c.message));
  }
}

TEST(WriteMdd, RefusesTimesThatDoNotFitTheCache) {
  TempDir dir;
  const PointCache cache = SmallCache();
  EXPECT_FALSE(WriteMdd(dir.Join("c.mdd"), cache, {0.0, 1.0}).ok());
  EXPECT_FALSE(WriteMdd(dir.Join("c.mdd"), cache, {0.0, 1.0, 0.5}).ok());
  EXPECT_FALSE(WriteMdd(dir.Join("c.mdd"), cache, {0.0, 1.0, std::nan("")}).ok());
}

TEST(ExportTake, MddWritesTopologyAndEveryCacheWithTimesFromTheFirstFrame) {
  TempDir dir;
  Take take;
  take.info.fps = 4.0;
  take.topology = MakeEllipsoidPatch(80, 100, 90, 0.5, 0.5, 2, 2);
  const int vertices = take.topology.vertex_count();
  take.positions.vertex_count = vertices;
  take.positions.positions = Eigen::MatrixXf::Random(3 * vertices, 3);
  PointCache offset = take.positions;
  offset.positions *= 0.01f;
  take.channels["dynamic_offset"] = offset;
  take.time_s = {10.0, 10.25, 10.5};
  take.world_from_skull.assign(3, Rigid3());
  const auto summary = ExportTake(take, ExportFormat::kMdd, dir.Join("out"));
  ASSERT_TRUE(summary.ok()) << summary.status().message();
  EXPECT_EQ(summary->files_written, 3);
  const auto positions = ReadMdd(dir.Join("out/positions.mdd"));
  ASSERT_TRUE(positions.ok()) << positions.status().message();
  EXPECT_TRUE(positions->points.positions == take.positions.positions);
  EXPECT_EQ(positions->time_s, (std::vector<float>{0.0f, 0.25f, 0.5f}));
  const auto channel = ReadMdd(dir.Join("out/dynamic_offset.mdd"));
  ASSERT_TRUE(channel.ok()) << channel.status().message();
  EXPECT_TRUE(channel->points.positions == offset.positions);
  EXPECT_TRUE(ReadMesh(dir.Join("out/topology.obj")).ok());
  EXPECT_EQ(*ParseExportFormat("mdd"), ExportFormat::kMdd);
}

}  // namespace
}  // namespace facedyn
