// The stop flag's signals (issue 18, item 2): INT, TERM, HUP and QUIT request a ramp to stop;
// SIGPIPE is ignored, so a closed stdout reader turns writes into EPIPE instead of a kill.
#include "rig/stop_signal.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>

namespace facedyn::rig {
namespace {

TEST(StopSignal, EveryStopSignalSetsTheFlag) {
  const std::atomic<bool>* flag = InstallStopSignalHandlers();
  for (int signal_number : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) {
    ClearStopRequest();
    ASSERT_FALSE(flag->load());
    ASSERT_EQ(::raise(signal_number), 0);
    EXPECT_TRUE(flag->load()) << "signal " << signal_number;  // and the process is alive
  }
  ClearStopRequest();
}

TEST(StopSignal, ClosedPipeIsAnErrorNotAKill) {
  InstallStopSignalHandlers();
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  ::close(fds[0]);
  const char byte = 'x';
  const ssize_t written = ::write(fds[1], &byte, 1);
  const int error = errno;
  ::close(fds[1]);
  EXPECT_EQ(written, -1);
  EXPECT_EQ(error, EPIPE);
  ASSERT_EQ(::raise(SIGPIPE), 0);  // ignored: still here
  ClearStopRequest();
}

}  // namespace
}  // namespace facedyn::rig
