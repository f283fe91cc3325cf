// PROCESS.yaml: defaults, every field read, and bad values named by file, line and field.

#include "process/process_config.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace facedyn::process {
namespace {

using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

StatusOr<ProcessConfig> Load(const TempDir& dir, const std::string& text) {
  WriteBytes(dir.Join("p.yaml"), text);
  return LoadProcessConfig(dir.Join("p.yaml"));
}

TEST(ProcessConfig, EmptyFileGivesTheDefaults) {
  TempDir dir;
  const auto config = Load(dir, "");
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  EXPECT_EQ(config->face, "procedural");
  EXPECT_EQ(config->takes, std::vector<std::string>{"*"});
  EXPECT_TRUE(config->removal.enabled);
  EXPECT_EQ(config->removal.targets, "moving-average");
  EXPECT_EQ(config->removal.epochs, 250);
  EXPECT_EQ(config->exports.formats, std::vector<std::string>{"pc2"});
  EXPECT_EQ(config->threads, 1);
}

TEST(ProcessConfig, ReadsEveryFieldAndResolvesPathsAgainstTheFile) {
  TempDir dir;
  const auto config = Load(dir, R"(face: faces/actor
takes: [smile_*, speech]
reconstruct: {marker_diameter_px: 6, bright_markers: true, calibration: cal.yaml}
removal: {train_takes: smile_*, targets: platform-synchronous, epochs: 12}
synthesis: {enabled: true, epochs: 3}
solve: {model: solvers/s1, epochs: 4}
export: {formats: [glb, mdd]}
seed: 7
threads: 2
slurm: {partition: gpu, account: vfx, cpus_per_task: 4, time: "01:00:00"}
)");
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  EXPECT_EQ(config->face, dir.Join("faces/actor"));
  EXPECT_EQ(config->takes, (std::vector<std::string>{"smile_*", "speech"}));
  EXPECT_DOUBLE_EQ(config->reconstruct.marker_diameter_px, 6.0);
  EXPECT_TRUE(config->reconstruct.bright_markers);
  EXPECT_EQ(config->reconstruct.calibration, dir.Join("cal.yaml"));
  EXPECT_EQ(config->removal.train_takes, std::vector<std::string>{"smile_*"});
  EXPECT_EQ(config->removal.targets, "platform-synchronous");
  EXPECT_EQ(config->removal.epochs, 12);
  EXPECT_EQ(config->synthesis.epochs, 3);
  EXPECT_EQ(config->solve.model, dir.Join("solvers/s1"));
  EXPECT_EQ(config->solve.epochs, 4);
  EXPECT_EQ(config->exports.formats, (std::vector<std::string>{"glb", "mdd"}));
  EXPECT_EQ(config->seed, 7u);
  EXPECT_EQ(config->threads, 2);
  EXPECT_EQ(config->slurm.partition, "gpu");
  EXPECT_EQ(config->slurm.account, "vfx");
  EXPECT_EQ(config->slurm.cpus_per_task, 4);
  EXPECT_EQ(config->slurm.time_limit, "01:00:00");
}

TEST(ProcessConfig, BadValuesAreNamed) {
  TempDir dir;
  struct Case {
    const char* text;
    const char* expected;
  };
  const Case cases[] = {
      {"fcae: x\n", "field 'fcae': unknown field"},
      {"removal: {targets: exact}\n", "field 'removal.targets'"},
      {"removal: {epochs: 0}\n", "field 'removal.epochs'"},
      {"export: {formats: [fbx]}\n", "unknown format 'fbx'"},
      {"takes: []\n", "field 'takes'"},
      {"threads: 0\n", "field 'threads'"},
      {"seed: -1\n", "field 'seed'"},
      {"reconstruct: {marker_diameter_px: fast}\n", "field 'reconstruct.marker_diameter_px'"},
      {"removal: {enabled: false}\n", "enable removal"},
      {"slurm: {cpus_per_task: 0}\n", "field 'slurm.cpus_per_task'"},
      {"- a list\n", "expected a map"},
  };
  for (const Case& c : cases) {
    const auto config = Load(dir, c.text);
    ASSERT_FALSE(config.ok()) << c.text;
    EXPECT_THAT(config.status().message(), HasSubstr(c.expected)) << c.text;
    EXPECT_THAT(config.status().message(), HasSubstr("p.yaml:")) << c.text;
  }
  EXPECT_FALSE(LoadProcessConfig(dir.Join("missing.yaml")).ok());
}

TEST(ProcessConfig, PatternsMatchLikeAShell) {
  EXPECT_TRUE(MatchesAnyPattern("smile_8hz", {"smile_*"}));
  EXPECT_TRUE(MatchesAnyPattern("speech", {"smile_*", "speech"}));
  EXPECT_FALSE(MatchesAnyPattern("speech_2", {"smile_*", "speech"}));
  EXPECT_TRUE(MatchesAnyPattern("walk_1", {"walk_?"}));
  EXPECT_FALSE(MatchesAnyPattern("walk_10", {"walk_?"}));
}

}  // namespace
}  // namespace facedyn::process
