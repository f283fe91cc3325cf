#include "sim/drive_sim.h"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "rig/drive_client.h"
#include "rig/modbus_transport.h"
#include "tests/rig/rig_test_util.h"

namespace facedyn::sim {
namespace {

TEST(DriveModel, RampsAtAccelRateOnVirtualClock) {
  DriveModelOptions options;
  options.accel_hz_per_s = 5.0;
  DriveModel model(options);
  model.SetSetpointHz(10.0);
  model.Run();
  for (int i = 0; i < 100; ++i) model.Advance(0.01);
  EXPECT_NEAR(model.state().output_hz, 5.0, 1e-9);
  for (int i = 0; i < 200; ++i) model.Advance(0.01);
  EXPECT_NEAR(model.state().output_hz, 10.0, 1e-12);  // holds the setpoint, no overshoot
  model.Stop();
  model.Advance(0.5);
  EXPECT_NEAR(model.state().output_hz, 7.5, 1e-9);
}

TEST(DriveModel, WatchdogStopsWhenSilent) {
  DriveModelOptions options;
  options.watchdog_s = 0.5;
  options.watchdog_fault_code = 10;
  DriveModel model(options);
  model.SetSetpointHz(8.0);
  model.Run();
  model.NoteRequest();
  model.Advance(0.4);
  EXPECT_TRUE(model.running());
  model.Advance(0.2);
  EXPECT_FALSE(model.running());
  EXPECT_TRUE(model.state().watchdog_fired);
  EXPECT_EQ(model.state().fault_code, 10);
}

TEST(DriveModel, TripCoastsAndBlocksRunUntilReset) {
  DriveModel model(DriveModelOptions{});
  model.SetSetpointHz(8.0);
  model.Run();
  model.Advance(1.0);
  model.ForceFault(1);
  model.Advance(0.01);
  EXPECT_EQ(model.state().output_hz, 0.0);
  model.Run();
  EXPECT_FALSE(model.running());
  model.ResetFault();
  model.Run();
  EXPECT_TRUE(model.running());
}

// An independent client (pymodbus) drives the simulated drive per sim.yaml.
TEST(DriveSim, AnswersPymodbusClientPerSimProfile) {
  FACEDYN_REQUIRE_PYMODBUS();
  const rig::DriveProfile profile = testing::LoadProfileOrDie("sim");
  DriveSimOptions options;
  options.model.accel_hz_per_s = 10.0;
  auto sim = DriveSim::Start(profile, options);
  ASSERT_TRUE(sim.ok()) << sim.status().ToString();
  const std::string command = fmt::format(
      "/usr/bin/python3 {} --port {} --setpoint-register {} --counts-per-hz {} --hz 8 "
      "--command-register {} --run-value {} --output-register {} --status-register {} --seconds "
      "1.2",
      testing::RigTestScript("pymodbus_client.py"), (*sim)->port(), profile.setpoint_register,
      profile.setpoint_scaling.CountsPerHz(), profile.command_register, profile.run_value,
      profile.output_frequency_register, profile.status_register);
  std::string output;
  ASSERT_EQ(testing::RunCommand(command, &output), 0) << output;
  const auto json = nlohmann::json::parse(output.substr(output.find('{')));
  const auto samples = json["samples_hz"].get<std::vector<double>>();
  ASSERT_GE(samples.size(), 5u);
  for (size_t i = 1; i < samples.size(); ++i) EXPECT_GE(samples[i], samples[i - 1]);  // ramps up
  EXPECT_LT(samples.front(), 4.0);
  EXPECT_NEAR(samples.back(), 8.0, 0.01);
  EXPECT_TRUE(profile.IsRunning(static_cast<uint16_t>(json["status"].get<int>())));
}

TEST(DriveSim, WatchdogStopsMotorWhenClientGoesSilent) {
  const rig::DriveProfile profile = testing::LoadProfileOrDie("sim");
  DriveSimOptions options;
  options.model.accel_hz_per_s = 50.0;
  options.model.watchdog_fault_code = 10;
  auto sim = DriveSim::Start(profile, options);
  ASSERT_TRUE(sim.ok());
  rig::TransportOptions transport_options;
  transport_options.port = (*sim)->port();
  auto transport = rig::ModbusTransport::Open(transport_options);
  ASSERT_TRUE(transport.ok());
  // The watchdog time is written over Modbus, as a client would on a real drive.
  ASSERT_TRUE(
      (*transport)->WriteRegister(*profile.comm_watchdog->register_address, 3).ok());  // 0.3 s
  rig::DriveClient client(transport->get(), profile);
  ASSERT_TRUE(client.SetFrequencyHz(8.0).ok());
  ASSERT_TRUE(client.Start().ok());
  for (int i = 0; i < 4; ++i) {  // keep talking: the motor runs
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    auto status = client.ReadStatus();
    ASSERT_TRUE(status.ok());
    EXPECT_TRUE(status->running);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(600));  // silence > watchdog
  EXPECT_TRUE((*sim)->state().watchdog_fired);
  auto status = client.ReadStatus();
  ASSERT_TRUE(status.ok());
  EXPECT_FALSE(status->running);
  EXPECT_EQ(status->fault_code, 10);
  EXPECT_EQ(status->output_hz, 0.0);
}

TEST(DriveModel, PlatformFollowsRatioAndLoadDependentSlip) {
  DriveModelOptions options;
  options.accel_hz_per_s = 100.0;
  options.platform_ratio = 0.5;
  options.slip_base = 0.01;
  options.slip_load = 0.04;
  options.slip_reference_hz = 20.0;
  options.sensor_noise_hz = 0.0;
  DriveModel model(options);
  model.SetSetpointHz(20.0);
  model.Run();
  for (int i = 0; i < 200; ++i) model.Advance(0.005);
  EXPECT_NEAR(model.state().output_hz, 20.0, 1e-12);
  EXPECT_NEAR(model.SlipAt(20.0), 0.05, 1e-12);
  EXPECT_NEAR(model.SlipAt(10.0), 0.02, 1e-12);
  EXPECT_NEAR(model.state().platform_hz, 20.0 * 0.5 * 0.95, 1e-12);
}

TEST(DriveModel, SensorReportsTheMeanFrequencyOverItsWindow) {
  DriveModelOptions options;
  options.accel_hz_per_s = 1000.0;  // steps, so the window average is easy to predict
  options.slip_base = 0.0;
  options.slip_load = 0.0;
  options.sensor_window_s = 0.5;
  options.sensor_noise_hz = 0.0;
  DriveModel model(options);
  model.SetSetpointHz(8.0);
  model.Run();
  for (int i = 0; i < 200; ++i) model.Advance(0.005);  // 1 s at 8 Hz
  EXPECT_NEAR(model.state().sensor_hz, 8.0, 1e-3);
  model.SetSetpointHz(10.0);
  for (int i = 0; i < 50; ++i) model.Advance(0.005);  // 0.25 s at 10 Hz: half the window
  EXPECT_NEAR(model.state().platform_hz, 10.0, 1e-12);
  EXPECT_NEAR(model.state().sensor_hz, 9.0, 0.03);
  for (int i = 0; i < 60; ++i) model.Advance(0.005);
  EXPECT_NEAR(model.state().sensor_hz, 10.0, 1e-3);
}

TEST(DriveModel, SensorNoiseHasTheConfiguredSpread) {
  DriveModelOptions options;
  options.accel_hz_per_s = 1000.0;
  options.sensor_noise_hz = 0.01;
  DriveModel model(options);
  model.SetSetpointHz(9.0);
  model.Run();
  for (int i = 0; i < 200; ++i) model.Advance(0.005);
  double sum = 0.0, sum_sq = 0.0;
  const int n = 4000;
  for (int i = 0; i < n; ++i) {
    model.Advance(0.005);
    const double e = model.state().sensor_hz - model.state().platform_hz;
    sum += e;
    sum_sq += e * e;
  }
  const double mean = sum / n;
  EXPECT_NEAR(mean, 0.0, 0.001);
  EXPECT_NEAR(std::sqrt(sum_sq / n - mean * mean), 0.01, 0.001);
}

TEST(DriveModel, ScheduledTripFiresAfterRunningTime) {
  DriveModelOptions options;
  DriveModel model(options);
  model.SetSetpointHz(8.0);
  model.ScheduleTrip(0.5, 2);
  model.Advance(1.0);  // not running: the trip clock does not advance
  EXPECT_EQ(model.state().fault_code, 0);
  model.Run();
  model.Advance(0.4);
  EXPECT_EQ(model.state().fault_code, 0);
  model.Advance(0.2);
  EXPECT_EQ(model.state().fault_code, 2);
  EXPECT_EQ(model.state().output_hz, 0.0);
}

TEST(ParseDriveModelOptions, ReadsFieldsAndNamesBadOnes) {
  auto node =
      ConfigNode::Parse("sim:\n  accel_hz_per_s: 7\n  slip_load: 0.05\n  seed: 3\n", "rig.yaml");
  ASSERT_TRUE(node.ok());
  DriveModelOptions options;
  ASSERT_TRUE(ParseDriveModelOptions(*node->Child("sim"), &options).ok());
  EXPECT_EQ(options.accel_hz_per_s, 7.0);
  EXPECT_EQ(options.slip_load, 0.05);
  EXPECT_EQ(options.seed, 3u);
  for (const char* bad :
       {"sim:\n  slip: 0.1\n", "sim:\n  slip_base: 0.9\n", "sim:\n  sensor_window_s: x\n"}) {
    SCOPED_TRACE(bad);
    auto parsed = ConfigNode::Parse(bad, "rig.yaml");
    ASSERT_TRUE(parsed.ok());
    DriveModelOptions o;
    const Status status = ParseDriveModelOptions(*parsed->Child("sim"), &o);
    ASSERT_FALSE(status.ok());
    EXPECT_THAT(status.message(), ::testing::HasSubstr("rig.yaml:2: field 'sim."));
  }
}

TEST(DriveSim, OptionsCheckNamesField) {
  DriveSimOptions options;
  options.model.accel_hz_per_s = 0.0;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("accel_hz_per_s"));
}

}  // namespace
}  // namespace facedyn::sim
