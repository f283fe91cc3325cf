// Take folders: a full round trip, and one test per way a folder on disk can be wrong, each
// asserting that the message names the file and, where there is one, the frame or line.
#include "core/take.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::ReadBytes;
using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::AllOf;
using ::testing::HasSubstr;

constexpr int kFrames = 20;
constexpr int kColumns = 6;
constexpr int kRows = 5;  // 6 x 5 = 30 vertices

// A gently curved 6x5 grid of triangles with UVs, about 50 x 40 mm.
Mesh MakeTopology() {
  Mesh mesh;
  mesh.positions_mm.resize(3, kColumns * kRows);
  mesh.uvs.resize(2, kColumns * kRows);
  for (int j = 0; j < kRows; ++j) {
    for (int i = 0; i < kColumns; ++i) {
      const int v = j * kColumns + i;
      const double x = 10.0 * i - 25.0, y = 10.0 * j - 20.0;
      mesh.positions_mm.col(v) << x, y, 80.0 - 0.01 * (x * x + y * y);
      mesh.uvs.col(v) << i / double(kColumns - 1), j / double(kRows - 1);
    }
  }
  for (int j = 0; j + 1 < kRows; ++j) {
    for (int i = 0; i + 1 < kColumns; ++i) {
      const int a = j * kColumns + i, b = a + 1, c = a + kColumns + 1, d = a + kColumns;
      mesh.AddFace({a, b, c}, {a, b, c});
      mesh.AddFace({a, c, d}, {a, c, d});
    }
  }
  return mesh;
}

PointCache MakeCache(int vertex_count, int frame_count) {
  PointCache cache;
  cache.vertex_count = vertex_count;
  cache.positions = Eigen::MatrixXf::Zero(3 * vertex_count, frame_count);
  return cache;
}

// 20 frames at 30 fps of the grid moving rigidly with a skull that nods about X and sways
// along Z, a jaw opening about the hinge, and two channels.
Take MakeTake() {
  Take take;
  take.info.fps = 30.0;
  take.info.subject = "grid";
  take.info.expression = "neutral";
  take.info.motion = "platform";
  take.info.source = "take_test";
  take.info.platform_hz = 8.5;
  take.info.hold_start_s = 0.5;
  take.info.metadata = Json{{"seed", 7},
                            {"amplitude_mm", 1.25},
                            {"note", "synthetic"},
                            {"nested", {{"list", {1, 2, 3}}, {"flag", true}}}};
  take.topology = MakeTopology();
  const int v_count = take.topology.vertex_count();
  take.positions = MakeCache(v_count, kFrames);
  take.channels["quasistatic"] = MakeCache(v_count, kFrames);
  take.channels["dynamic_offset"] = MakeCache(v_count, kFrames);
  for (int f = 0; f < kFrames; ++f) {
    const double phase = 2.0 * M_PI * 8.5 * f / 30.0;
    const Rigid3 world_from_skull =
        Rigid3::FromAxisAngle(Eigen::Vector3d(1, 0.1, 0), 0.05 * std::sin(phase),
                              Eigen::Vector3d(0.5 * f, 3.0, 2.0 * std::sin(phase)));
    take.world_from_skull.push_back(world_from_skull);
    take.skull_from_jaw.push_back(
        Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), 0.01 * f, Eigen::Vector3d(0, -40, 60)));
    const Eigen::Matrix3Xd world = world_from_skull.Apply(take.topology.positions_mm);
    take.positions.Frame(f) = world.cast<float>();
    take.channels["quasistatic"].Frame(f) = (world.array() + 0.125).matrix().cast<float>();
    take.channels["dynamic_offset"].Frame(f).setConstant(0.001f * f);
  }
  take.SetUniformTimes();
  return take;
}

// Saves MakeTake() into `dir` and checks it loads, as the starting point for corruptions.
void SaveGoodTake(const std::string& dir) {
  const Status saved = SaveTake(MakeTake(), dir);
  ASSERT_TRUE(saved.ok()) << saved.message();
  const auto loaded = LoadTake(dir);
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
}

// Replaces 1-based line `line` of a text file.
void ReplaceLine(const std::string& path, int line, const std::string& text) {
  std::istringstream in(ReadBytes(path));
  std::string out, current;
  int n = 0;
  bool replaced = false;
  while (std::getline(in, current)) {
    ++n;
    if (n == line) {
      current = text;
      replaced = true;
    }
    out += current + "\n";
  }
  ASSERT_TRUE(replaced) << path << " has no line " << line;
  WriteBytes(path, out);
}

// Keeps the first `lines` lines of a text file.
void KeepLines(const std::string& path, int lines) {
  std::istringstream in(ReadBytes(path));
  std::string out, current;
  for (int n = 0; n < lines && std::getline(in, current); ++n) out += current + "\n";
  WriteBytes(path, out);
}

// Rewrites take.json with one top-level field replaced by raw JSON text (or removed if "").
void SetTakeJsonField(const std::string& dir, const std::string& key,
                      const std::string& raw_value) {
  Json json = Json::parse(ReadBytes(dir + "/take.json"));
  ASSERT_TRUE(json.contains(key)) << key;
  if (raw_value.empty()) {
    json.erase(key);
  } else {
    json[key] = Json::parse(raw_value);
  }
  WriteBytes(dir + "/take.json", json.dump(2) + "\n");
}

Status LoadError(const std::string& dir) {
  const auto loaded = LoadTake(dir);
  EXPECT_FALSE(loaded.ok()) << "LoadTake(" << dir << ") should have failed";
  return loaded.ok() ? Status::Ok() : loaded.status();
}

TEST(SaveTake, RoundTripKeepsEveryField) {
  TempDir dir;
  const Take take = MakeTake();
  ASSERT_TRUE(take.Validate().ok()) << take.Validate().message();
  const std::string folder = dir.Join("take");
  const Status saved = SaveTake(take, folder);
  ASSERT_TRUE(saved.ok()) << saved.message();
  for (const char* file : {"take.json", "topology.obj", "positions.pc2", "skull.csv", "jaw.csv",
                           "quasistatic.pc2", "dynamic_offset.pc2"}) {
    EXPECT_TRUE(std::filesystem::exists(folder + "/" + file)) << file;
  }

  const auto loaded = LoadTake(folder);
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  const Take& t = *loaded;
  EXPECT_EQ(t.info.fps, 30.0);
  EXPECT_EQ(t.info.subject, "grid");
  EXPECT_EQ(t.info.expression, "neutral");
  EXPECT_EQ(t.info.motion, "platform");
  EXPECT_EQ(t.info.source, "take_test");
  ASSERT_TRUE(t.info.platform_hz.has_value());
  EXPECT_EQ(*t.info.platform_hz, 8.5);
  ASSERT_TRUE(t.info.hold_start_s.has_value());
  EXPECT_EQ(*t.info.hold_start_s, 0.5);
  EXPECT_EQ(t.info.metadata, take.info.metadata) << t.info.metadata.dump();

  EXPECT_EQ(t.frame_count(), kFrames);
  EXPECT_EQ(t.vertex_count(), 30);
  EXPECT_NEAR(t.duration_s(), kFrames / 30.0, 1e-12);
  EXPECT_TRUE(SameTopology(t.topology, take.topology));
  EXPECT_EIGEN_NEAR(t.topology.positions_mm, take.topology.positions_mm, 1e-4);  // float32 OBJ read
  EXPECT_EQ(t.positions.vertex_count, 30);
  EXPECT_TRUE(t.positions.positions == take.positions.positions);  // exact floats
  EXPECT_EIGEN_NEAR(t.FramePositions(7), take.FramePositions(7), 0.0);

  ASSERT_EQ(t.channels.size(), 2u);
  ASSERT_TRUE(t.channels.count("quasistatic"));
  ASSERT_TRUE(t.channels.count("dynamic_offset"));
  EXPECT_TRUE(t.channels.at("quasistatic").positions == take.channels.at("quasistatic").positions);
  EXPECT_TRUE(t.channels.at("dynamic_offset").positions ==
              take.channels.at("dynamic_offset").positions);

  ASSERT_EQ(t.time_s.size(), take.time_s.size());
  ASSERT_EQ(t.world_from_skull.size(), take.world_from_skull.size());
  ASSERT_EQ(t.skull_from_jaw.size(), take.skull_from_jaw.size());
  for (int f = 0; f < kFrames; ++f) {
    SCOPED_TRACE("frame " + std::to_string(f));
    EXPECT_NEAR(t.time_s[f], take.time_s[f], 1e-9);
    EXPECT_EIGEN_NEAR(t.world_from_skull[f].rotation().coeffs(),
                      take.world_from_skull[f].rotation().coeffs(), 1e-8);
    EXPECT_EIGEN_NEAR(t.world_from_skull[f].translation(), take.world_from_skull[f].translation(),
                      1e-6);
    EXPECT_EIGEN_NEAR(t.skull_from_jaw[f].rotation().coeffs(),
                      take.skull_from_jaw[f].rotation().coeffs(), 1e-8);
    EXPECT_EIGEN_NEAR(t.skull_from_jaw[f].translation(), take.skull_from_jaw[f].translation(),
                      1e-6);
  }
}

TEST(SaveTake, TakeJsonContents) {
  TempDir dir;
  ASSERT_TRUE(SaveTake(MakeTake(), dir.path()).ok());
  const Json json = Json::parse(ReadBytes(dir.Join("take.json")));
  EXPECT_EQ(json.at("format_version"), kTakeFormatVersion);
  EXPECT_EQ(json.at("fps"), 30.0);
  EXPECT_EQ(json.at("frame_count"), kFrames);
  EXPECT_EQ(json.at("vertex_count"), 30);
  EXPECT_EQ(json.at("units"), "mm");
  EXPECT_EQ(json.at("platform_hz"), 8.5);
  // Channels are listed in name order (std::map).
  EXPECT_EQ(json.at("channels"), Json::array({"dynamic_offset", "quasistatic"}));
  EXPECT_EQ(json.at("metadata").at("seed"), 7);
}

TEST(SaveTake, RoundTripWithoutJawChannelsOrPlatform) {
  TempDir dir;
  Take take = MakeTake();
  take.skull_from_jaw.clear();
  take.channels.clear();
  take.info.platform_hz.reset();
  take.info.hold_start_s.reset();
  take.info.metadata = Json::object();
  // First save a take with a jaw, then overwrite it: the stale jaw.csv must go.
  ASSERT_TRUE(SaveTake(MakeTake(), dir.path()).ok());
  ASSERT_TRUE(std::filesystem::exists(dir.Join("jaw.csv")));
  ASSERT_TRUE(SaveTake(take, dir.path()).ok());
  EXPECT_FALSE(std::filesystem::exists(dir.Join("jaw.csv")));
  const auto loaded = LoadTake(dir.path());
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  EXPECT_TRUE(loaded->skull_from_jaw.empty());
  EXPECT_TRUE(loaded->channels.empty());
  EXPECT_FALSE(loaded->info.platform_hz.has_value());
  EXPECT_FALSE(loaded->info.hold_start_s.has_value());
  EXPECT_TRUE(loaded->info.metadata.is_object());
  EXPECT_TRUE(loaded->info.metadata.empty());
}

TEST(SaveTake, ZeroFrames) {
  TempDir dir;
  Take take = MakeTake();
  take.positions = MakeCache(30, 0);
  take.channels.clear();
  take.world_from_skull.clear();
  take.skull_from_jaw.clear();
  take.time_s.clear();
  ASSERT_TRUE(SaveTake(take, dir.path()).ok());
  const auto loaded = LoadTake(dir.path());
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  EXPECT_EQ(loaded->frame_count(), 0);
  EXPECT_EQ(loaded->vertex_count(), 30);
}

TEST(SaveTake, RefusesAnInconsistentTakeAndWritesNothing) {
  TempDir dir;
  Take take = MakeTake();
  take.world_from_skull.pop_back();
  const std::string folder = dir.Join("never");
  const Status status = SaveTake(take, folder);
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(status.message(), HasSubstr("19 skull poses for 20 frames"));
  EXPECT_FALSE(std::filesystem::exists(folder));
}

TEST(SaveTake, RefusalLeavesAnExistingTakeUntouched) {
  TempDir dir;
  SaveGoodTake(dir.path());
  const std::string json_before = ReadBytes(dir.Join("take.json"));
  const std::string positions_before = ReadBytes(dir.Join("positions.pc2"));
  Take take = MakeTake();
  take.channels["Bad Name"] = take.positions;
  take.positions.positions.setZero();
  ASSERT_FALSE(SaveTake(take, dir.path()).ok());
  EXPECT_EQ(ReadBytes(dir.Join("take.json")), json_before);
  EXPECT_EQ(ReadBytes(dir.Join("positions.pc2")), positions_before);
  EXPECT_TRUE(LoadTake(dir.path()).ok());
}

TEST(SaveTake, FailedWriteRemovesTheStaleTakeJson) {
  // take.json marks a complete take. If a save fails part way (here positions.pc2 cannot be
  // replaced because a directory is in the way), the folder must not keep the old take.json
  // beside a mix of new and old files.
  TempDir dir;
  SaveGoodTake(dir.path());
  std::filesystem::remove(dir.Join("positions.pc2"));
  std::filesystem::create_directories(dir.Join("positions.pc2/blocker"));
  const Status status = SaveTake(MakeTake(), dir.path());
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("positions.pc2"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("take.json")));
  EXPECT_THAT(LoadError(dir.path()).message(), HasSubstr("take.json"));
}

TEST(TakeValidate, ReportsEachInconsistency) {
  Take take = MakeTake();
  ASSERT_TRUE(take.Validate().ok());

  take.info.fps = 0.0;
  EXPECT_THAT(take.Validate().message(), HasSubstr("fps must be positive"));
  take.info.fps = std::nan("");
  EXPECT_THAT(take.Validate().message(), HasSubstr("fps must be positive"));

  take = MakeTake();
  take.time_s.pop_back();
  EXPECT_THAT(take.Validate().message(), HasSubstr("19 frame times for 20 frames"));

  take = MakeTake();
  take.skull_from_jaw.resize(3);
  EXPECT_THAT(take.Validate().message(), HasSubstr("3 jaw poses for 20 frames"));

  take = MakeTake();
  take.positions = MakeCache(29, kFrames);
  EXPECT_THAT(take.Validate().message(), HasSubstr("positions have 29 vertices, topology has 30"));

  take = MakeTake();
  take.channels["quasistatic"] = MakeCache(30, 5);
  EXPECT_THAT(take.Validate().message(),
              HasSubstr("channel 'quasistatic' is 5 frames x 30 vertices, the take is 20 x 30"));

  take = MakeTake();
  take.channels["positions"] = take.positions;
  EXPECT_THAT(take.Validate().message(), HasSubstr("bad channel name 'positions'"));

  take = MakeTake();
  take.topology.positions_mm(2, 4) = std::nan("");
  EXPECT_THAT(take.Validate().message(), HasSubstr("vertex 4 has a non-finite coordinate"));
}

TEST(IsValidChannelName, AcceptsFileStemsOnly) {
  EXPECT_TRUE(IsValidChannelName("quasistatic"));
  EXPECT_TRUE(IsValidChannelName("dynamic_offset"));
  EXPECT_TRUE(IsValidChannelName("f2_synth"));
  EXPECT_FALSE(IsValidChannelName(""));
  EXPECT_FALSE(IsValidChannelName("positions"));
  EXPECT_FALSE(IsValidChannelName("Quasistatic"));
  EXPECT_FALSE(IsValidChannelName("dynamic-offset"));
  EXPECT_FALSE(IsValidChannelName("../escape"));
  EXPECT_FALSE(IsValidChannelName("a.pc2"));
  EXPECT_FALSE(IsValidChannelName(std::string(65, 'a')));
  EXPECT_TRUE(IsValidChannelName(std::string(64, 'a')));
}

TEST(SetUniformTimes, IsFrameOverFps) {
  Take take = MakeTake();
  take.info.fps = 128.0;
  take.SetUniformTimes();
  ASSERT_EQ(take.time_s.size(), static_cast<size_t>(kFrames));
  for (int f = 0; f < kFrames; ++f) EXPECT_DOUBLE_EQ(take.time_s[f], f / 128.0);
}

TEST(LoadTake, MissingFolder) {
  TempDir dir;
  const Status status = LoadError(dir.Join("absent"));
  EXPECT_EQ(status.code(), StatusCode::kNotFound);
  EXPECT_THAT(status.message(), HasSubstr("absent"));
}

TEST(LoadTake, MissingTakeJson) {
  TempDir dir;
  SaveGoodTake(dir.path());
  std::filesystem::remove(dir.Join("take.json"));
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kNotFound);
  EXPECT_THAT(status.message(), HasSubstr(dir.Join("take.json")));
}

TEST(LoadTake, TakeJsonSyntaxErrorNamesTheLine) {
  TempDir dir;
  SaveGoodTake(dir.path());
  WriteBytes(dir.Join("take.json"),
             "{\n"
             "  \"format_version\": 1,\n"
             "  \"fps\": 30\n"  // missing comma: the parser notices on the next line
             "  \"frame_count\": 20,\n"
             "  \"vertex_count\": 30\n"
             "}\n");
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(),
              AllOf(HasSubstr(dir.Join("take.json") + ":4:"), HasSubstr("syntax error")));
}

TEST(LoadTake, FpsMissing) {
  TempDir dir;
  SaveGoodTake(dir.path());
  SetTakeJsonField(dir.path(), "fps", "");
  const Status status = LoadError(dir.path());
  EXPECT_THAT(status.message(), AllOf(HasSubstr("take.json"), HasSubstr("field 'fps'"),
                                      HasSubstr("required field is missing")));
}

TEST(LoadTake, FpsNegative) {
  TempDir dir;
  SaveGoodTake(dir.path());
  SetTakeJsonField(dir.path(), "fps", "-30");
  const Status status = LoadError(dir.path());
  EXPECT_THAT(status.message(), AllOf(HasSubstr("take.json"), HasSubstr("field 'fps'"),
                                      HasSubstr("-30 is outside the allowed range")));
}

TEST(LoadTake, FpsIsAString) {
  TempDir dir;
  SaveGoodTake(dir.path());
  SetTakeJsonField(dir.path(), "fps", "\"30\"");
  const Status status = LoadError(dir.path());
  EXPECT_THAT(status.message(), AllOf(HasSubstr("take.json"), HasSubstr("field 'fps'"),
                                      HasSubstr("expected a number, got '30'")));
}

TEST(LoadTake, UnitsNotMillimetres) {
  TempDir dir;
  SaveGoodTake(dir.path());
  SetTakeJsonField(dir.path(), "units", "\"cm\"");
  const Status status = LoadError(dir.path());
  EXPECT_THAT(status.message(), AllOf(HasSubstr("take.json"), HasSubstr("field 'units'"),
                                      HasSubstr("'cm' is not supported")));
}

TEST(LoadTake, UnsupportedFormatVersion) {
  TempDir dir;
  SaveGoodTake(dir.path());
  SetTakeJsonField(dir.path(), "format_version", "2");
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr("field 'format_version'"), HasSubstr("version 2 is not supported")));
}

TEST(LoadTake, VertexCountDisagreesWithTopology) {
  TempDir dir;
  SaveGoodTake(dir.path());
  SetTakeJsonField(dir.path(), "vertex_count", "31");
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(status.message(), AllOf(HasSubstr(dir.Join("topology.obj")),
                                      HasSubstr("has 30 vertices but take.json says 31")));
}

TEST(LoadTake, FrameCountDisagreesWithPositions) {
  TempDir dir;
  SaveGoodTake(dir.path());
  SetTakeJsonField(dir.path(), "frame_count", "21");
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(status.message(), AllOf(HasSubstr(dir.Join("positions.pc2")),
                                      HasSubstr("has 20 frames but take.json says 21")));
}

TEST(LoadTake, NegativeFrameCount) {
  TempDir dir;
  SaveGoodTake(dir.path());
  SetTakeJsonField(dir.path(), "frame_count", "-1");
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr("field 'frame_count'"), HasSubstr("must not be negative")));
}

TEST(LoadTake, ChannelListedButMissing) {
  TempDir dir;
  SaveGoodTake(dir.path());
  std::filesystem::remove(dir.Join("quasistatic.pc2"));
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kNotFound);
  EXPECT_THAT(status.message(), HasSubstr(dir.Join("quasistatic.pc2")));
}

TEST(LoadTake, ChannelWithWrongVertexCount) {
  TempDir dir;
  SaveGoodTake(dir.path());
  ASSERT_TRUE(WritePc2(dir.Join("dynamic_offset.pc2"), MakeCache(29, kFrames)).ok());
  const Status status = LoadError(dir.path());
  EXPECT_THAT(status.message(), AllOf(HasSubstr(dir.Join("dynamic_offset.pc2")),
                                      HasSubstr("has 29 vertices but take.json says 30")));
}

TEST(LoadTake, ChannelWithWrongFrameCount) {
  TempDir dir;
  SaveGoodTake(dir.path());
  ASSERT_TRUE(WritePc2(dir.Join("quasistatic.pc2"), MakeCache(30, kFrames - 1)).ok());
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr(dir.Join("quasistatic.pc2")),
                    HasSubstr("has 19 frames but take.json says 20")));
}

TEST(LoadTake, BadChannelName) {
  TempDir dir;
  SaveGoodTake(dir.path());
  SetTakeJsonField(dir.path(), "channels", R"(["quasistatic", "../positions"])");
  const Status status = LoadError(dir.path());
  EXPECT_THAT(status.message(),
              AllOf(HasSubstr("take.json"), HasSubstr("field 'channels'"),
                    HasSubstr("entry 1 '../positions' is not a valid channel name")));
}

TEST(LoadTake, TruncatedPositions) {
  TempDir dir;
  SaveGoodTake(dir.path());
  const std::string bytes = ReadBytes(dir.Join("positions.pc2"));
  // Keep the header and 12.5 frames of 30 vertices.
  WriteBytes(dir.Join("positions.pc2"), bytes.substr(0, 32 + 12 * 360 + 180));
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(),
              AllOf(HasSubstr(dir.Join("positions.pc2")), HasSubstr("frame 12 is incomplete")));
}

TEST(LoadTake, NonFinitePosition) {
  TempDir dir;
  SaveGoodTake(dir.path());
  Take take = MakeTake();
  take.positions.Frame(3)(1, 17) = std::nanf("");
  ASSERT_TRUE(WritePc2(dir.Join("positions.pc2"), take.positions).ok());
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr(dir.Join("positions.pc2")), HasSubstr("frame 3 vertex 17")));
}

TEST(LoadTake, SkullCsvWrongHeader) {
  TempDir dir;
  SaveGoodTake(dir.path());
  ReplaceLine(dir.Join("skull.csv"), 1, "frame,time,qw,qx,qy,qz,tx,ty,tz");
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(),
              AllOf(HasSubstr(dir.Join("skull.csv") + ":1:"), HasSubstr("header is")));
}

TEST(LoadTake, SkullCsvWrongFieldCount) {
  TempDir dir;
  SaveGoodTake(dir.path());
  ReplaceLine(dir.Join("skull.csv"), 6, "4,0.133333333,1,0,0,0,1,2");  // frame 4, 8 fields
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr(dir.Join("skull.csv") + ":6:"),
                    HasSubstr("expected 9 comma-separated fields, got 8")));
}

TEST(LoadTake, SkullCsvNonNumericFieldNamesColumnAndLine) {
  TempDir dir;
  SaveGoodTake(dir.path());
  ReplaceLine(dir.Join("skull.csv"), 4, "2,0.066666667,1,abc,0,0,1,2,3");
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr(dir.Join("skull.csv") + ":4:"),
                    HasSubstr("column qx is 'abc', not a finite number")));
  ReplaceLine(dir.Join("skull.csv"), 4, "2,0.066666667,1,0,0,0,1,nan,3");
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr(dir.Join("skull.csv") + ":4:"), HasSubstr("column ty is 'nan'")));
}

TEST(LoadTake, SkullCsvNonUnitQuaternionNamesTheFrame) {
  TempDir dir;
  SaveGoodTake(dir.path());
  ReplaceLine(dir.Join("skull.csv"), 5, "3,0.1,0.9,0,0,0,1,2,3");
  const Status status = LoadError(dir.path());
  EXPECT_THAT(status.message(),
              AllOf(HasSubstr(dir.Join("skull.csv") + ":5:"), HasSubstr("frame 3"),
                    HasSubstr("quaternion has norm 0.900000")));
}

TEST(LoadTake, SkullCsvFramesOutOfOrder) {
  TempDir dir;
  SaveGoodTake(dir.path());
  ReplaceLine(dir.Join("skull.csv"), 5, "5,0.1,1,0,0,0,1,2,3");
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr(dir.Join("skull.csv") + ":5:"),
                    HasSubstr("frame number 5 where frame 3 was expected")));
}

TEST(LoadTake, SkullCsvTimeNotIncreasing) {
  TempDir dir;
  SaveGoodTake(dir.path());
  ReplaceLine(dir.Join("skull.csv"), 7, "5,0.1,1,0,0,0,1,2,3");  // frame 4 is at 0.1333
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr(dir.Join("skull.csv") + ":7:"),
                    HasSubstr("frame 5: time 0.1 s does not increase")));
}

TEST(LoadTake, SkullCsvFewerRowsThanFrames) {
  TempDir dir;
  SaveGoodTake(dir.path());
  KeepLines(dir.Join("skull.csv"), 1 + 15);
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(status.message(), AllOf(HasSubstr(dir.Join("skull.csv")),
                                      HasSubstr("has 15 frames but take.json says 20")));
}

TEST(LoadTake, SkullCsvMissing) {
  TempDir dir;
  SaveGoodTake(dir.path());
  std::filesystem::remove(dir.Join("skull.csv"));
  EXPECT_THAT(LoadError(dir.path()).message(), HasSubstr(dir.Join("skull.csv")));
}

TEST(LoadTake, JawCsvWithFewerRows) {
  TempDir dir;
  SaveGoodTake(dir.path());
  KeepLines(dir.Join("jaw.csv"), 1 + 18);
  EXPECT_THAT(
      LoadError(dir.path()).message(),
      AllOf(HasSubstr(dir.Join("jaw.csv")), HasSubstr("has 18 frames but take.json says 20")));
}

TEST(LoadTake, JawCsvNonUnitQuaternion) {
  TempDir dir;
  SaveGoodTake(dir.path());
  ReplaceLine(dir.Join("jaw.csv"), 10, "8,0.266666667,2,0,0,0,0,-40,60");
  EXPECT_THAT(LoadError(dir.path()).message(), AllOf(HasSubstr(dir.Join("jaw.csv") + ":10:"),
                                                     HasSubstr("frame 8: quaternion has norm 2")));
}

TEST(WriteTransformCsv, RoundTripAndFormat) {
  TempDir dir;
  const std::string path = dir.Join("poses.csv");
  const std::vector<double> times = {0.0, 0.5, 1.25};
  const std::vector<Rigid3> poses = {
      Rigid3::Identity(),
      Rigid3::FromAxisAngle(Eigen::Vector3d(0, 1, 0), 0.3, Eigen::Vector3d(1, 2, 3)),
      Rigid3::FromTranslation(Eigen::Vector3d(-1.5, 0, 1e3))};
  ASSERT_TRUE(WriteTransformCsv(path, times, poses).ok());
  const std::string text = ReadBytes(path);
  EXPECT_EQ(text.substr(0, text.find('\n')), "frame,time_s,qw,qx,qy,qz,tx,ty,tz");
  EXPECT_THAT(text, HasSubstr("\n0,0.000000000,1,0,0,0,0,0,0\n"));
  EXPECT_THAT(text, HasSubstr("\n2,1.250000000,1,0,0,0,-1.5,0,1000\n"));

  std::vector<double> read_times;
  std::vector<Rigid3> read_poses;
  ASSERT_TRUE(ReadTransformCsv(path, &read_times, &read_poses).ok());
  EXPECT_EQ(read_times, times);
  ASSERT_EQ(read_poses.size(), 3u);
  for (size_t i = 0; i < 3; ++i) EXPECT_TRUE(read_poses[i].IsApprox(poses[i], 1e-8)) << i;
}

TEST(ReadTransformCsv, ReplacesPreviousContents) {
  TempDir dir;
  const std::string path = dir.Join("poses.csv");
  WriteBytes(path, "frame,time_s,qw,qx,qy,qz,tx,ty,tz\n0,0.5,1,0,0,0,0,0,7\n");
  std::vector<double> times = {9.0, 10.0};
  std::vector<Rigid3> poses = {Rigid3::Identity(), Rigid3::Identity()};
  ASSERT_TRUE(ReadTransformCsv(path, &times, &poses).ok());
  EXPECT_EQ(times, std::vector<double>{0.5});
  ASSERT_EQ(poses.size(), 1u);
  EXPECT_EIGEN_NEAR(poses[0].translation(), Eigen::Vector3d(0, 0, 7), 0.0);
}

TEST(ReadTransformCsv, EqualTimesAreNotIncreasing) {
  TempDir dir;
  const std::string path = dir.Join("poses.csv");
  WriteBytes(path, "frame,time_s,qw,qx,qy,qz,tx,ty,tz\n0,0,1,0,0,0,0,0,0\n1,0,1,0,0,0,0,0,0\n");
  std::vector<double> times;
  std::vector<Rigid3> poses;
  const Status status = ReadTransformCsv(path, &times, &poses);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(),
              AllOf(HasSubstr(path + ":3:"), HasSubstr("frame 1: time 0 s does not increase")));
}

}  // namespace
}  // namespace facedyn
