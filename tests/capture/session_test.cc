#include "capture/session.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <thread>

#include "capture/frame_file.h"
#include "capture/recorder.h"
#include "core/file_util.h"
#include "tests/support/test_support.h"

namespace facedyn::capture {
namespace {

std::vector<SessionCameraInfo> Cameras(int count) {
  std::vector<SessionCameraInfo> cameras;
  for (int k = 0; k < count; ++k)
    cameras.push_back({"cam" + std::to_string(k), "sim", 32, 16, "mono8"});
  return cameras;
}

Frame MakeFrame(int camera, int64_t trigger) {
  Frame frame;
  frame.camera_index = camera;
  frame.trigger_index = trigger;
  frame.width_px = 32;
  frame.height_px = 16;
  frame.pixels.assign(frame.ExpectedBytes(), 9);
  return frame;
}

// Records `frames` triggers on every camera into a new take and ends it.
void RecordTake(SessionWriter* session, const std::string& name, int cameras, int frames,
                int skip_trigger = -1, const Json& extra = Json::object()) {
  auto take_dir = session->BeginTake(name, 128.0, frames);
  ASSERT_TRUE(take_dir.ok()) << take_dir.status().message();
  std::vector<std::string> paths;
  for (int k = 0; k < cameras; ++k)
    paths.push_back(*take_dir + "/cam" + std::to_string(k) + "/" + kFrameFileName);
  auto recorder = Recorder::Start(RecorderOptions(), paths);
  ASSERT_TRUE(recorder.ok());
  TakeResult result;
  result.status = "complete";
  result.fps = 128.0;
  result.triggers_requested = frames;
  result.triggers_emitted = frames;
  result.extra = extra;
  for (int k = 0; k < cameras; ++k) {
    FrameSyncChecker checker(0);
    for (int t = 0; t < frames; ++t) {
      if (k == 0 && t == skip_trigger) continue;
      (void)checker.Observe(t, 0, 0, frames);
      ASSERT_EQ((*recorder)->Push(k, MakeFrame(k, t)), PushResult::kQueued);
    }
    checker.Finish(frames);
    result.cameras.push_back(
        {"cam" + std::to_string(k), "cam" + std::to_string(k), checker.counts(), {}});
  }
  ASSERT_TRUE((*recorder)->Finish().ok());
  const auto stats = (*recorder)->stats();
  for (int k = 0; k < cameras; ++k) result.cameras[k].record = stats[k];
  if (skip_trigger >= 0) {
    result.status = "aborted";
    result.reason = "cam0 missed a trigger";
  }
  ASSERT_TRUE(session->EndTake(name, result).ok());
}

TEST(Session, CompleteTakeChecksComplete) {
  testing::TempDir dir;
  auto session = SessionWriter::Open(dir.path(), "virtual", Cameras(2), Json{{"config", "test"}});
  ASSERT_TRUE(session.ok()) << session.status().message();
  RecordTake(session->get(), "t1", 2, 20);
  auto check = CheckSession(dir.path());
  ASSERT_TRUE(check.ok()) << check.status().message();
  EXPECT_TRUE(check->Complete()) << check->ToText();
  ASSERT_EQ(check->takes.size(), 1u);
  EXPECT_EQ(check->takes[0].cameras[1].frames, 20);
  EXPECT_EQ(check->events, 3);  // session_open, take_start, take_stop
  EXPECT_FALSE(std::filesystem::exists(dir.path() + "/takes/t1/.reserve"));

  auto info = ReadSession(dir.path());
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->takes[0].status, "complete");
  EXPECT_EQ(info->takes[0].cameras[0].frames_in_manifest, 20);
  EXPECT_EQ(info->cameras.size(), 2u);
}

TEST(Session, ReopenAppendsAndRefusesExistingTake) {
  testing::TempDir dir;
  {
    auto session = SessionWriter::Open(dir.path(), "virtual", Cameras(1), Json::object());
    ASSERT_TRUE(session.ok());
    RecordTake(session->get(), "a", 1, 5);
  }
  auto session = SessionWriter::Open(dir.path(), "virtual", Cameras(1), Json::object());
  ASSERT_TRUE(session.ok()) << session.status().message();
  auto again = (*session)->BeginTake("a", 128, 5);
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.status().message().find("already exists"), std::string::npos);
  EXPECT_FALSE((*session)->BeginTake("../x", 128, 5).ok());
  RecordTake(session->get(), "b", 1, 5);
  auto check = CheckSession(dir.path());
  ASSERT_TRUE(check.ok());
  EXPECT_EQ(check->takes.size(), 2u);
  EXPECT_TRUE(check->Complete()) << check->ToText();
  // Two writers on one session: refused.
  auto second = SessionWriter::Open(dir.path(), "virtual", Cameras(1), Json::object());
  ASSERT_FALSE(second.ok());
  EXPECT_NE(second.status().message().find("another facedyn process"), std::string::npos);
  session->reset();
  auto other = SessionWriter::Open(dir.path(), "virtual", Cameras(3), Json::object());
  ASSERT_FALSE(other.ok());
  EXPECT_NE(other.status().message().find("cameras"), std::string::npos);
}

TEST(Session, MissingFrameAndTornEventLineAreReported) {
  testing::TempDir dir;
  auto session = SessionWriter::Open(dir.path(), "virtual", Cameras(2), Json::object());
  ASSERT_TRUE(session.ok());
  RecordTake(session->get(), "gap", 2, 10, /*skip_trigger=*/4);
  {
    std::FILE* f = std::fopen((dir.path() + "/events.jsonl").c_str(), "a");
    std::fputs("{\"event\":\"take_st", f);
    std::fclose(f);
  }
  auto check = CheckSession(dir.path());
  ASSERT_TRUE(check.ok());
  EXPECT_FALSE(check->Complete());
  EXPECT_NE(check->events_problem.find("torn"), std::string::npos);
  EXPECT_FALSE(check->takes[0].complete);
  EXPECT_EQ(check->takes[0].cameras[0].missing, 1);
  EXPECT_EQ(check->takes[0].cameras[1].missing, 0);
  const std::string text = check->ToText();
  EXPECT_NE(text.find("1 of 10 triggers have no frame"), std::string::npos) << text;
}

// A capture.json whose frame_file points outside the take folder once had `session check` (and
// reconstruct) open whatever it named: "../../elsewhere/frames.fdr" or an absolute path. Each
// such entry is refused, named with its file and index, and the other cameras are still read.
TEST(Session, FramePathsOutsideTheTakeAreRefused) {
  for (const std::string hostile :
       {"../../outside/frames.fdr", "cam0/../../../outside/frames.fdr", "/OUTSIDE/frames.fdr"}) {
    testing::TempDir dir;
    auto session = SessionWriter::Open(dir.path(), "virtual", Cameras(2), Json::object());
    ASSERT_TRUE(session.ok());
    RecordTake(session->get(), "t", 2, 6);
    // A complete frame file outside the session that the manifest points at: before the fix
    // the check read it and called the take complete.
    const std::string outside = dir.Join("outside");
    std::filesystem::create_directories(outside);
    std::filesystem::copy_file(dir.path() + "/takes/t/cam1/frames.fdr", outside + "/frames.fdr");
    std::string target = hostile;
    if (target[0] == '/') target = outside + "/frames.fdr";
    const std::string manifest_path = dir.path() + "/takes/t/capture.json";
    Json manifest = Json::parse(testing::ReadBytes(manifest_path));
    manifest["cameras"][1]["frame_file"] = target;
    testing::WriteBytes(manifest_path, manifest.dump(2));

    auto info = ReadSession(dir.path());
    ASSERT_TRUE(info.ok()) << info.status().message();
    const SessionTakeCamera& camera = info->takes[0].cameras[1];
    EXPECT_EQ(camera.frame_file, "") << target;
    EXPECT_NE(camera.problem.find(manifest_path), std::string::npos) << camera.problem;
    EXPECT_NE(camera.problem.find("cameras[1].frame_file '" + target + "'"), std::string::npos)
        << camera.problem;
    EXPECT_EQ(info->takes[0].cameras[0].problem, "");

    auto check = CheckSession(dir.path());
    ASSERT_TRUE(check.ok());
    EXPECT_FALSE(check->Complete()) << target;
    EXPECT_EQ(check->takes[0].cameras[0].frames, 6);  // the honest camera is still read
    EXPECT_EQ(check->takes[0].cameras[1].frames, 0);
    const std::string text = check->ToText();
    EXPECT_NE(text.find("refused"), std::string::npos) << text;
  }
}

// session.json's calibration reference is confined to the session like capture.json's frame
// paths: before, "../" or an absolute path made reconstruct load camera models from anywhere.
TEST(Session, CalibrationPathOutsideTheSessionIsRefusedNamingTheField) {
  for (const std::string hostile :
       {"../outside/calibration.yaml", "sub/../../outside/calibration.yaml", "/OUTSIDE"}) {
    testing::TempDir dir;
    {
      auto session = SessionWriter::Open(dir.Join("s"), "virtual", Cameras(1), Json::object());
      ASSERT_TRUE(session.ok());
      ASSERT_TRUE((*session)->SetCalibration("calibration.yaml").ok());
      EXPECT_FALSE((*session)->SetCalibration(hostile).ok()) << hostile;
    }
    std::filesystem::create_directories(dir.Join("outside"));
    testing::WriteBytes(dir.Join("outside/calibration.yaml"), "cameras: []\n");
    std::string target = hostile == "/OUTSIDE" ? dir.Join("outside/calibration.yaml") : hostile;
    const std::string path = dir.Join("s/session.json");
    Json json = Json::parse(testing::ReadBytes(path));
    EXPECT_EQ(json["calibration"], "calibration.yaml");
    json["calibration"] = target;
    testing::WriteBytes(path, json.dump(2));
    auto info = ReadSession(dir.Join("s"));
    ASSERT_FALSE(info.ok()) << target;
    EXPECT_NE(info.status().message().find("field 'calibration'"), std::string::npos)
        << info.status().message();
    EXPECT_NE(info.status().message().find(target), std::string::npos) << info.status().message();
    EXPECT_FALSE(CheckSession(dir.Join("s")).ok());
  }
  // A path inside the session is still read.
  testing::TempDir dir;
  ASSERT_TRUE(SessionWriter::Open(dir.path(), "virtual", Cameras(1), Json::object()).ok());
  Json json = Json::parse(testing::ReadBytes(dir.Join("session.json")));
  json["calibration"] = "calib/cameras.yaml";
  testing::WriteBytes(dir.Join("session.json"), json.dump(2));
  auto info = ReadSession(dir.path());
  ASSERT_TRUE(info.ok()) << info.status().message();
  EXPECT_EQ(info->calibration_path, info->dir + "/calib/cameras.yaml");
}

// triggers_emitted sizes reconstruct's per-trigger arrays; 2^40 in a manifest is refused here.
TEST(Session, ImpossibleTriggerCountInManifestIsRefused) {
  testing::TempDir dir;
  auto session = SessionWriter::Open(dir.path(), "virtual", Cameras(1), Json::object());
  ASSERT_TRUE(session.ok());
  RecordTake(session->get(), "t", 1, 4);
  const std::string manifest_path = dir.path() + "/takes/t/capture.json";
  Json manifest = Json::parse(testing::ReadBytes(manifest_path));
  manifest["triggers_emitted"] = int64_t{1} << 40;
  testing::WriteBytes(manifest_path, manifest.dump(2));
  auto info = ReadSession(dir.path());
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->takes[0].triggers_emitted, -1);
  ASSERT_EQ(info->takes[0].problems.size(), 1u);
  EXPECT_NE(info->takes[0].problems[0].find("triggers_emitted 1099511627776 is outside"),
            std::string::npos)
      << info->takes[0].problems[0];
  auto check = CheckSession(dir.path());
  ASSERT_TRUE(check.ok());
  EXPECT_FALSE(check->Complete());
}

// A frame record with an impossible trigger index makes the take incomplete and is named.
TEST(Session, ImpossibleTriggerIndexInFrameFileIsReported) {
  testing::TempDir dir;
  auto session = SessionWriter::Open(dir.path(), "virtual", Cameras(1), Json::object());
  ASSERT_TRUE(session.ok());
  RecordTake(session->get(), "t", 1, 4);
  const std::string path = dir.path() + "/takes/t/cam0/frames.fdr";
  std::string bytes = testing::ReadBytes(path);
  const size_t record = bytes.size() / 4;
  const int64_t hostile = int64_t{1} << 40;
  std::memcpy(&bytes[3 * record + 8], &hostile, sizeof(hostile));
  uint64_t hash = 1469598103934665603ull;  // FNV-1a-64 of header bytes 0..55 (frame_file.h)
  for (int i = 0; i < 56; ++i) {
    hash ^= static_cast<uint8_t>(bytes[3 * record + i]);
    hash *= 1099511628211ull;
  }
  std::memcpy(&bytes[3 * record + 56], &hash, sizeof(hash));
  testing::WriteBytes(path, bytes);
  auto check = CheckSession(dir.path());
  ASSERT_TRUE(check.ok());
  EXPECT_FALSE(check->Complete());
  EXPECT_EQ(check->takes[0].cameras[0].frames, 3);
  const std::string text = check->ToText();
  EXPECT_NE(text.find("trigger_index 1099511627776"), std::string::npos) << text;
}

TEST(Session, CorruptSessionJsonIsAnError) {
  testing::TempDir dir;
  auto session = SessionWriter::Open(dir.path(), "virtual", Cameras(1), Json::object());
  ASSERT_TRUE(session.ok());
  std::string text = testing::ReadBytes(dir.Join("session.json"));
  testing::WriteBytes(dir.Join("session.json"), text.substr(0, text.size() / 2));
  auto check = CheckSession(dir.path());
  ASSERT_FALSE(check.ok());
  EXPECT_NE(check.status().message().find("session.json"), std::string::npos);
  EXPECT_FALSE(CheckSession(dir.Join("nothing")).ok());
}

// kill -9 in the middle of a take: the session stays readable and reports what it holds.
TEST(Session, KillNineMidTakeLeavesReadableSession) {
  testing::TempDir dir;
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    auto session = SessionWriter::Open(dir.path(), "virtual", Cameras(2), Json::object());
    if (!session.ok()) ::_exit(3);
    RecordTake(session->get(), "done", 2, 8);
    auto take_dir = (*session)->BeginTake("killed", 128.0, 1000000);
    if (!take_dir.ok()) ::_exit(4);
    auto recorder = Recorder::Start(
        RecorderOptions(), {*take_dir + "/cam0/frames.fdr", *take_dir + "/cam1/frames.fdr"});
    if (!recorder.ok()) ::_exit(5);
    for (int64_t t = 0;; ++t) {
      for (int k = 0; k < 2; ++k) (void)(*recorder)->Push(k, MakeFrame(k, t));
      if (t % 50 == 0) (void)(*session)->events().Append({{"event", "progress"}, {"t", t}});
    }
  }
  const std::string frames = dir.path() + "/takes/killed/cam1/frames.fdr";
  for (int i = 0; i < 500; ++i) {
    std::error_code ec;
    if (std::filesystem::exists(frames, ec) && std::filesystem::file_size(frames, ec) > 200000)
      break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ::kill(child, SIGKILL);
  int wait_status = 0;
  ::waitpid(child, &wait_status, 0);
  ASSERT_TRUE(WIFSIGNALED(wait_status));
  auto check = CheckSession(dir.path());
  ASSERT_TRUE(check.ok()) << check.status().message();
  ASSERT_EQ(check->takes.size(), 2u);
  EXPECT_TRUE(check->takes[0].complete) << check->ToText();
  EXPECT_FALSE(check->takes[1].complete);
  EXPECT_EQ(check->takes[1].status, "recording");
  EXPECT_GT(check->takes[1].cameras[1].frames, 100);
  EXPECT_NE(check->ToText().find("never stopped"), std::string::npos);

  // Reopening the session (`--resume`) marks the dead take interrupted, frames kept; a complete
  // take that says it supersedes it makes the session complete again.
  const int64_t kept = check->takes[1].cameras[1].frames;
  auto reopened = SessionWriter::Open(dir.path(), "virtual", Cameras(2), Json::object());
  ASSERT_TRUE(reopened.ok()) << reopened.status().message();
  check = CheckSession(dir.path());
  ASSERT_TRUE(check.ok());
  EXPECT_EQ(check->takes[1].status, "interrupted");
  EXPECT_EQ(check->takes[1].cameras[1].frames, kept);
  EXPECT_FALSE(check->Complete()) << check->ToText();  // interrupted and not redone
  EXPECT_NE(testing::ReadBytes(dir.path() + "/events.jsonl").find("take_interrupted"),
            std::string::npos);
  RecordTake(reopened->get(), "killed_retry2", 2, 8, -1, Json{{"supersedes", {"killed"}}});
  check = CheckSession(dir.path());
  ASSERT_TRUE(check.ok());
  EXPECT_EQ(check->takes[1].superseded_by, "killed_retry2");
  EXPECT_TRUE(check->Complete()) << check->ToText();
  // Only a complete take supersedes: an aborted one that claims to does not.
  RecordTake(reopened->get(), "victim", 2, 8, /*skip_trigger=*/3);
  RecordTake(reopened->get(), "bogus", 2, 8, /*skip_trigger=*/3, Json{{"supersedes", {"victim"}}});
  check = CheckSession(dir.path());
  ASSERT_TRUE(check.ok());
  ASSERT_EQ(check->takes.size(), 5u);
  EXPECT_EQ(check->takes[3].name, "victim");
  EXPECT_EQ(check->takes[3].superseded_by, "");
}

}  // namespace
}  // namespace facedyn::capture
