#include "rig/drive_profile.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>

#include "tests/rig/rig_test_util.h"

namespace facedyn::rig {
namespace {

using ::testing::HasSubstr;

const char* const kRealProfiles[] = {"delta_ms300", "invertek_e3", "siemens_v20"};

TEST(LoadDriveProfile, ShippedProfilesLoad) {
  for (const char* name : {"delta_ms300", "invertek_e3", "siemens_v20", "sim"}) {
    auto profile = LoadDriveProfile(testing::DriveProfilePath(name));
    ASSERT_TRUE(profile.ok()) << profile.status().ToString();
    EXPECT_EQ(profile->name, name);
    EXPECT_FALSE(profile->fault_reset_values.empty());
  }
}

TEST(LoadDriveProfile, DeltaMapMatchesManual) {
  const DriveProfile p = testing::LoadProfileOrDie("delta_ms300");
  EXPECT_EQ(p.command_register, 0x2000);
  EXPECT_EQ(p.setpoint_register, 0x2001);
  EXPECT_EQ(p.status_register, 0x2101);
  EXPECT_EQ(p.output_frequency_register, 0x2103);
  EXPECT_EQ(p.fault_reset_register, 0x2002);
  ASSERT_TRUE(p.comm_watchdog.has_value());
  EXPECT_EQ(p.comm_watchdog->register_address, 0x0903);
  EXPECT_TRUE(p.IsRunning(0x0003));
  EXPECT_FALSE(p.IsRunning(0x0002));
}

TEST(LoadDriveProfile, InvertekSharesStatusAndFaultRegister) {
  const DriveProfile p = testing::LoadProfileOrDie("invertek_e3");
  EXPECT_EQ(p.command_register, 1);
  EXPECT_EQ(p.setpoint_register, 2);
  EXPECT_EQ(p.fault_code_register, 6);
  EXPECT_EQ(p.FaultCodeFrom(0x0D02), 13);
  EXPECT_TRUE(p.IsFaultBitSet(0x0D02));
  EXPECT_THAT(p.DescribeFault(13), HasSubstr("communications loss"));
  EXPECT_THAT(p.DescribeFault(200), HasSubstr("unknown"));
}

TEST(FrequencyScaling, RoundTripsEveryRealProfileAcrossTheBand) {
  for (const char* name : kRealProfiles) {
    const DriveProfile p = testing::LoadProfileOrDie(name);
    for (double hz = 6.0; hz <= 11.0 + 1e-9; hz += 0.1) {
      auto counts = p.setpoint_scaling.HzToRegister(hz, "setpoint");
      ASSERT_TRUE(counts.ok()) << name << " " << counts.status().ToString();
      // Resolution is one count: 0.01 Hz (Delta), 0.1 Hz (E3), 50/16384 Hz (V20).
      EXPECT_NEAR(p.setpoint_scaling.RegisterToHz(*counts), hz,
                  0.5 / p.setpoint_scaling.CountsPerHz())
          << name;
    }
  }
}

TEST(FrequencyScaling, KnownValues) {
  EXPECT_EQ(*testing::LoadProfileOrDie("delta_ms300").setpoint_scaling.HzToRegister(7.5, "x"), 750);
  EXPECT_EQ(*testing::LoadProfileOrDie("invertek_e3").setpoint_scaling.HzToRegister(7.5, "x"), 75);
  const DriveProfile v20 = testing::LoadProfileOrDie("siemens_v20");
  EXPECT_EQ(*v20.setpoint_scaling.HzToRegister(50.0, "x"), 16384);
  EXPECT_EQ(*v20.setpoint_scaling.HzToRegister(25.0, "x"), 8192);
  // HIW is signed: reverse rotation reads negative.
  EXPECT_NEAR(v20.output_scaling.RegisterToHz(static_cast<uint16_t>(-8192)), -25.0, 1e-9);
}

TEST(FrequencyScaling, RefusesValuesThatDoNotFit16Bits) {
  FrequencyScaling delta;  // 100 counts per Hz
  auto too_big = delta.HzToRegister(700.0, "delta setpoint");
  ASSERT_FALSE(too_big.ok());
  EXPECT_THAT(too_big.status().message(), HasSubstr("delta setpoint"));
  EXPECT_THAT(too_big.status().message(), HasSubstr("16-bit"));
  EXPECT_FALSE(delta.HzToRegister(-1.0, "x").ok());
  FrequencyScaling v20{16384, 50.0, true};
  EXPECT_FALSE(v20.HzToRegister(100.0, "x").ok());  // 32768 > int16 max
  EXPECT_TRUE(v20.HzToRegister(-50.0, "x").ok());
}

const char kMinimal[] = R"(name: test
registers: {command: 0, setpoint: 1, status: 2, output_frequency: 3, fault_code: 4}
setpoint_scaling: {counts: 100, hz: 1}
output_scaling: {counts: 100, hz: 1}
command: {run: 1, stop: 0, fault_reset: [4]}
status: {running_mask: 1, running_value: 1}
)";

TEST(ParseDriveProfile, MinimalProfileParses) {
  auto root = ConfigNode::Parse(kMinimal, "test.yaml");
  ASSERT_TRUE(root.ok());
  auto profile = ParseDriveProfile(*root);
  ASSERT_TRUE(profile.ok()) << profile.status().ToString();
  EXPECT_EQ(profile->MaxRegister(), 4);
}

Status ParseText(const std::string& text) {
  auto root = ConfigNode::Parse(text, "drive.yaml");
  if (!root.ok()) return root.status();
  return ParseDriveProfile(*root).status();
}

TEST(ParseDriveProfile, MissingFieldNamesFileLineAndField) {
  std::string text = kMinimal;
  text.replace(text.find("status: 2, "), 11, "");
  const Status status = ParseText(text);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("drive.yaml:2:"));
  EXPECT_THAT(status.message(), HasSubstr("registers.status"));
}

TEST(ParseDriveProfile, BadRegisterIsRefused) {
  std::string text = kMinimal;
  text.replace(text.find("setpoint: 1,"), 12, "setpoint: 0x1FFFF,");
  Status status = ParseText(text);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("registers.setpoint"));
  EXPECT_THAT(status.message(), HasSubstr("0x1FFFF"));

  text = kMinimal;
  text.replace(text.find("setpoint: 1,"), 12, "setpoint: two,");
  status = ParseText(text);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("'two'"));

  text = kMinimal;
  text.replace(text.find("setpoint: 1,"), 12, "setpoint: 0,");
  status = ParseText(text);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("also the command register"));
}

TEST(ParseDriveProfile, RunEqualToStopIsRefused) {
  std::string text = kMinimal;
  text.replace(text.find("stop: 0"), 7, "stop: 1");
  const Status status = ParseText(text);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("command.stop"));
}

TEST(LoadDriveProfile, MalformedYamlNamesFileAndLine) {
  testing::TempDir dir;
  const std::string path = dir.Join("broken.yaml");
  testing::WriteBytes(path, "name: x\nregisters: {command: 0,\n  setpoint: [1\nstatus: 2\n");
  auto profile = LoadDriveProfile(path);
  ASSERT_FALSE(profile.ok());
  EXPECT_THAT(profile.status().message(), HasSubstr(path + ":"));
  EXPECT_THAT(profile.status().message(), HasSubstr("syntax error"));
}

TEST(LoadDriveProfile, MissingFileIsAnError) {
  auto profile = LoadDriveProfile("/nonexistent/drive.yaml");
  ASSERT_FALSE(profile.ok());
  EXPECT_THAT(profile.status().message(), HasSubstr("/nonexistent/drive.yaml"));
}

}  // namespace
}  // namespace facedyn::rig
