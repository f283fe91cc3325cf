// The rig stage of `facedyn demo` (app/rig_demo.cc), compiled into this test.
#include "app/rig_demo.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

#include "rig/session_log.h"
#include "tests/rig/rig_test_util.h"

namespace facedyn::app {
namespace {

TEST(RunRigDemoStage, SweepsTheSimulatedRigAndReportsMeasuredFrequencies) {
  ::setenv("FACEDYN_CONFIG_DIR", (std::string(FACEDYN_SOURCE_DIR) + "/config").c_str(), 1);
  testing::TempDir dir;
  for (int run = 0; run < 2; ++run) {  // a second demo into the same folder replaces the first
    Json metrics;
    const Status status = RunRigDemoStage(dir.path(), /*quick=*/true, &metrics);
    ASSERT_TRUE(status.ok()) << status.ToString();
    ASSERT_EQ(metrics["steps"].size(), 3u);
    for (const Json& step : metrics["steps"]) {
      EXPECT_NEAR(step["measured_mean_hz"].get<double>(), step["target_hz"].get<double>(), 0.05);
      EXPECT_NEAR(step["true_platform_hz"].get<double>(), step["target_hz"].get<double>(), 0.05);
    }
    EXPECT_LE(metrics["worst_steady_state_error_hz"].get<double>(), 0.05);
    EXPECT_GT(metrics["exposure"]["vibrating_s"].get<double>(), 1.5);
    auto records = rig::ReadSessionLog(metrics["log"].get<std::string>());
    ASSERT_TRUE(records.ok()) << records.status().ToString();
    int done = 0;
    for (const Json& r : *records) done += r["event"] == "step_done";
    EXPECT_EQ(done, 3);
  }
}

TEST(RunRigDemoStage, MissingConfigIsAClearError) {
  ::setenv("FACEDYN_CONFIG_DIR", "/nonexistent/facedyn-config", 1);
  testing::TempDir dir;
  // The test binary is not next to a config folder, and ./config is not one when run by CTest
  // from the build folder.
  ASSERT_EQ(::chdir(dir.path().c_str()), 0);
  const Status status = RunRigDemoStage(dir.path(), true, nullptr);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), ::testing::HasSubstr("FACEDYN_CONFIG_DIR"));
}

}  // namespace
}  // namespace facedyn::app
