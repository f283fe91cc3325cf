#include "rig/session_log.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <random>
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

// Issue 18, item 5: after a kill -9 mid-record, the next session's records must not glue onto
// the fragment. Open moves the fragment to log.jsonl.torn and the log reads cleanly after.
TEST(SessionLog, TornTailIsMovedAsideAndTheLogContinuesOnANewLine) {
  testing::TempDir dir;
  const std::string path = dir.Join("log.jsonl");
  const std::string fragment = "{\"event\":\"b\",\"t_";
  testing::WriteBytes(path, "{\"event\":\"a\",\"t_ns\":1}\n" + fragment);
  {
    auto log = SessionLog::Open(path);
    ASSERT_TRUE(log.ok()) << log.status().ToString();
    (*log)->Write("resume");
  }
  bool truncated = true;
  auto records = ReadSessionLog(path, &truncated);
  ASSERT_TRUE(records.ok()) << records.status().ToString();
  ASSERT_EQ(records->size(), 2u);
  EXPECT_EQ((*records)[0]["event"], "a");
  EXPECT_EQ((*records)[1]["event"], "resume");
  EXPECT_FALSE(truncated);
  EXPECT_EQ(testing::ReadBytes(path + ".torn"), fragment + "\n");  // nothing that was written is lost
}

// Repeated kill -9 at random points: every reopen repairs, and the log never holds a glued or
// duplicated record.
TEST(SessionLog, RandomTornTailsNeverBreakTheLog) {
  testing::TempDir dir;
  const std::string path = dir.Join("log.jsonl");
  std::mt19937 random(7);
  int written = 0;
  for (int round = 0; round < 50; ++round) {
    {
      auto log = SessionLog::Open(path);
      ASSERT_TRUE(log.ok()) << log.status().ToString();
      (*log)->Write("step", {{"n", written++}});
    }
    // A crash mid-write: append a random prefix of a record.
    const std::string record = "{\"event\":\"step\",\"n\":12345,\"pad\":\"xxxxxxxx\"}";
    const size_t cut = std::uniform_int_distribution<size_t>(1, record.size() - 1)(random);
    testing::WriteBytes(path, testing::ReadBytes(path) + record.substr(0, cut));
  }
  {
    auto log = SessionLog::Open(path);
    ASSERT_TRUE(log.ok());
  }
  auto records = ReadSessionLog(path);
  ASSERT_TRUE(records.ok()) << records.status().ToString();
  ASSERT_EQ(records->size(), 50u);
  for (int i = 0; i < 50; ++i) EXPECT_EQ((*records)[i]["n"], i);
}

}  // namespace
}  // namespace facedyn::rig
