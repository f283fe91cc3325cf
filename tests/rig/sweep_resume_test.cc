// ReadPriorSweep: what `sweep --resume` takes from a rig_log.jsonl that a crash tore or a person
// edited. Every field that decides what the resumed sweep does is checked.
#include "rig/sweep_resume.h"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>

#include "core/config_node.h"
#include "tests/support/test_support.h"

namespace facedyn::rig {
namespace {

using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

SweepScript Script() {
  auto root = ConfigNode::Parse("name: t\nsteps:\n  - {hz: 8, hold_s: 1}\n  - {hz: 9, hold_s: 1}\n",
                                "sweep.yaml");
  EXPECT_TRUE(root.ok()) << root.status().message();
  auto script = ParseSweepScript(*root, "/base", 42);
  EXPECT_TRUE(script.ok()) << script.status().message();
  return *script;
}

std::string Start(const SweepScript& script) {
  return fmt::format("{{\"event\":\"sweep_start\",\"t_ns\":1,\"script_hash\":\"{:016x}\"}}\n",
                     script.text_hash);
}

StatusOr<PriorSweep> Read(const TempDir& dir, const std::string& log) {
  const std::string path = dir.Join("rig_log.jsonl");
  WriteBytes(path, log);
  return ReadPriorSweep(path, Script(), 2);
}

TEST(ReadPriorSweep, DoneInterruptedAndExposure) {
  TempDir dir;
  const SweepScript script = Script();
  const auto prior = Read(
      dir, Start(script) +
               "{\"event\":\"step_start\",\"t_ns\":2,\"instance\":0}\n"
               "{\"event\":\"step_done\",\"t_ns\":3,\"instance\":0,\"hz\":8,\"prompt\":\"smile\","
               "\"hold\":{\"seconds\":1.0,\"samples\":10},\"vibrating_s\":1.5,\"dose_m2_s3\":2.0,"
               "\"exposure\":{\"peak_rms_m_s2\":0.7}}\n"
               "{\"event\":\"step_start\",\"t_ns\":4,\"instance\":1}\n");
  ASSERT_TRUE(prior.ok()) << prior.status().message();
  EXPECT_TRUE(prior->started);
  EXPECT_FALSE(prior->finished);
  ASSERT_EQ(prior->done.size(), 1u);
  EXPECT_EQ(prior->done.at(0).prompt, "smile");
  EXPECT_EQ(prior->done.at(0).hold.samples, 10);
  EXPECT_EQ(prior->interrupted, 1);
  EXPECT_EQ(prior->last_t_ns, 4);
  EXPECT_DOUBLE_EQ(prior->vibrating_s, 1.5);
  EXPECT_DOUBLE_EQ(prior->dose_m2_s3, 2.0);
  EXPECT_DOUBLE_EQ(prior->peak_rms_m_s2, 0.7);
}

// Exposure only grows: an edited record that lowers it does not lower the actor's dose.
TEST(ReadPriorSweep, ExposureIsTheLargestRecordedNotTheLast) {
  TempDir dir;
  const auto prior = Read(dir, Start(Script()) +
                                   "{\"event\":\"x\",\"vibrating_s\":9,\"dose_m2_s3\":5}\n"
                                   "{\"event\":\"x\",\"vibrating_s\":1,\"dose_m2_s3\":0.5}\n");
  ASSERT_TRUE(prior.ok()) << prior.status().message();
  EXPECT_DOUBLE_EQ(prior->vibrating_s, 9.0);
  EXPECT_DOUBLE_EQ(prior->dose_m2_s3, 5.0);
}

TEST(ReadPriorSweep, BadRecordsAreErrorsNamingTheRecord) {
  const SweepScript script = Script();
  struct Case {
    std::string record;
    std::string message;
  };
  const Case cases[] = {
      {"{\"event\":\"step_done\",\"instance\":2}", "step instance 2 is not in the script"},
      {"{\"event\":\"step_start\",\"instance\":-1}", "step instance -1 is not in the script"},
      {"{\"event\":\"step_start\",\"instance\":1099511627776}", "not in the script"},
      {"{\"event\":\"step_done\",\"instance\":\"0\"}", "record 2 is not a valid sweep record"},
      {"{\"event\":\"step_done\"}", "record 2 is not a valid sweep record"},
      {"{\"event\":\"x\",\"vibrating_s\":-5,\"dose_m2_s3\":1}", "'vibrating_s' is -5"},
      {"{\"event\":\"x\",\"vibrating_s\":1,\"dose_m2_s3\":-1e300}", "'dose_m2_s3'"},
      {"{\"event\":\"x\",\"exposure\":{\"peak_rms_m_s2\":-1}}", "'peak_rms_m_s2'"},
      {"{\"event\":\"step_done\",\"instance\":0,\"hold\":[1]}", "'hold' is not an object"},
      {"{\"event\":\"step_done\",\"instance\":0,\"hold\":{\"seconds\":-1}}", "'seconds'"},
      {"{\"event\":7}", "record 2 is not a valid sweep record"},
      {"[1,2]", "rig_log.jsonl:2: not a session log record"},
      // Floats where integers belong: converting 8.9e74 to int64 was undefined behaviour.
      {"{\"event\":\"step_start\",\"instance\":8.88889e+74}", "'instance' is 8.88889e+74"},
      {"{\"event\":\"step_start\",\"instance\":1.0}", "not an integer"},
      {"{\"event\":\"x\",\"t_ns\":1e300}", "'t_ns'"},
      {"{\"event\":\"x\",\"t_ns\":18446744073709551615}", "beyond int64"},
      {"{\"event\":\"step_done\",\"instance\":0,\"hold\":{\"samples\":-3}}", "'samples'"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.record);
    TempDir dir;
    const auto prior = Read(dir, Start(script) + c.record + "\n");
    ASSERT_FALSE(prior.ok());
    EXPECT_EQ(prior.status().code(), StatusCode::kDataLoss);
    EXPECT_THAT(prior.status().message(), HasSubstr(c.message));
  }
}

TEST(ReadPriorSweep, OtherScriptTwiceDoneAndForeignLogs) {
  TempDir dir;
  auto other = Read(dir, "{\"event\":\"sweep_start\",\"script_hash\":\"0000000000000001\"}\n");
  ASSERT_FALSE(other.ok());
  EXPECT_THAT(other.status().message(), HasSubstr("different sweep script"));
  auto twice = Read(dir, Start(Script()) +
                             "{\"event\":\"step_done\",\"instance\":1}\n"
                             "{\"event\":\"step_done\",\"instance\":1}\n");
  ASSERT_FALSE(twice.ok());
  EXPECT_THAT(twice.status().message(), HasSubstr("marked done twice"));
  auto foreign = Read(dir, "{\"event\":\"hello\"}\n");
  ASSERT_FALSE(foreign.ok());
  EXPECT_THAT(foreign.status().message(), HasSubstr("no sweep_start"));
  auto empty = Read(dir, "");
  ASSERT_TRUE(empty.ok()) << empty.status().message();
  EXPECT_FALSE(empty->started);
}

}  // namespace
}  // namespace facedyn::rig
