#include "sim/drive_sim.h"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

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

// A raw Modbus TCP request on a fresh socket; returns the reply's function byte (0x90 = an
// exception to FC16) or -1.
int RawRequest(int port, const std::vector<uint8_t>& pdu) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0) {
    ::close(fd);
    return -1;
  }
  std::vector<uint8_t> frame = {0x00, 0x01, 0x00, 0x00, static_cast<uint8_t>((pdu.size() + 1) >> 8),
                                static_cast<uint8_t>((pdu.size() + 1) & 0xFF), 0x01};
  frame.insert(frame.end(), pdu.begin(), pdu.end());
  (void)!::write(fd, frame.data(), frame.size());
  timeval timeout{2, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof(timeout));
  uint8_t reply[260];
  const ssize_t n = ::read(fd, reply, sizeof(reply));
  ::close(fd);
  return n >= 8 ? reply[7] : -1;
}

// Issue 18, item 8: a write the drive refuses with an exception changes nothing. Before, an
// FC16 of quantity 200 got exception 03 and then re-applied the mapping's words, so a drive
// its watchdog had stopped started again (its command word still said "run").
TEST(DriveSim, RefusedWriteChangesNothing) {
  const rig::DriveProfile profile = testing::LoadProfileOrDie("sim");
  DriveSimOptions options;
  options.model.accel_hz_per_s = 50.0;
  auto sim = DriveSim::Start(profile, options);
  ASSERT_TRUE(sim.ok());
  {
    rig::TransportOptions transport_options;
    transport_options.port = (*sim)->port();
    auto transport = rig::ModbusTransport::Open(transport_options);
    ASSERT_TRUE(transport.ok());
    ASSERT_TRUE((*transport)->WriteRegister(*profile.comm_watchdog->register_address, 3).ok());
    rig::DriveClient client(transport->get(), profile);
    ASSERT_TRUE(client.SetFrequencyHz(8.0).ok());
    ASSERT_TRUE(client.Start().ok());
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(600));  // silence: the watchdog stops it
  ASSERT_TRUE((*sim)->state().watchdog_fired);
  ASSERT_FALSE((*sim)->state().run_commanded);
  // FC16 at register 0, quantity 200 (> 123), byte count 144 (400 mod 256) and 144 data bytes.
  std::vector<uint8_t> pdu = {0x10, 0x00, 0x00, 0x00, 200, 144};
  pdu.resize(pdu.size() + 144, 0);
  EXPECT_EQ(RawRequest((*sim)->port(), pdu), 0x90);  // exception reply
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_FALSE((*sim)->state().run_commanded);
  EXPECT_EQ((*sim)->state().output_hz, 0.0);
}

// Issue 18, item 8: more idle connections than select() can watch (FD_SETSIZE 1024) no longer
// abort the server; the connection limit refuses the extra ones and a client still gets served.
TEST(DriveSim, ManyIdleConnectionsDoNotStopTheServer) {
  const rig::DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = DriveSim::Start(profile, DriveSimOptions());
  ASSERT_TRUE(sim.ok());
  rlimit limit{};
  ::getrlimit(RLIMIT_NOFILE, &limit);
  const int wanted = 1100;
  if (limit.rlim_cur < static_cast<rlim_t>(2 * wanted + 64)) {
    limit.rlim_cur = std::min<rlim_t>(limit.rlim_max, 2 * wanted + 64);
    ::setrlimit(RLIMIT_NOFILE, &limit);
  }
  std::vector<int> idle;
  for (int i = 0; i < wanted; ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0) break;
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(static_cast<uint16_t>((*sim)->port()));
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0) {
      ::close(fd);
      break;
    }
    idle.push_back(fd);
  }
  EXPECT_GE(idle.size(), 1000u) << "could not open enough sockets to test";
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  // FC03 read of 1 register at 2: a normal reply (function 0x03).
  EXPECT_EQ(RawRequest((*sim)->port(), {0x03, 0x00, 0x02, 0x00, 0x01}), -1)
      << "served past the connection limit";
  for (size_t i = 0; i < idle.size(); ++i) ::close(idle[i]);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(RawRequest((*sim)->port(), {0x03, 0x00, 0x02, 0x00, 0x01}), 0x03);
}

}  // namespace
}  // namespace facedyn::sim
