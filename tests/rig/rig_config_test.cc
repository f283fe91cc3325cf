#include "rig/rig_config.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>

#include "tests/rig/rig_test_util.h"

namespace facedyn::rig {
namespace {

using ::testing::HasSubstr;

const char* const kShippedRigs[] = {"sim-tcp", "sim-rtu", "delta-ms300", "invertek-e3",
                                    "siemens-v20"};

TEST(LoadRigConfig, ShippedConfigsLoad) {
  for (const char* name : kShippedRigs) {
    SCOPED_TRACE(name);
    auto config = LoadRigConfig(testing::RigConfigPath(name));
    ASSERT_TRUE(config.ok()) << config.status().ToString();
    EXPECT_EQ(config->name, name);
    EXPECT_EQ(config->limits.min_hz, 6.0);
    EXPECT_EQ(config->limits.max_hz, 11.0);
    EXPECT_TRUE(config->Check().ok());
  }
  auto tcp = LoadRigConfig(testing::RigConfigPath("sim-tcp"));
  ASSERT_TRUE(tcp.ok());
  EXPECT_EQ(tcp->transport.kind, TransportOptions::Kind::kTcp);
  EXPECT_EQ(tcp->transport.port, 5020);
  EXPECT_EQ(tcp->profile.name, "sim");
  auto rtu = LoadRigConfig(testing::RigConfigPath("siemens-v20"));
  ASSERT_TRUE(rtu.ok());
  EXPECT_EQ(rtu->transport.kind, TransportOptions::Kind::kRtu);
  EXPECT_EQ(rtu->transport.parity, 'E');
  EXPECT_EQ(rtu->feedback, "drive_output");
}

// Writes the sim-tcp config with one line replaced, and returns the load error.
std::string ErrorWith(const testing::TempDir& dir, const std::string& from, const std::string& to) {
  std::string text = testing::ReadBytes(testing::RigConfigPath("sim-tcp"));
  const size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at == std::string::npos) return "";
  text.replace(at, from.size(), to);
  text.replace(text.find("../drives/sim.yaml"), 18, testing::DriveProfilePath("sim"));
  const std::string path = dir.Join("rig.yaml");
  testing::WriteBytes(path, text);
  auto config = LoadRigConfig(path);
  EXPECT_FALSE(config.ok()) << "accepted: " << to;
  return config.ok() ? "" : config.status().message();
}

TEST(LoadRigConfig, BadFieldsAreNamed) {
  testing::TempDir dir;
  EXPECT_THAT(ErrorWith(dir, "max_hz: 11.0", "max_hz: 12.0"), HasSubstr("limits.max_hz"));
  EXPECT_THAT(ErrorWith(dir, "max_hz: 11.0", "max_hz: 5.0"), HasSubstr("below min_hz"));
  EXPECT_THAT(ErrorWith(dir, "max_hz: 11.0", "max_hz: fast"), HasSubstr("limits.max_hz"));
  EXPECT_THAT(ErrorWith(dir, "kind: tcp", "kind: can"), HasSubstr("transport.kind"));
  EXPECT_THAT(ErrorWith(dir, "port: 5020", "port: 70000"), HasSubstr("transport.port"));
  EXPECT_THAT(ErrorWith(dir, "slip: 0.03", "slip: 0.7"), HasSubstr("platform.slip"));
  EXPECT_THAT(ErrorWith(dir, "feedback: sensor", "feedback: guess"),
              HasSubstr("platform.feedback"));
  EXPECT_THAT(ErrorWith(dir, "motor_max_hz: 13.0", "motor_max_hz: 11.0"),
              HasSubstr("limits.motor_max_hz"));
  EXPECT_THAT(ErrorWith(dir, "comm_watchdog_s: 1.0", "comm_watchdog_s: 0.2"),
              HasSubstr("safety.comm_watchdog_s"));
  EXPECT_THAT(ErrorWith(dir, "max_ramp_hz_per_s: 2.0", "max_ramp_hz_per_sec: 2.0"),
              HasSubstr("limits.max_ramp_hz_per_sec': unknown field"));
  EXPECT_THAT(ErrorWith(dir, "  port: 5020\n", "  port: 5020\n  device: /dev/ttyS0\n"),
              HasSubstr("only applies to kind: rtu"));
  // The error names the file and line.
  EXPECT_THAT(ErrorWith(dir, "slip: 0.03", "slip: -1"), HasSubstr("rig.yaml:"));
}

TEST(LoadRigConfig, SensorFeedbackNeedsTheRegister) {
  testing::TempDir dir;
  std::string text = testing::ReadBytes(testing::RigConfigPath("sim-tcp"));
  text.replace(text.find("../drives/sim.yaml"), 18, testing::DriveProfilePath("delta_ms300"));
  testing::WriteBytes(dir.Join("rig.yaml"), text);
  auto config = LoadRigConfig(dir.Join("rig.yaml"));
  ASSERT_FALSE(config.ok());
  EXPECT_THAT(config.status().message(), HasSubstr("platform.feedback"));
  EXPECT_THAT(config.status().message(), HasSubstr("oscillation_frequency"));
}

TEST(LoadRigConfig, WatchdogLongerThanTheDriveAllowsIsRefused) {
  testing::TempDir dir;
  std::string text = testing::ReadBytes(testing::RigConfigPath("delta-ms300"));
  text.replace(text.find("../drives/delta_ms300.yaml"), 26,
               testing::DriveProfilePath("delta_ms300"));
  text.replace(text.find("comm_watchdog_s: 1.0"), 20, "comm_watchdog_s: 150");
  testing::WriteBytes(dir.Join("rig.yaml"), text);
  auto config = LoadRigConfig(dir.Join("rig.yaml"));
  ASSERT_FALSE(config.ok());
  EXPECT_THAT(config.status().message(),
              HasSubstr("safety.comm_watchdog_s: 150 s is above the 100 s"));
  EXPECT_THAT(config.status().message(), HasSubstr("Pr.09-03"));
}

TEST(LoadRigConfig, MissingProfileIsNamed) {
  testing::TempDir dir;
  std::string text = testing::ReadBytes(testing::RigConfigPath("sim-tcp"));
  text.replace(text.find("../drives/sim.yaml"), 18, dir.Join("nope.yaml"));
  testing::WriteBytes(dir.Join("rig.yaml"), text);
  auto config = LoadRigConfig(dir.Join("rig.yaml"));
  ASSERT_FALSE(config.ok());
  EXPECT_THAT(config.status().message(), HasSubstr("drive_profile"));
  EXPECT_THAT(config.status().message(), HasSubstr("nope.yaml"));
}

TEST(RigConfig, MotorLimitsCoverTheWindowPlusTrim) {
  auto config = LoadRigConfig(testing::RigConfigPath("sim-tcp"));
  ASSERT_TRUE(config.ok());
  const DriveLimits motor = config->MotorLimits();
  const PlatformModel model(config->platform);
  EXPECT_LE(motor.window_min_hz, model.MotorHzFor(6.0));
  EXPECT_GE(motor.window_max_hz, model.MotorHzFor(11.0));
  EXPECT_LE(motor.window_max_hz, config->limits.motor_max_hz);
  EXPECT_TRUE(motor.Check().ok());
}

}  // namespace
}  // namespace facedyn::rig
