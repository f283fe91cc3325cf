// The exit-code contract of tests/support/test_main.cc, which CTest's SKIP_RETURN_CODE turns
// into "Skipped": this binary runs itself with filters and checks the code of each run.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <string>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

// Probes: harmless in a normal run; the environment makes them skip or fail.
TEST(Probe, SkipsWhenAsked) {
  if (std::getenv("FACEDYN_PROBE_SKIP")) GTEST_SKIP() << "asked to skip";
}
TEST(Probe, Passes) { SUCCEED(); }
TEST(Probe, FailsThenSkipsWhenAsked) {
  if (std::getenv("FACEDYN_PROBE_FAIL")) {
    ADD_FAILURE() << "asked to fail";
    GTEST_SKIP() << "a skip after a failure must not hide it";
  }
}

int RunSelf(const std::string& environment, const std::string& filter) {
  std::string output;
  return testing::RunCommand(
      environment + " /proc/" + std::to_string(::getpid()) + "/exe --gtest_filter=" + filter,
      &output);
}

TEST(TestMain, ExitCodeSaysSkippedOnlyWhenEveryCaseThatRanSkipped) {
  EXPECT_EQ(RunSelf("FACEDYN_PROBE_SKIP=1", "Probe.SkipsWhenAsked"), FACEDYN_TEST_SKIP_CODE);
  // One skipped and one passed: the binary passed (CTest runs each case on its own anyway).
  EXPECT_EQ(RunSelf("FACEDYN_PROBE_SKIP=1", "Probe.SkipsWhenAsked:Probe.Passes"), 0);
  EXPECT_EQ(RunSelf("", "Probe.SkipsWhenAsked"), 0);
  // A failure wins over a skip, alone or next to one.
  EXPECT_EQ(RunSelf("FACEDYN_PROBE_FAIL=1", "Probe.FailsThenSkipsWhenAsked"), 1);
  EXPECT_EQ(RunSelf("FACEDYN_PROBE_FAIL=1 FACEDYN_PROBE_SKIP=1",
                    "Probe.FailsThenSkipsWhenAsked:Probe.SkipsWhenAsked"),
            1);
  // Listing the cases (what gtest_discover_tests does) is not a skip.
  EXPECT_EQ(RunSelf("", "Probe.* --gtest_list_tests"), 0);
}

}  // namespace
}  // namespace facedyn
