// End-to-end tests of `facedyn capture` and `facedyn session check` on the simulated stage.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/mount.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <thread>

#include "capture/frame_file.h"
#include "capture/session.h"
#include "core/take.h"
#include "tests/capture/cli_helpers.h"
#include "tests/support/test_support.h"

namespace facedyn::capture {
namespace {

TEST(CaptureCli, Sim3TakeIsCompleteWithGroundTruth) {
  testing::TempDir dir;
  const std::string session = dir.Join("session");
  std::string output;
  ASSERT_EQ(testing::RunCommand(Facedyn() + " -q capture --config " + Sim3Config(dir.path()) +
                                    " --session " + session + " --take t1 --json",
                                &output),
            0)
      << output;
  const json report = json::parse(output);
  EXPECT_EQ(report["status"], "complete");
  EXPECT_EQ(report["triggers_emitted"], 32);
  for (const auto& camera : report["cameras"]) {
    EXPECT_EQ(camera["frames_written"], 32);
    EXPECT_EQ(camera["sync"]["missing"], 0);
    EXPECT_EQ(camera["sync"]["max_timestamp_error_ns"], 0);
  }
  ASSERT_EQ(testing::RunCommand(Facedyn() + " session check " + session, &output), 0) << output;
  EXPECT_NE(output.find("take t1: complete"), std::string::npos) << output;
  // Frames carry their trigger and its time; ground truth sits beside them on the same clock.
  auto reader = FrameFileReader::Open(session + "/takes/t1/cam2/frames.fdr");
  ASSERT_TRUE(reader.ok());
  ASSERT_EQ((*reader)->frame_count(), 32);
  EXPECT_EQ((*reader)->scan().records[10].trigger_index, 10);
  EXPECT_EQ((*reader)->scan().records[10].timestamp_ns, 78125000);
  auto truth = LoadTake(session + "/takes/t1/ground_truth/take");
  ASSERT_TRUE(truth.ok()) << truth.status().message();
  EXPECT_GE(truth->frame_count(), 32);
  EXPECT_NEAR(truth->time_s[10], 10 / 128.0, 1e-9);
  EXPECT_TRUE(truth->channels.count("quasistatic"));
  EXPECT_TRUE(std::filesystem::exists(session + "/takes/t1/ground_truth/cameras.yaml"));
  EXPECT_TRUE(std::filesystem::exists(session + "/calibration.yaml"));
  // A second take with the same name is refused; the first stays intact.
  EXPECT_NE(testing::RunCommand(Facedyn() + " -q capture --config " + Sim3Config(dir.path()) +
                                    " --session " + session + " --take t1",
                                &output),
            0);
  EXPECT_NE(output.find("already exists"), std::string::npos) << output;
  ASSERT_EQ(testing::RunCommand(Facedyn() + " session check " + session, &output), 0) << output;
}

TEST(CaptureCli, InjectedFaultsMakeAnIncompleteTakeWithEvents) {
  testing::TempDir dir;
  const std::string session = dir.Join("session");
  const std::string config =
      Sim3Config(dir.path(), "  faults: {cam1: {drop: [3], duplicate: [5], late: [7]}}\n");
  std::string output;
  EXPECT_EQ(testing::RunCommand(Facedyn() + " -q capture --config " + config + " --session " +
                                    session + " --take f",
                                &output),
            1)
      << output;
  EXPECT_NE(output.find("incomplete"), std::string::npos) << output;
  const json manifest = ReadJson(session + "/takes/f/capture.json");
  EXPECT_EQ(manifest["status"], "aborted");
  EXPECT_EQ(manifest["cameras"][1]["sync"]["missing"], 1);
  EXPECT_EQ(manifest["cameras"][1]["sync"]["duplicated"], 1);
  EXPECT_EQ(manifest["cameras"][1]["sync"]["out_of_order"], 1);
  EXPECT_EQ(manifest["cameras"][1]["frames_written"], 31);
  EXPECT_EQ(manifest["cameras"][0]["frames_written"], 32);
  int anomalies = 0;
  std::ifstream events(session + "/events.jsonl");
  for (std::string line; std::getline(events, line);)
    anomalies += json::parse(line)["event"] == "frame_anomaly";
  EXPECT_EQ(anomalies, 4);  // gap before 4, the duplicate of 5, gap before 8, 7 out of order
  EXPECT_EQ(testing::RunCommand(Facedyn() + " session check " + session + " --json", &output), 1);
  const json check =
      json::parse(output.substr(output.find('{'), output.rfind('}') - output.find('{') + 1));
  EXPECT_FALSE(check["complete"].get<bool>());
  EXPECT_EQ(check["takes"][0]["cameras"][1]["missing"], 1);
}

TEST(CaptureCli, BadConfigNamesTheField) {
  testing::TempDir dir;
  const std::string config = Sim3Config(dir.path(), "", "colour: blue\n");
  std::string output;
  EXPECT_EQ(testing::RunCommand(Facedyn() + " capture --config " + config + " --session " +
                                    dir.Join("s") + " --take t",
                                &output),
            1);
  EXPECT_NE(output.find("colour"), std::string::npos) << output;
  EXPECT_FALSE(std::filesystem::exists(dir.Join("s")));
  EXPECT_EQ(testing::RunCommand(Facedyn() + " capture --config " + Sim3Config(dir.path()) +
                                    " --session " + dir.Join("s"),
                                &output),
            1);
  EXPECT_NE(output.find("exactly one of --take"), std::string::npos) << output;
}

// The disk fills up mid-take: the take stops cleanly, the manifest is valid, frames intact.
TEST(CaptureCli, TooSmallFilesystemStopsCleanly) {
  testing::TempDir dir;
  const std::string mount_point = dir.Join("small");
  std::filesystem::create_directories(mount_point);
  if (::mount("tmpfs", mount_point.c_str(), "tmpfs", 0, "size=48m") != 0) {
    if (testing::InCi()) FAIL() << "cannot mount a tmpfs (needs root) and CI=true";
    GTEST_SKIP() << "cannot mount a tmpfs (needs root)";
  }
  struct Unmount {
    std::string path;
    ~Unmount() { ::umount2(path.c_str(), MNT_DETACH); }
  } unmount{mount_point};
  const std::string session = mount_point + "/session";
  // Ground truth (~25 MB) fits; 3 x 128 frames of 640x512 (126 MB) do not.
  const std::string config = Sim3Config(dir.path(), "", "", 1.0, 640, 512);
  std::string output;
  EXPECT_EQ(testing::RunCommand(Facedyn() + " -q capture --config " + config + " --session " +
                                    session + " --take full",
                                &output),
            1)
      << output;
  EXPECT_NE(output.find("disk full"), std::string::npos) << output;
  const json manifest = ReadJson(session + "/takes/full/capture.json");
  EXPECT_EQ(manifest["status"], "aborted");
  EXPECT_NE(manifest["reason"].get<std::string>().find("no space"), std::string::npos);
  int64_t written = 0;
  for (int k = 0; k < 3; ++k) {
    auto reader =
        FrameFileReader::Open(session + "/takes/full/cam" + std::to_string(k) + "/frames.fdr");
    ASSERT_TRUE(reader.ok());
    EXPECT_TRUE((*reader)->scan().tail_problem.empty()) << (*reader)->scan().tail_problem;
    EXPECT_EQ((*reader)->frame_count(), manifest["cameras"][k]["frames_written"].get<int64_t>());
    written += (*reader)->frame_count();
  }
  EXPECT_GT(written, 0);
  EXPECT_EQ(testing::RunCommand(Facedyn() + " session check " + session, &output), 1);
  EXPECT_NE(output.find("take full: incomplete"), std::string::npos) << output;
  EXPECT_EQ(output.find("torn"), std::string::npos) << output;
}

TEST(CaptureCli, KillNineMidTakeLeavesACheckableSession) {
  testing::TempDir dir;
  const std::string session = dir.Join("session");
  const std::string config = Sim3Config(dir.path(), "", "", 2.0, 640, 512);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::execl(Facedyn().c_str(), "facedyn", "-q", "capture", "--config", config.c_str(), "--session",
            session.c_str(), "--take", "killed", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const std::string frames = session + "/takes/killed/cam2/frames.fdr";
  bool started = false;
  for (int i = 0; i < 3000 && !started; ++i) {
    std::error_code ec;
    started = std::filesystem::exists(frames, ec) &&
              std::filesystem::file_size(frames, ec) > 3 * 640 * 512;
    if (!started) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(started) << "the take never started writing frames";
  ASSERT_TRUE(WIFSIGNALED(status));
  std::string output;
  EXPECT_EQ(testing::RunCommand(Facedyn() + " session check " + session, &output), 1);
  EXPECT_NE(output.find("take killed: incomplete (status recording)"), std::string::npos) << output;
  EXPECT_NE(output.find("never stopped"), std::string::npos) << output;
  auto check = CheckSession(session);
  ASSERT_TRUE(check.ok()) << check.status().message();
  EXPECT_GE(check->takes[0].cameras[2].frames, 3);
}

}  // namespace
}  // namespace facedyn::capture
