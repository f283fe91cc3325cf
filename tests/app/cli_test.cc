// End-to-end tests of the `facedyn` executable: exit codes, messages and files on disk.

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::FacedynExecutable;
using ::facedyn::testing::ReadBytes;
using ::facedyn::testing::RunCommand;
using ::facedyn::testing::TempDir;
using ::testing::HasSubstr;

std::string Facedyn(const std::string& args) { return FacedynExecutable() + " " + args; }

// Runs `facedyn demo --quick` once for the whole suite (it simulates a face, which takes a
// few seconds) and returns the folder of its small rigid take; tests copy what they modify.
const TempDir& DemoDir() {
  static const TempDir* dir = [] {
    auto* d = new TempDir();
    std::string out;
    const int rc = RunCommand(Facedyn("--quiet demo --quick --out " + d->Join("demo")), &out);
    EXPECT_EQ(rc, 0) << out;
    return d;
  }();
  return *dir;
}

std::string MakeDemoTake(const TempDir& dir) {
  const std::string copy = dir.Join("platform_8hz");
  std::filesystem::copy(DemoDir().Join("demo/takes/platform_8hz"), copy);
  return copy;
}

template <typename T>
T Read(const std::string& bytes, size_t offset) {
  T value;
  std::memcpy(&value, bytes.data() + offset, sizeof(T));
  return value;
}

TEST(Cli, VersionAndHelp) {
  std::string out;
  EXPECT_EQ(RunCommand(Facedyn("--version"), &out), 0);
  EXPECT_THAT(out, HasSubstr("facedyn 0."));
  EXPECT_EQ(RunCommand(Facedyn("--help"), &out), 0);
  for (const char* command : {"take", "export", "demo"}) EXPECT_THAT(out, HasSubstr(command));
  EXPECT_EQ(RunCommand(Facedyn("export --help"), &out), 0);
  EXPECT_THAT(out, HasSubstr("--format"));
}

TEST(Cli, BadCommandLineExitsTwo) {
  std::string out;
  EXPECT_EQ(RunCommand(Facedyn("no-such-command"), &out), 2);
  EXPECT_EQ(RunCommand(Facedyn("export --take x --format xyz --out y"), &out), 2);
  EXPECT_THAT(out, HasSubstr("xyz"));
  EXPECT_EQ(RunCommand(Facedyn("take info"), &out), 2);
  EXPECT_THAT(out, HasSubstr("TAKE"));
}

TEST(Cli, DemoWritesTakeAndExports) {
  TempDir dir;
  const std::string take = MakeDemoTake(dir);
  for (const char* file : {"take.json", "topology.obj", "positions.pc2", "skull.csv"}) {
    EXPECT_TRUE(std::filesystem::exists(take + "/" + file)) << file;
  }
  EXPECT_TRUE(std::filesystem::exists(DemoDir().Join("demo/export/obj/frame_000063.obj")));
  EXPECT_TRUE(std::filesystem::exists(DemoDir().Join("demo/export/pc2/positions.pc2")));
  // The simulated platform take carries the exact quasistatic channel.
  const std::string sim = DemoDir().Join("demo/takes/sim_neutral_11hz");
  for (const char* file : {"take.json", "positions.pc2", "quasistatic.pc2", "dynamic_offset.pc2", "jaw.csv"}) {
    EXPECT_TRUE(std::filesystem::exists(sim + "/" + file)) << file;
  }
  EXPECT_TRUE(std::filesystem::exists(DemoDir().Join("demo/face/face_rig.json")));
}

// The demo's metrics.json has every stage's section, its figures are consistent with what the
// stages measure, and the report embeds its renders and plots (no network needed).
TEST(Cli, DemoMetricsAndReport) {
  const std::string metrics_path = DemoDir().Join("demo/metrics.json");
  ASSERT_TRUE(std::filesystem::exists(metrics_path));
  const auto metrics = nlohmann::json::parse(ReadBytes(metrics_path));
  for (const char* section :
       {"rig", "simulation", "capture", "reconstruct", "dynamics", "renders", "stages_s", "total_s"}) {
    EXPECT_TRUE(metrics.contains(section)) << section;
  }
  ASSERT_FALSE(metrics["rig"]["steps"].empty());
  for (const auto& step : metrics["rig"]["steps"]) {
    EXPECT_NEAR(step["measured_mean_hz"].get<double>(), step["target_hz"].get<double>(), 0.05);
  }
  const auto& removal = metrics["dynamics"]["removal"];
  ASSERT_FALSE(removal.empty());
  for (const auto& entry : removal) {
    const auto& methods = entry["methods"];
    for (const char* method : {"F_exact_targets", "no_removal", "lowpass", "moving_average"}) {
      ASSERT_TRUE(methods.contains(method)) << method;
    }
    // The held-out take's removal must at least remove most of the dynamics.
    EXPECT_LT(methods["F_exact_targets"]["jiggle_mean_mm"].get<double>(),
              0.5 * methods["no_removal"]["jiggle_mean_mm"].get<double>());
  }
  ASSERT_TRUE(metrics["dynamics"].contains("synthesis"));
  ASSERT_TRUE(metrics["dynamics"].contains("removal_by_training_frequencies"));
  EXPECT_TRUE(metrics["capture"]["session_complete"].get<bool>());
  EXPECT_GT(metrics["reconstruct"]["dynamic_offset_correlation"].get<double>(), 0.9);
  EXPECT_EQ(metrics["renders"]["images"].size(), 6u);
  const std::string report = ReadBytes(DemoDir().Join("demo/report.html"));
  EXPECT_THAT(report, HasSubstr("<svg"));
  EXPECT_THAT(report, HasSubstr("data:image/png;base64,"));
  // Self-contained: nothing is loaded from elsewhere (the SVG namespace URI is not a fetch).
  for (const char* remote : {"src=\"http", "href=\"http", "url(http", "@import"}) {
    EXPECT_EQ(report.find(remote), std::string::npos) << "the report loads " << remote;
  }
}

TEST(Cli, TakeInfoJsonReportsCountsAndSkullRange) {
  TempDir dir;
  const std::string take = MakeDemoTake(dir);
  std::string out;
  ASSERT_EQ(RunCommand(Facedyn("take info --json " + take + " 2>/dev/null"), &out), 0) << out;
  const auto json = nlohmann::json::parse(out);
  EXPECT_EQ(json["frames"], 64);
  EXPECT_EQ(json["fps"], 128.0);
  EXPECT_EQ(json["vertices"], 33 * 33);
  EXPECT_NEAR(json["duration_s"].get<double>(), 0.5, 1e-12);
  // The demo head oscillates +-2 mm vertically with +-0.5 deg of pitch; 64 frames at 8 Hz and
  // 128 fps cover 4 full periods, so the peaks are sampled exactly.
  EXPECT_NEAR(json["skull_motion"]["translation_range_mm"][1].get<double>(), 4.0, 1e-6);
  EXPECT_NEAR(json["skull_motion"]["max_rotation_deg"].get<double>(), 0.5, 1e-4);
}

TEST(Cli, ExportPc2HeaderReadIndependently) {
  TempDir dir;
  const std::string take = MakeDemoTake(dir);
  std::string out;
  ASSERT_EQ(RunCommand(Facedyn("export --take " + take + " --format pc2 --out " + dir.Join("pc2")), &out), 0)
      << out;
  const std::string bytes = ReadBytes(dir.Join("pc2/positions.pc2"));
  ASSERT_GE(bytes.size(), 32u);
  // ARCHITECTURE.md: "POINTCACHE2\0", int32 version=1, int32 vertex count, float32 start
  // frame, float32 sampling, int32 frame count, then float32 xyz.
  EXPECT_EQ(std::memcmp(bytes.data(), "POINTCACHE2\0", 12), 0);
  EXPECT_EQ(Read<int32_t>(bytes, 12), 1);
  const int32_t vertices = Read<int32_t>(bytes, 16);
  EXPECT_EQ(vertices, 33 * 33);
  EXPECT_EQ(Read<float>(bytes, 20), 0.0f);
  EXPECT_EQ(Read<float>(bytes, 24), 1.0f);
  const int32_t frames = Read<int32_t>(bytes, 28);
  EXPECT_EQ(frames, 64);
  EXPECT_EQ(bytes.size(), 32u + size_t(vertices) * size_t(frames) * 12u);
  // Frame 0 equals the exported topology's rest pose moved by skull pose 0 (identity at
  // phase 0), i.e. the first "v" line of topology.obj.
  const std::string obj = ReadBytes(dir.Join("pc2/topology.obj"));
  const size_t v = obj.find("\nv ");
  ASSERT_NE(v, std::string::npos);
  float x, y, z;
  ASSERT_EQ(std::sscanf(obj.c_str() + v + 3, "%f %f %f", &x, &y, &z), 3);
  EXPECT_NEAR(Read<float>(bytes, 32), x, 1e-4);
  EXPECT_NEAR(Read<float>(bytes, 36), y, 1e-4);
  EXPECT_NEAR(Read<float>(bytes, 40), z, 1e-4);
}

TEST(Cli, ExportPerFrameObjAndPly) {
  TempDir dir;
  const std::string take = MakeDemoTake(dir);
  std::string out;
  ASSERT_EQ(RunCommand(Facedyn("--quiet export --take " + take + " --format ply --out " + dir.Join("ply")), &out), 0)
      << out;
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir.Join("ply"))) {
    EXPECT_EQ(entry.path().extension(), ".ply");
    ++count;
  }
  EXPECT_EQ(count, 64);
}

TEST(Cli, TakeInfoErrorsNameTheProblem) {
  TempDir dir;
  std::string out;
  EXPECT_EQ(RunCommand(Facedyn("take info " + dir.Join("missing")), &out), 1);
  EXPECT_THAT(out, HasSubstr("missing: no such take folder"));

  const std::string take = MakeDemoTake(dir);
  // Truncate the point cache: the error names the file and the incomplete frame.
  std::filesystem::resize_file(take + "/positions.pc2", 32 + 12 * 33 * 33 * 10 + 7);
  EXPECT_EQ(RunCommand(Facedyn("take info " + take), &out), 1);
  EXPECT_THAT(out, HasSubstr("positions.pc2: truncated"));
  EXPECT_THAT(out, HasSubstr("frame 10 is incomplete"));
}

TEST(Cli, ExportErrorLeavesNoCrash) {
  TempDir dir;
  const std::string take = MakeDemoTake(dir);
  // The output path is an existing file, not a folder.
  testing::WriteBytes(dir.Join("file"), "x");
  std::string out;
  EXPECT_EQ(RunCommand(Facedyn("export --take " + take + " --format pc2 --out " + dir.Join("file")), &out), 1);
  EXPECT_THAT(out, HasSubstr("file"));
}

TEST(Cli, SimFaceAndPerformWriteATakeWithQuasistaticChannel) {
  TempDir dir;
  std::string out;
  ASSERT_EQ(RunCommand(Facedyn("--quiet sim face --vertices 4000 --out " + dir.Join("face")), &out), 0) << out;
  ASSERT_EQ(RunCommand(Facedyn("--quiet sim perform --face " + dir.Join("face") +
                               " --expression smile --motion platform --hz 9 --seconds 0.25 --fps 96 --out " +
                               dir.Join("take")),
                       &out),
            0)
      << out;
  ASSERT_EQ(RunCommand(Facedyn("take info --json " + dir.Join("take") + " 2>/dev/null"), &out), 0) << out;
  const auto json = nlohmann::json::parse(out);
  EXPECT_EQ(json["frames"], 24);
  EXPECT_EQ(json["fps"], 96.0);
  EXPECT_EQ(json["expression"], "smile");
  EXPECT_EQ(json["platform_hz"], 9.0);
  EXPECT_EQ(json["channels"], nlohmann::json({"dynamic_offset", "quasistatic"}));
  EXPECT_EQ(json["has_jaw"], true);
}

TEST(Cli, SimPerformBadArgumentsAreClearErrors) {
  TempDir dir;
  std::string out;
  EXPECT_EQ(RunCommand(Facedyn("sim perform --motion wobble --out " + dir.Join("t")), &out), 1);
  EXPECT_THAT(out, HasSubstr("wobble"));
  EXPECT_EQ(RunCommand(Facedyn("sim perform --expression grimace --seconds 0.1 --out " + dir.Join("t")), &out), 1);
  EXPECT_THAT(out, HasSubstr("grimace"));
  EXPECT_EQ(RunCommand(Facedyn("sim perform --face " + dir.Join("nope") + " --out " + dir.Join("t")), &out), 1);
  EXPECT_THAT(out, HasSubstr("nope"));
  EXPECT_EQ(RunCommand(Facedyn("sim perform --seconds -1 --out " + dir.Join("t")), &out), 1);
  EXPECT_THAT(out, HasSubstr("seconds"));
  EXPECT_EQ(RunCommand(Facedyn("sim face --ict " + dir.Join("no-ict") + " --out " + dir.Join("f")), &out), 1);
  EXPECT_THAT(out, HasSubstr("no-ict"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("t/take.json")));
}

}  // namespace
}  // namespace facedyn
