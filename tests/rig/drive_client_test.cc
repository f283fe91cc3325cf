// DriveClient and ModbusTransport against two peers: pymodbus (independent implementation) as
// a server for every real profile, and facedyn's simulated drive for fault injection.
#include "rig/drive_client.h"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "rig/modbus_transport.h"
#include "sim/drive_sim.h"
#include "tests/rig/rig_test_util.h"

namespace facedyn::rig {
namespace {

using ::testing::HasSubstr;

TransportOptions LocalTcp(int port) {
  TransportOptions options;
  options.host = "127.0.0.1";
  options.port = port;
  options.response_timeout_s = 0.2;
  options.retries = 2;
  return options;
}

std::unique_ptr<sim::DriveSim> StartSim(const DriveProfile& profile, double watchdog_s = 0.0) {
  sim::DriveSimOptions options;
  options.model.accel_hz_per_s = 20.0;
  options.model.watchdog_s = watchdog_s;
  options.model.watchdog_fault_code = 10;
  auto sim = sim::DriveSim::Start(profile, options);
  EXPECT_TRUE(sim.ok()) << sim.status().ToString();
  return sim.ok() ? std::move(sim).value() : nullptr;
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

TEST(DriveLimits, CheckNamesField) {
  DriveLimits limits;
  EXPECT_TRUE(limits.Check().ok());
  limits.window_max_hz = 5.0;
  EXPECT_THAT(limits.Check().message(), HasSubstr("window_max_hz"));
}

TEST(TransportOptions, CheckNamesField) {
  TransportOptions options;
  options.retries = -1;
  EXPECT_THAT(options.Check().message(), HasSubstr("retries"));
  options = TransportOptions();
  options.kind = TransportOptions::Kind::kRtu;
  EXPECT_THAT(options.Check().message(), HasSubstr("device"));
  EXPECT_FALSE(ParseTcpEndpoint("localhost", &options).ok());
  ASSERT_TRUE(ParseTcpEndpoint("127.0.0.1:5020", &options).ok());
  EXPECT_EQ(options.port, 5020);
}

TEST(DriveClient, RefusesSetpointsOutsideWindowAndAboveMaximum) {
  const DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = StartSim(profile);
  ASSERT_NE(sim, nullptr);
  auto transport = ModbusTransport::Open(LocalTcp(sim->port()));
  ASSERT_TRUE(transport.ok()) << transport.status().ToString();
  DriveLimits limits;
  limits.absolute_max_hz = 10.0;
  DriveClient client(transport->get(), profile, limits);
  Status low = client.SetFrequencyHz(5.5);
  ASSERT_FALSE(low.ok());
  EXPECT_EQ(low.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(low.message(), HasSubstr("hz: 5.5 Hz is outside the allowed window 6..11"));
  Status high = client.SetFrequencyHz(10.5);
  ASSERT_FALSE(high.ok());
  EXPECT_THAT(high.message(), HasSubstr("above the configured maximum 10"));
  EXPECT_EQ(sim->requests_served(), 0);  // nothing reached the drive
  EXPECT_TRUE(client.SetFrequencyHz(9.0).ok());
  EXPECT_TRUE(client.Stop().ok());  // stop is never refused
}

// Our client, pymodbus server: the registers and scalings of each real profile.
TEST(DriveClient, WritesEachRealProfileToPymodbusServer) {
  FACEDYN_REQUIRE_PYMODBUS();
  struct Case {
    const char* name;
    int setpoint_counts;  // 7.5 Hz
  };
  for (const Case& c :
       {Case{"delta_ms300", 750}, Case{"invertek_e3", 75}, Case{"siemens_v20", 2458}}) {
    SCOPED_TRACE(c.name);
    const DriveProfile profile = testing::LoadProfileOrDie(c.name);
    testing::TempDir dir;
    testing::PymodbusServer server(dir, profile.MaxRegister() + 1);
    ASSERT_NE(server.port(), 0) << "pymodbus server did not start";
    auto transport = ModbusTransport::Open(LocalTcp(server.port()));
    ASSERT_TRUE(transport.ok()) << transport.status().ToString();
    DriveClient client(transport->get(), profile);
    ASSERT_TRUE(client.SetFrequencyHz(7.5).ok());
    ASSERT_TRUE(client.Start().ok());
    ASSERT_TRUE(client.Stop().ok());
    ASSERT_TRUE(client.ResetFault().ok());

    std::vector<std::string> expected = {
        fmt::format("{} {}", profile.setpoint_register, c.setpoint_counts),
        fmt::format("{} {}", profile.command_register, profile.run_value),
        fmt::format("{} {}", profile.command_register, profile.stop_value)};
    for (const uint16_t value : profile.fault_reset_values) {
      expected.push_back(fmt::format("{} {}", profile.fault_reset_register, value));
    }
    EXPECT_EQ(Lines(server.Writes()), expected);
  }
}

// Our client decodes status words the pymodbus server holds (set as the manuals describe).
TEST(DriveClient, ReadsStatusOfEachRealProfileFromPymodbusServer) {
  FACEDYN_REQUIRE_PYMODBUS();
  struct Case {
    const char* name;
    std::vector<std::string> presets;
    bool running;
    int fault_code;
    double output_hz;
  };
  const std::vector<Case> cases = {
      {"delta_ms300", {"0x2101=3", "0x2103=812"}, true, 0, 8.12},
      {"delta_ms300", {"0x2101=0", "0x2100=21"}, false, 21, 0.0},
      {"invertek_e3", {"6=0x0001", "7=95"}, true, 0, 9.5},
      {"invertek_e3", {"6=0x0D02"}, false, 13, 0.0},
      {"siemens_v20", {"109=0x0004", "110=2458"}, true, 0, 2458 * 50.0 / 16384},
      {"siemens_v20", {"109=0x0008", "399=2"}, false, 2, 0.0},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const DriveProfile profile = testing::LoadProfileOrDie(c.name);
    testing::TempDir dir;
    testing::PymodbusServer server(dir, profile.MaxRegister() + 1, c.presets);
    ASSERT_NE(server.port(), 0);
    auto transport = ModbusTransport::Open(LocalTcp(server.port()));
    ASSERT_TRUE(transport.ok()) << transport.status().ToString();
    DriveClient client(transport->get(), profile);
    auto status = client.ReadStatus();
    ASSERT_TRUE(status.ok()) << status.status().ToString();
    EXPECT_EQ(status->running, c.running);
    EXPECT_EQ(status->fault_code, c.fault_code);
    EXPECT_EQ(status->faulted, c.fault_code != 0);
    EXPECT_NEAR(status->output_hz, c.output_hz, 1e-9);
    EXPECT_TRUE(server.Writes().empty());  // a status read writes nothing
  }
}

TEST(ModbusTransport, RetriesDroppedRepliesAndCountsThem) {
  const DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = StartSim(profile);
  ASSERT_NE(sim, nullptr);
  TransportOptions options = LocalTcp(sim->port());
  options.retries = 3;
  options.response_timeout_s = 0.1;
  auto transport = ModbusTransport::Open(options);
  ASSERT_TRUE(transport.ok());
  sim->DropNextRequests(2);
  ASSERT_TRUE((*transport)->WriteRegister(profile.setpoint_register, 800).ok());
  EXPECT_EQ((*transport)->stats().retries, 2);
  EXPECT_EQ((*transport)->stats().failures, 0);
  EXPECT_EQ(sim->requests_dropped(), 2);
  EXPECT_NEAR(sim->state().setpoint_hz, 8.0, 1e-9);
}

TEST(ModbusTransport, GivesUpAfterRetriesNamingTheRegister) {
  const DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = StartSim(profile);
  ASSERT_NE(sim, nullptr);
  TransportOptions options = LocalTcp(sim->port());
  options.retries = 1;
  options.response_timeout_s = 0.1;
  auto transport = ModbusTransport::Open(options);
  ASSERT_TRUE(transport.ok());
  sim->DropNextRequests(5);
  auto read = (*transport)->ReadRegisters(profile.status_register, 1);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kUnavailable);
  EXPECT_THAT(read.status().message(), HasSubstr("register(s) from 2"));
  EXPECT_THAT(read.status().message(), HasSubstr("failed after 2 attempt(s)"));
  EXPECT_THAT(read.status().message(), HasSubstr("timed out"));
  EXPECT_EQ((*transport)->stats().failures, 1);
}

TEST(ModbusTransport, HealthyOnlyAfterConsecutiveGoodTransactions) {
  const DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = StartSim(profile);
  ASSERT_NE(sim, nullptr);
  TransportOptions options = LocalTcp(sim->port());
  options.healthy_after = 3;
  options.retries = 0;
  options.response_timeout_s = 0.1;
  auto transport = ModbusTransport::Open(options);
  ASSERT_TRUE(transport.ok());
  for (int i = 0; i < 2; ++i) ASSERT_TRUE((*transport)->ReadRegisters(0, 4).ok());
  EXPECT_FALSE((*transport)->healthy());
  ASSERT_TRUE((*transport)->ReadRegisters(0, 4).ok());
  EXPECT_TRUE((*transport)->healthy());
  sim->DropNextRequests(1);
  EXPECT_FALSE((*transport)->ReadRegisters(0, 4).ok());
  EXPECT_FALSE((*transport)->healthy());
}

TEST(ModbusTransport, LinkCutIsAnErrorAndReconnectRecovers) {
  const DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = StartSim(profile);
  ASSERT_NE(sim, nullptr);
  const int port = sim->port();
  auto transport = ModbusTransport::Open(LocalTcp(port));
  ASSERT_TRUE(transport.ok());
  DriveClient client(transport->get(), profile);
  ASSERT_TRUE(client.ReadStatus().ok());
  sim.reset();  // the drive goes away mid-session
  auto status = client.ReadStatus();
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.status().code(), StatusCode::kUnavailable);
  EXPECT_THAT(status.status().message(), HasSubstr("drive sim status"));
  EXPECT_GE((*transport)->stats().reconnects, 1);
  EXPECT_FALSE((*transport)->healthy());
}

TEST(ModbusTransport, NothingListeningIsUnavailable) {
  const DriveProfile profile = testing::LoadProfileOrDie("sim");
  int port = 0;
  {
    auto sim = StartSim(profile);  // borrow a free port, then free it
    ASSERT_NE(sim, nullptr);
    port = sim->port();
  }
  auto transport = ModbusTransport::Open(LocalTcp(port));
  ASSERT_FALSE(transport.ok());
  EXPECT_EQ(transport.status().code(), StatusCode::kUnavailable);
  EXPECT_THAT(transport.status().message(), HasSubstr(fmt::format("127.0.0.1:{}", port)));
}

TEST(DriveClient, FaultResetIsExplicit) {
  const DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = StartSim(profile);
  ASSERT_NE(sim, nullptr);
  auto transport = ModbusTransport::Open(LocalTcp(sim->port()));
  ASSERT_TRUE(transport.ok());
  DriveClient client(transport->get(), profile);
  sim->ForceFault(2);
  auto status = client.ReadStatus();
  ASSERT_TRUE(status.ok());
  EXPECT_TRUE(status->faulted);
  EXPECT_THAT(status->fault_text, HasSubstr("over-current"));
  // Start does not clear a trip.
  ASSERT_TRUE(client.Start().ok());
  EXPECT_TRUE(client.ReadStatus()->faulted);
  ASSERT_TRUE(client.ResetFault().ok());
  status = client.ReadStatus();
  ASSERT_TRUE(status.ok());
  EXPECT_FALSE(status->faulted);
  EXPECT_FALSE(status->running);
}

}  // namespace
}  // namespace facedyn::rig
