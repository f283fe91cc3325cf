// main() of every facedyn test binary (instead of GoogleTest's gtest_main): the same run, but
// a binary in which every case that ran was skipped exits with FACEDYN_TEST_SKIP_CODE, which
// CTest's SKIP_RETURN_CODE reports as "Skipped" (cmake/FacedynHelpers.cmake). gtest_main exits
// 0 for a skip, so a test whose peer (socat, pymodbus, umockdev, a shared asset) was missing
// used to count as passed.
//
// The exit code is decided from GoogleTest's own counts, not from its output: a failure always
// wins (a failed case is never counted as skipped, even if it called GTEST_SKIP after failing),
// and a crash or a sanitizer report after the tests still changes the exit code and fails.
// (For the per-case tests, CMake's gtest_discover_tests also sets SKIP_REGULAR_EXPRESSION on
// GoogleTest's "[  SKIPPED ]" line; the two agree, since GoogleTest prints that line only for
// a case that skipped without failing.)
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#ifndef FACEDYN_TEST_SKIP_CODE
#error "FACEDYN_TEST_SKIP_CODE must be defined by the build (CTest's SKIP_RETURN_CODE)"
#endif

int main(int argc, char** argv) {
  ::testing::InitGoogleMock(&argc, argv);
  const int result = RUN_ALL_TESTS();
  if (result != 0) return result;
  const ::testing::UnitTest& unit = *::testing::UnitTest::GetInstance();
  // Some cases passed and some skipped: the binary passed. Each case is its own CTest test
  // (gtest_discover_tests) unless the binary is registered ONE_PROCESS, so this only hides a
  // skip in those few binaries.
  if (unit.skipped_test_count() > 0 && unit.successful_test_count() == 0) {
    return FACEDYN_TEST_SKIP_CODE;
  }
  return 0;
}
