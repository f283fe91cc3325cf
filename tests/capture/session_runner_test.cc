#include "capture/session_runner.h"

#include <gtest/gtest.h>

#include <condition_variable>
#include <deque>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>

#include "capture/frame_file.h"
#include "tests/support/test_support.h"

namespace facedyn::capture {
namespace {

// A minimal in-memory camera: one small frame per trigger; optionally fails at one trigger.
class ScriptedCamera : public Camera {
 public:
  ScriptedCamera(int index, std::string name, int64_t fail_at = -1)
      : index_(index), name_(std::move(name)), fail_at_(fail_at) {}
  const std::string& name() const override { return name_; }
  std::string backend() const override { return "test"; }
  Status Configure(const CameraSettings& settings) override {
    settings_ = settings;
    return Status::Ok();
  }
  const CameraSettings& settings() const override { return settings_; }
  Status Arm() override { return Status::Ok(); }
  Status OnTrigger(const TriggerEvent& trigger) override {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_.push_back(trigger);
    changed_.notify_all();
    return Status::Ok();
  }
  Status NextFrame(double timeout_s, Frame* frame, bool* got_frame) override {
    *got_frame = false;
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                      [&] { return !pending_.empty() || disarmed_; });
    if (pending_.empty()) {
      return disarmed_ ? AbortedError("disarmed") : Status::Ok();
    }
    const TriggerEvent trigger = pending_.front();
    pending_.pop_front();
    if (trigger.index == fail_at_) return UnavailableError("sensor link lost");
    frame->camera_index = index_;
    frame->trigger_index = trigger.index;
    frame->timestamp_ns = trigger.time_ns;
    frame->width_px = 16;
    frame->height_px = 8;
    frame->format = PixelFormat::kMono8;
    frame->pixels.assign(frame->ExpectedBytes(), static_cast<uint8_t>(trigger.index));
    *got_frame = true;
    return Status::Ok();
  }
  Status Disarm() override {
    std::lock_guard<std::mutex> lock(mutex_);
    disarmed_ = true;
    changed_.notify_all();
    return Status::Ok();
  }

 private:
  int index_;
  std::string name_;
  int64_t fail_at_;
  CameraSettings settings_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<TriggerEvent> pending_;
  bool disarmed_ = false;
};

std::vector<SessionCameraInfo> Infos(int count) {
  std::vector<SessionCameraInfo> infos;
  for (int k = 0; k < count; ++k)
    infos.push_back({"c" + std::to_string(k), "test", 16, 8, "mono8"});
  return infos;
}

std::vector<nlohmann::json> Events(const std::string& dir) {
  std::vector<nlohmann::json> events;
  std::ifstream in(dir + "/events.jsonl");
  for (std::string line; std::getline(in, line);) events.push_back(nlohmann::json::parse(line));
  return events;
}

TEST(RecordTake, CleanTakeIsComplete) {
  testing::TempDir dir;
  auto session = SessionWriter::Open(dir.path(), "virtual", Infos(2), Json::object());
  ASSERT_TRUE(session.ok());
  ScriptedCamera a(0, "c0"), b(1, "c1");
  VirtualTrigger trigger({100.0, 0.0});
  TakeOptions options;
  options.name = "ok";
  options.triggers = 50;
  auto report = RecordTake(session->get(), {&a, &b}, &trigger, options);
  ASSERT_TRUE(report.ok()) << report.status().message();
  EXPECT_EQ(report->result.status, "complete") << report->result.reason;
  EXPECT_EQ(report->result.cameras[1].record.frames_written, 50);
  auto reader = FrameFileReader::Open(dir.path() + "/takes/ok/cam1/frames.fdr");
  ASSERT_TRUE(reader.ok());
  EXPECT_EQ((*reader)->scan().records[49].timestamp_ns, 490000000);
}

TEST(RecordTake, CameraErrorStopsTheTakeAndNamesTheCamera) {
  testing::TempDir dir;
  auto session = SessionWriter::Open(dir.path(), "virtual", Infos(2), Json::object());
  ASSERT_TRUE(session.ok());
  ScriptedCamera a(0, "c0"), b(1, "c1", /*fail_at=*/20);
  VirtualTrigger trigger({100.0, 1.0});  // real time: the failure stops the trigger early
  TakeOptions options;
  options.name = "broken";
  options.triggers = 1000;
  auto report = RecordTake(session->get(), {&a, &b}, &trigger, options);
  ASSERT_TRUE(report.ok()) << report.status().message();
  EXPECT_EQ(report->result.status, "aborted");
  EXPECT_NE(report->result.reason.find("c1: sensor link lost"), std::string::npos)
      << report->result.reason;
  EXPECT_LT(report->result.triggers_emitted, 1000);
  EXPECT_GE(report->result.cameras[1].record.frames_written, 20);
  bool logged = false;
  for (const auto& event : Events(dir.path()))
    logged |= event["event"] == "camera_error" && event["camera"] == "c1";
  EXPECT_TRUE(logged);
  auto check = CheckSession(dir.path());
  ASSERT_TRUE(check.ok());
  EXPECT_FALSE(check->takes[0].complete);
}

TEST(RecordTake, StopRequestEndsTheTakeInterrupted) {
  testing::TempDir dir;
  auto session = SessionWriter::Open(dir.path(), "virtual", Infos(1), Json::object());
  ASSERT_TRUE(session.ok());
  ScriptedCamera a(0, "c0");
  VirtualTrigger trigger({100.0, 0.0});
  std::atomic<bool> stop{false};
  TakeOptions options;
  options.name = "stopped";
  options.triggers = 100;
  options.stop_requested = &stop;
  int calls = 0;
  options.telemetry = [&]() -> StatusOr<TelemetrySample> {
    if (++calls == 3) stop = true;
    TelemetrySample sample;
    sample.state = "settled";
    return sample;
  };
  options.telemetry_period_s = 1e-9;  // every trigger
  auto report = RecordTake(session->get(), {&a}, &trigger, options);
  ASSERT_TRUE(report.ok());
  EXPECT_EQ(report->result.status, "interrupted");
  EXPECT_NE(report->result.reason.find("interrupted"), std::string::npos) << report->result.reason;
  EXPECT_EQ(report->result.triggers_emitted, 3);
  // Pulses 0..2 went out (the request is seen at the start of pulse 3); each has its frame.
  EXPECT_EQ(report->result.cameras[0].record.frames_written, 3);
  std::ifstream telemetry(dir.path() + "/takes/stopped/telemetry.csv");
  std::string header;
  std::getline(telemetry, header);
  EXPECT_EQ(header, "t_ns,state,running,faulted,output_hz,measured_hz,target_hz");
}

TEST(TakeOptions, CheckNamesTheProblem) {
  TakeOptions options;
  options.name = "../x";
  EXPECT_NE(options.Check().message().find("../x"), std::string::npos);
  options.name = "fine";
  EXPECT_NE(options.Check().message().find("triggers"), std::string::npos);
}

}  // namespace
}  // namespace facedyn::capture
