// `facedyn capture` with the simulated platform: set, settle, record with telemetry, stop; and
// the capture step of a sweep.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "tests/capture/cli_helpers.h"
#include "tests/support/test_support.h"

namespace facedyn::capture {
namespace {

// Set the simulated platform over Modbus, settle, record with telemetry, stop.
TEST(CaptureCli, SimulatedPlatformSettlesAndTelemetryIsRecorded) {
  testing::TempDir dir;
  const std::string session = dir.Join("session");
  const std::string platform = "platform: {rig: " + kSource +
                               "/config/rigs/sim-tcp.yaml, start_simulated_drive: true, hz: 9, "
                               "settle_timeout_s: 30, telemetry_period_s: 0.02}\n";
  std::string output;
  ASSERT_EQ(testing::RunCommand(Facedyn() + " -q capture --config " +
                                    Sim3Config(dir.path(), "", platform, 0.5) + " --session " +
                                    session + " --take p9 --json",
                                &output),
            0)
      << output;
  const json report = json::parse(output);
  EXPECT_EQ(report["status"], "complete");
  EXPECT_NEAR(report["platform"]["measured_hz_at_start"].get<double>(), 9.0, 0.06);
  EXPECT_NEAR(report["platform_hz_true"].get<double>(), 9.0, 0.06);
  std::ifstream telemetry(session + "/takes/p9/telemetry.csv");
  std::string header, line;
  std::getline(telemetry, header);
  EXPECT_EQ(header, "t_ns,state,running,faulted,output_hz,measured_hz,target_hz");
  int rows = 0;
  int64_t last_t = -1;
  while (std::getline(telemetry, line)) {
    const int64_t t = std::stoll(line.substr(0, line.find(',')));
    EXPECT_GE(t, last_t);
    EXPECT_LT(t, 500000000);  // on the take's clock
    last_t = t;
    ++rows;
  }
  EXPECT_GE(rows, 1);
  EXPECT_TRUE(std::filesystem::exists(session + "/rig_log.jsonl"));
}

// The capture step of a sweep: one complete take per step, frame counts = fps x duration.
TEST(CaptureCli, SweepRecordsOneCompleteTakePerStep) {
  testing::TempDir dir;
  const std::string session = dir.Join("session");
  const std::string platform = "platform: {rig: " + kSource +
                               "/config/rigs/sim-tcp.yaml, start_simulated_drive: true, hz: 8}\n";
  // Two steps (config/sweeps/demo.yaml has three; two keep the test short).
  std::ofstream(dir.Join("sweep.yaml"))
      << "name: two-step\nrig: " << kSource << "/config/rigs/sim-tcp.yaml\n"
      << "defaults: {settle_timeout_s: 20, settle_s: 0, hold_s: 0.2}\n"
      << "steps:\n  - {hz: 7, prompt: neutral}\n  - {hz: 9.5, prompt: smile}\n";
  std::string output;
  ASSERT_EQ(testing::RunCommand(Facedyn() + " -q capture --config " +
                                    Sim3Config(dir.path(), "", platform, 0.25) + " --session " +
                                    session + " --sweep " + dir.Join("sweep.yaml") + " --json",
                                &output),
            0)
      << output;
  const json report = json::parse(output.substr(output.find('{')));
  ASSERT_EQ(report["takes"].size(), 2u);
  for (const auto& take : report["takes"]) {
    EXPECT_EQ(take["status"], "complete");
    for (const auto& camera : take["cameras"]) {
      EXPECT_EQ(camera["frames_written"], 32);
      EXPECT_EQ(camera["sync"]["max_timestamp_error_ns"], 0);
    }
  }
  EXPECT_NEAR(report["takes"][0]["platform_hz_true"].get<double>(), 7.0, 0.06);
  EXPECT_NEAR(report["takes"][1]["platform_hz_true"].get<double>(), 9.5, 0.06);
  EXPECT_EQ(report["takes"][1]["sweep"]["prompt"], "smile");
  EXPECT_EQ(report["takes"][1]["name"], "step02_9.50hz_smile");
  ASSERT_EQ(testing::RunCommand(Facedyn() + " session check " + session, &output), 0) << output;
}

}  // namespace
}  // namespace facedyn::capture
