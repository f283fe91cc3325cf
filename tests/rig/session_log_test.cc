#include "rig/session_log.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>

#include "tests/support/test_support.h"

namespace facedyn::rig {
namespace {

using ::testing::HasSubstr;

TEST(SessionLog, RoundTripAndAppend) {
  testing::TempDir dir;
  const std::string path = dir.Join("log.jsonl");
  {
    auto log = SessionLog::Open(path);
    ASSERT_TRUE(log.ok()) << log.status().ToString();
    (*log)->Write("command", {{"command", "run"}, {"value", 1}});
    (*log)->Write("state", {{"from", "idle"}, {"to", "ramping"}});
    EXPECT_TRUE((*log)->status().ok());
  }
  {
    auto log = SessionLog::Open(path, 5'000'000'000);  // continues the session clock
    ASSERT_TRUE(log.ok());
    (*log)->Write("resume");
  }
  auto records = ReadSessionLog(path);
  ASSERT_TRUE(records.ok()) << records.status().ToString();
  ASSERT_EQ(records->size(), 3u);
  EXPECT_EQ((*records)[0]["event"], "command");
  EXPECT_EQ((*records)[0]["value"], 1);
  EXPECT_EQ((*records)[1]["to"], "ramping");
  EXPECT_LE((*records)[0]["t_ns"].get<int64_t>(), (*records)[1]["t_ns"].get<int64_t>());
  EXPECT_GE((*records)[2]["t_ns"].get<int64_t>(), 5'000'000'000);
  EXPECT_THAT((*records)[2]["wall"].get<std::string>(), ::testing::EndsWith("Z"));
}

TEST(ReadSessionLog, SkipsATruncatedLastLine) {
  testing::TempDir dir;
  const std::string path = dir.Join("log.jsonl");
  testing::WriteBytes(path, "{\"event\":\"a\",\"t_ns\":1}\n{\"event\":\"b\",\"t_");
  bool truncated = false;
  auto records = ReadSessionLog(path, &truncated);
  ASSERT_TRUE(records.ok());
  EXPECT_EQ(records->size(), 1u);
  EXPECT_TRUE(truncated);
}

TEST(ReadSessionLog, CorruptLineInTheMiddleIsAnErrorNamingTheLine) {
  testing::TempDir dir;
  const std::string path = dir.Join("log.jsonl");
  testing::WriteBytes(path, "{\"event\":\"a\"}\nnot json\n{\"event\":\"b\"}\n");
  auto records = ReadSessionLog(path);
  ASSERT_FALSE(records.ok());
  EXPECT_EQ(records.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(records.status().message(), HasSubstr("log.jsonl:2"));
}

TEST(ReadSessionLog, MissingFileIsAnError) {
  auto records = ReadSessionLog("/nonexistent/facedyn/log.jsonl");
  EXPECT_FALSE(records.ok());
}

}  // namespace
}  // namespace facedyn::rig
