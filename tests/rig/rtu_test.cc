// Modbus RTU end to end: facedyn's transport and the simulated drive on the two ends of a
// pseudo-terminal pair made by socat, with the fault injection a serial line sees (CRC garbage,
// late replies, exception replies, a trip, a cut cable), and pymodbus as an independent RTU
// client of the simulated drive.
#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "rig/drive_client.h"
#include "rig/modbus_transport.h"
#include "rig/rig_config.h"
#include "rig/supervisor.h"
#include "sim/drive_sim.h"
#include "tests/rig/rig_test_util.h"

namespace facedyn {
namespace {

using ::testing::HasSubstr;
using Clock = std::chrono::steady_clock;

bool SocatAvailable() {
  std::string output;
  return testing::RunCommand("command -v socat", &output) == 0;
}

#define FACEDYN_REQUIRE_SOCAT()                                             \
  if (!SocatAvailable()) {                                                  \
    if (testing::InCi()) FAIL() << "socat is missing and CI=true";          \
    GTEST_SKIP() << "socat not installed (needed for RTU over a pty pair)"; \
  }

// `socat pty,link=drive pty,link=host`: a null-modem cable between two pseudo-terminals.
class PtyPair {
 public:
  explicit PtyPair(const testing::TempDir& dir)
      : drive_(dir.Join("drive")), host_(dir.Join("host")) {
    pid_ = ::fork();
    if (pid_ == 0) {
      const std::string a = "pty,raw,echo=0,link=" + drive_;
      const std::string b = "pty,raw,echo=0,link=" + host_;
      ::execlp("socat", "socat", a.c_str(), b.c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
    const auto deadline = Clock::now() + std::chrono::seconds(5);
    struct stat info {};
    while (Clock::now() < deadline) {
      if (::stat(drive_.c_str(), &info) == 0 && ::stat(host_.c_str(), &info) == 0) {
        ready_ = true;
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  ~PtyPair() {
    if (pid_ > 0) {
      ::kill(pid_, SIGTERM);
      int status = 0;
      ::waitpid(pid_, &status, 0);
    }
  }
  bool ready() const { return ready_; }
  const std::string& drive() const { return drive_; }
  const std::string& host() const { return host_; }

 private:
  std::string drive_, host_;
  pid_t pid_ = -1;
  bool ready_ = false;
};

std::unique_ptr<sim::DriveSim> StartRtuSim(const rig::DriveProfile& profile,
                                           const std::string& device,
                                           int watchdog_fault_code = 10) {
  sim::DriveSimOptions options;
  options.rtu_device = device;
  options.baud = 19200;
  options.model.accel_hz_per_s = 10.0;
  options.model.watchdog_fault_code = watchdog_fault_code;
  auto sim = sim::DriveSim::Start(profile, options);
  EXPECT_TRUE(sim.ok()) << sim.status().ToString();
  return sim.ok() ? std::move(sim).value() : nullptr;
}

rig::TransportOptions RtuOptions(const std::string& device) {
  rig::TransportOptions options;
  options.kind = rig::TransportOptions::Kind::kRtu;
  options.device = device;
  options.baud = 19200;
  options.response_timeout_s = 0.2;
  options.retries = 2;
  options.rtu_gap_s = 0.004;
  return options;
}

TEST(Rtu, DriveClientRunsTheSimulatedDriveOverAPtyPair) {
  FACEDYN_REQUIRE_SOCAT();
  testing::TempDir dir;
  PtyPair pty(dir);
  ASSERT_TRUE(pty.ready());
  const rig::DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = StartRtuSim(profile, pty.drive());
  ASSERT_NE(sim, nullptr);
  auto transport = rig::ModbusTransport::Open(RtuOptions(pty.host()));
  ASSERT_TRUE(transport.ok()) << transport.status().ToString();
  rig::DriveClient client(transport->get(), profile);
  ASSERT_TRUE(client.SetFrequencyHz(9.0).ok());
  ASSERT_TRUE(client.Start().ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  auto status = client.ReadStatus();
  ASSERT_TRUE(status.ok()) << status.status().ToString();
  EXPECT_TRUE(status->running);
  EXPECT_NEAR(status->output_hz, 9.0, 1e-9);
  ASSERT_TRUE(client.Stop().ok());
  EXPECT_EQ((*transport)->stats().retries, 0);
  EXPECT_GE(sim->requests_served(), 5);
}

TEST(Rtu, CrcGarbageIsRetriedAndCounted) {
  FACEDYN_REQUIRE_SOCAT();
  testing::TempDir dir;
  PtyPair pty(dir);
  ASSERT_TRUE(pty.ready());
  const rig::DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = StartRtuSim(profile, pty.drive());
  ASSERT_NE(sim, nullptr);
  auto transport = rig::ModbusTransport::Open(RtuOptions(pty.host()));
  ASSERT_TRUE(transport.ok());
  sim->GarbleNextReplies(2);
  auto words = (*transport)->ReadRegisters(profile.status_register, 1);
  ASSERT_TRUE(words.ok()) << words.status().ToString();
  EXPECT_EQ(sim->replies_garbled(), 2);
  EXPECT_EQ((*transport)->stats().retries, 2);
  EXPECT_EQ((*transport)->stats().failures, 0);
  // Garbage on every attempt is a failure naming the register and the last error.
  sim->GarbleNextReplies(3);
  auto failed = (*transport)->ReadRegisters(profile.output_frequency_register, 1);
  ASSERT_FALSE(failed.ok());
  EXPECT_THAT(failed.status().message(), HasSubstr("register(s) from 3"));
  EXPECT_THAT(failed.status().message(), HasSubstr("failed after 3 attempt(s)"));
  // The line recovers once the noise stops.
  EXPECT_TRUE((*transport)->ReadRegisters(profile.status_register, 1).ok());
}

TEST(Rtu, LateRepliesTimeOutWithoutConfusingTheNextRequest) {
  FACEDYN_REQUIRE_SOCAT();
  testing::TempDir dir;
  PtyPair pty(dir);
  ASSERT_TRUE(pty.ready());
  const rig::DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = StartRtuSim(profile, pty.drive());
  ASSERT_NE(sim, nullptr);
  rig::TransportOptions options = RtuOptions(pty.host());
  options.retries = 1;
  auto transport = rig::ModbusTransport::Open(options);
  ASSERT_TRUE(transport.ok());
  ASSERT_TRUE((*transport)->WriteRegister(profile.setpoint_register, 750).ok());
  // Longer than both attempts' response timeouts together (2 x 0.2 s plus the gap): every
  // reply comes too late.
  sim->SetReplyDelayS(0.5);
  auto late = (*transport)->ReadRegisters(profile.setpoint_register, 1);
  ASSERT_FALSE(late.ok());
  EXPECT_THAT(late.status().message(), HasSubstr("timed out"));
  sim->SetReplyDelayS(0.0);
  std::this_thread::sleep_for(std::chrono::milliseconds(1200));  // both late replies land, stale
  // The next transactions must not take a stale reply for their own (nor need a retry for it).
  const long retries_before = (*transport)->stats().retries;
  ASSERT_TRUE((*transport)->WriteRegister(profile.setpoint_register, 812).ok());
  auto fresh = (*transport)->ReadRegisters(profile.setpoint_register, 1);
  ASSERT_TRUE(fresh.ok()) << fresh.status().ToString();
  EXPECT_EQ((*fresh)[0], 812);
  EXPECT_EQ((*transport)->stats().retries, retries_before);
}

TEST(Rtu, ExceptionReplyIsTheDrivesAnswerAndNamed) {
  FACEDYN_REQUIRE_SOCAT();
  testing::TempDir dir;
  PtyPair pty(dir);
  ASSERT_TRUE(pty.ready());
  const rig::DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = StartRtuSim(profile, pty.drive());
  ASSERT_NE(sim, nullptr);
  auto transport = rig::ModbusTransport::Open(RtuOptions(pty.host()));
  ASSERT_TRUE(transport.ok());
  sim->ExceptionNextReplies(1, MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE);
  const Status refused = (*transport)->WriteRegister(profile.setpoint_register, 800);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(refused.message(), HasSubstr("the drive refused"));
  EXPECT_THAT(refused.message(), HasSubstr("Illegal data value"));
  EXPECT_EQ((*transport)->stats().retries, 0);  // an answer is not retried
  EXPECT_TRUE((*transport)->WriteRegister(profile.setpoint_register, 800).ok());
}

// The supervisor over RTU, from sim-rtu.yaml: settles within tolerance, then the cable is cut
// during the hold and the drive stops on its own watchdog.
TEST(Rtu, SupervisorHoldsFrequencyAndLinkCutTripsTheDriveWatchdog) {
  FACEDYN_REQUIRE_SOCAT();
  testing::TempDir dir;
  PtyPair pty(dir);
  ASSERT_TRUE(pty.ready());
  auto rig = rig::LoadRigConfig(testing::RigConfigPath("sim-rtu"));
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  rig->transport.device = pty.host();
  auto sim = StartRtuSim(rig->profile, pty.drive());
  ASSERT_NE(sim, nullptr);
  auto supervisor = rig::RigSupervisor::Connect(*rig, nullptr, nullptr);
  ASSERT_TRUE(supervisor.ok()) << supervisor.status().ToString();
  ASSERT_TRUE((*supervisor)->Arm().ok());
  ASSERT_TRUE((*supervisor)->SetTargetHz(9.5).ok());
  const Status settled = (*supervisor)->WaitSettled(15.0);
  ASSERT_TRUE(settled.ok()) << settled.ToString();
  EXPECT_NEAR(sim->state().platform_hz, 9.5, 0.05);
  StatusOr<rig::HoldSummary> hold = InternalError("not run");
  std::thread holder([&] { hold = (*supervisor)->Hold(10.0); });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  sim->CutLink(true);
  const auto cut = Clock::now();
  while (!sim->state().watchdog_fired && Clock::now() - cut < std::chrono::seconds(3)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const double fired_after_s = std::chrono::duration<double>(Clock::now() - cut).count();
  holder.join();
  ASSERT_FALSE(hold.ok());
  EXPECT_THAT(hold.status().message(), HasSubstr("link to the drive lost"));
  EXPECT_TRUE(sim->state().watchdog_fired);
  EXPECT_LE(fired_after_s, rig->safety.comm_watchdog_s + 0.05);
  EXPECT_EQ(sim->state().fault_code, 10);
  EXPECT_EQ(sim->state().output_hz, 0.0);
}

// pymodbus as an independent RTU client of the simulated drive.
TEST(Rtu, PymodbusSerialClientDrivesTheSimulatedDrive) {
  FACEDYN_REQUIRE_SOCAT();
  FACEDYN_REQUIRE_PYMODBUS();
  testing::TempDir dir;
  PtyPair pty(dir);
  ASSERT_TRUE(pty.ready());
  const rig::DriveProfile profile = testing::LoadProfileOrDie("sim");
  auto sim = StartRtuSim(profile, pty.drive());
  ASSERT_NE(sim, nullptr);
  const std::string command = fmt::format(
      "/usr/bin/python3 {} --rtu {} --port 0 --setpoint-register {} --counts-per-hz {} --hz 7 "
      "--command-register {} --run-value {} --output-register {} --status-register {} --seconds "
      "1.0",
      testing::RigTestScript("pymodbus_client.py"), pty.host(), profile.setpoint_register,
      profile.setpoint_scaling.CountsPerHz(), profile.command_register, profile.run_value,
      profile.output_frequency_register, profile.status_register);
  std::string output;
  ASSERT_EQ(testing::RunCommand(command, &output), 0) << output;
  const auto json = nlohmann::json::parse(output.substr(output.find('{')));
  const auto samples = json["samples_hz"].get<std::vector<double>>();
  ASSERT_GE(samples.size(), 4u);
  for (size_t i = 1; i < samples.size(); ++i) EXPECT_GE(samples[i], samples[i - 1]);
  EXPECT_NEAR(samples.back(), 7.0, 0.01);
  EXPECT_TRUE(profile.IsRunning(static_cast<uint16_t>(json["status"].get<int>())));
}

}  // namespace
}  // namespace facedyn
