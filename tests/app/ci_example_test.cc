// examples/ci-simulated-rig.sh, the README's hardware-free CI job: it passes on the shipped rig
// config and sweep script, and fails naming the stage when the sweep script under test is bad.

#include <arpa/inet.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <string>

#include "tests/support/test_support.h"

namespace {

using ::facedyn::testing::FacedynExecutable;
using ::facedyn::testing::RunCommand;
using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

// A TCP port free right now on loopback (the job's simulated drive listens there).
int FreePort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  address.sin_port = 0;
  socklen_t length = sizeof(address);
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length) != 0) {
    if (fd >= 0) ::close(fd);
    return 15020;
  }
  const int port = ntohs(address.sin_port);
  ::close(fd);
  return port;
}

std::string Job(const TempDir& dir, const std::string& environment) {
  return "FACEDYN=" + FacedynExecutable() + " FACEDYN_SIM_PORT=" + std::to_string(FreePort()) +
         " " + environment + " bash " + FACEDYN_SOURCE_DIR + "/examples/ci-simulated-rig.sh " +
         dir.Join("work");
}

TEST(CiExample, PassesOnTheShippedRigAndSweep) {
  TempDir dir;
  std::string out;
  ASSERT_EQ(RunCommand(Job(dir, ""), &out), 0) << out;
  EXPECT_THAT(out, HasSubstr("ci-simulated-rig: passed"));
  // Every stage ran and reported.
  for (const std::string& line :
       {std::string("== sweep script"), std::string("10.50 Hz  held"),
        std::string("take neutral_8hz: complete"),
        "session " + dir.Join("work/capture") + ": complete", std::string("mean error")}) {
    EXPECT_THAT(out, HasSubstr(line));
  }
}

TEST(CiExample, ABadSweepScriptFailsTheJobNamingTheStage) {
  TempDir dir;
  // 12 Hz is outside the rig's 6-11 Hz window: the plan check refuses it before anything moves.
  WriteBytes(dir.Join("bad.yaml"),
             "name: bad\nrig: " + std::string(FACEDYN_SOURCE_DIR) +
                 "/config/rigs/sim-tcp.yaml\ndefaults: {settle_timeout_s: 20, settle_s: 0, "
                 "hold_s: 1}\nsteps:\n  - {hz: 12, prompt: neutral}\n");
  std::string out;
  EXPECT_EQ(RunCommand(Job(dir, "FACEDYN_SWEEP=" + dir.Join("bad.yaml")), &out), 1) << out;
  EXPECT_THAT(out, HasSubstr("FAILED: the sweep script does not validate against the rig"));
  EXPECT_THAT(out, HasSubstr("12"));
  EXPECT_THAT(out, ::testing::Not(HasSubstr("== capture session")));
  // A missing config is named before anything starts.
  EXPECT_EQ(RunCommand(Job(dir, "FACEDYN_RIG_CONFIG=" + dir.Join("none.yaml")), &out), 1) << out;
  EXPECT_THAT(out, HasSubstr("no rig config " + dir.Join("none.yaml")));
}

}  // namespace
