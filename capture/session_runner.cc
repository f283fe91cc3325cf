#include "capture/session_runner.h"

#include <fmt/format.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>
#include <thread>

#include "capture/frame_file.h"
#include "capture/frame_sync.h"
#include "core/file_util.h"

namespace facedyn::capture {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Shared between the trigger thread and the acquisition threads.
struct TakeState {
  std::vector<int64_t> trigger_time_ns;  // sized to the requested count up front
  std::atomic<int64_t> emitted{0};
  std::atomic<bool> stop{false};
  std::atomic<bool> interrupted{false};  // a stop request ended it (not an error)
  std::mutex error_mutex;
  std::string first_error;
  void Fail(const std::string& error) {
    std::lock_guard<std::mutex> lock(error_mutex);
    if (first_error.empty()) first_error = error;
    stop = true;
  }
};

struct CameraWorker {
  int index = 0;
  Camera* camera = nullptr;
  FrameSyncChecker checker{0};
  std::atomic<int64_t> delivered{0};  // unique valid frames
  int anomaly_events = 0;
  int64_t dropped = 0;
  std::string error;
  std::thread thread;
};

}  // namespace

Status TakeOptions::Check() const {
  if (!IsValidTakeName(name)) return InvalidArgumentError("take name '" + name + "' is not valid");
  if (triggers < 1) return InvalidArgumentError("take triggers must be >= 1");
  if (!(drain_timeout_s > 0)) return InvalidArgumentError("take drain_timeout_s must be > 0");
  if (!(telemetry_period_s > 0)) return InvalidArgumentError("take telemetry_period_s must be > 0");
  return recorder.Check();
}

StatusOr<TakeReport> RecordTake(SessionWriter* session, const std::vector<Camera*>& cameras,
                                TriggerSource* trigger, const TakeOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  if (cameras.empty()) return InvalidArgumentError("a take needs at least one camera");
  const auto wall_start = Clock::now();
  TakeReport report;
  FACEDYN_ASSIGN_OR_RETURN(report.take_dir,
                           session->BeginTake(options.name, trigger->rate_hz(), options.triggers));
  EventLog& events = session->events();
  TakeResult& result = report.result;
  result.fps = trigger->rate_hz();
  result.triggers_requested = options.triggers;
  result.start_utc = UtcNowIso8601();
  result.extra = options.extra;

  const int camera_count = static_cast<int>(cameras.size());
  std::vector<std::unique_ptr<CameraWorker>> workers;
  for (int k = 0; k < camera_count; ++k) {
    auto worker = std::make_unique<CameraWorker>();
    worker->index = k;
    worker->camera = cameras[k];
    worker->checker = FrameSyncChecker(options.timestamp_tolerance_ns);
    workers.push_back(std::move(worker));
  }
  auto finish_early = [&](const std::string& reason) -> StatusOr<TakeReport> {
    result.status = "aborted";
    result.reason = reason;
    result.stop_utc = UtcNowIso8601();
    for (int k = 0; k < camera_count; ++k)
      result.cameras.push_back({cameras[k]->name(), SessionWriter::CameraDirName(k), {}, {}});
    FACEDYN_RETURN_IF_ERROR(session->EndTake(options.name, result));
    report.wall_s = SecondsSince(wall_start);
    return report;
  };

  if (options.before_first_trigger) {
    Status status = options.before_first_trigger(report.take_dir);
    if (!status.ok()) return finish_early("before the first trigger: " + status.message());
  }
  for (Camera* camera : cameras) {
    Status status = camera->Arm();
    if (!status.ok()) {
      for (Camera* c : cameras) (void)c->Disarm();
      return finish_early("arming " + camera->name() + ": " + status.message());
    }
  }

  std::vector<std::string> paths;
  for (int k = 0; k < camera_count; ++k) {
    paths.push_back(
        JoinPath(JoinPath(report.take_dir, SessionWriter::CameraDirName(k)), kFrameFileName));
  }
  BufferPool pool(static_cast<size_t>(camera_count) * (options.recorder.queue_frames + 4));
  auto recorder_or = Recorder::Start(options.recorder, paths, &pool);
  if (!recorder_or.ok()) {
    for (Camera* c : cameras) (void)c->Disarm();
    return finish_early("starting the recorder: " + recorder_or.status().message());
  }
  std::unique_ptr<Recorder> recorder = std::move(recorder_or).value();
  TakeState state;
  state.trigger_time_ns.assign(options.triggers, 0);
  recorder->SetErrorCallback([&](const Status& error) {
    (void)events.Append(
        {{"event", "write_error"}, {"take", options.name}, {"message", error.message()}});
    state.Fail("write error: " + error.message());
    trigger->Stop();
  });

  // Acquisition threads.
  for (auto& worker_ptr : workers) {
    CameraWorker* worker = worker_ptr.get();
    worker->thread = std::thread([&, worker] {
      Frame frame;
      for (;;) {
        frame.pixels = pool.Acquire(0);
        bool got_frame = false;
        Status status = worker->camera->NextFrame(0.5, &frame, &got_frame);
        if (status.code() == StatusCode::kAborted) break;  // disarmed and drained
        if (status.ok() && !got_frame) continue;           // nothing within the timeout
        if (!status.ok()) {
          worker->error = status.message();
          (void)events.Append({{"event", "camera_error"},
                               {"take", options.name},
                               {"camera", worker->camera->name()},
                               {"message", status.message()}});
          state.Fail(worker->camera->name() + ": " + status.message());
          trigger->Stop();
          break;
        }
        const int64_t emitted = state.emitted.load();
        const int64_t trigger_time = frame.trigger_index >= 0 && frame.trigger_index < emitted
                                         ? state.trigger_time_ns[frame.trigger_index]
                                         : 0;
        const SyncObservation seen =
            worker->checker.Observe(frame.trigger_index, frame.timestamp_ns, trigger_time, emitted);
        if ((seen.verdict != SyncVerdict::kOk || seen.timestamp_mismatch) &&
            worker->anomaly_events < options.max_anomaly_events) {
          ++worker->anomaly_events;
          Json event{
              {"event", "frame_anomaly"},         {"take", options.name},
              {"camera", worker->camera->name()}, {"t_ns", frame.timestamp_ns},
              {"trigger", frame.trigger_index},   {"verdict", SyncVerdictName(seen.verdict)}};
          if (seen.verdict == SyncVerdict::kGap) event["missing_before"] = seen.gap_triggers;
          if (seen.timestamp_mismatch) event["timestamp_error_ns"] = seen.timestamp_error_ns;
          if (!seen.record) event["recorded"] = false;
          (void)events.Append(event);
        }
        if (!seen.record) continue;
        worker->delivered.fetch_add(1);
        const int64_t trigger_index = frame.trigger_index;
        const PushResult pushed = recorder->Push(worker->index, std::move(frame));
        frame = Frame();
        if (pushed == PushResult::kDropped) {
          ++worker->dropped;
          if (worker->anomaly_events < options.max_anomaly_events) {
            ++worker->anomaly_events;
            (void)events.Append(
                {{"event", "drop"},
                 {"take", options.name},
                 {"camera", worker->camera->name()},
                 {"trigger", trigger_index},
                 {"reason", "queue_full"},
                 {"backpressure", BackpressurePolicyName(options.recorder.policy)}});
          }
        }
        // kFailed: the take is stopping (write error); keep draining the camera.
      }
    });
  }

  // Telemetry file, on the session clock (the trigger times).
  std::FILE* telemetry_file = nullptr;
  if (options.telemetry) {
    telemetry_file = std::fopen(JoinPath(report.take_dir, "telemetry.csv").c_str(), "w");
    if (telemetry_file != nullptr)
      std::fputs("t_ns,state,running,faulted,output_hz,measured_hz,target_hz\n", telemetry_file);
    result.extra["telemetry"] = "telemetry.csv";
  }
  auto last_telemetry = Clock::now() - std::chrono::hours(1);
  std::string last_rig_state;
  auto sample_telemetry = [&](int64_t t_ns) -> Status {
    FACEDYN_ASSIGN_OR_RETURN(const TelemetrySample sample, options.telemetry());
    if (telemetry_file != nullptr) {
      std::fprintf(telemetry_file, "%lld,%s,%d,%d,%.4f,%.4f,%.4f\n", static_cast<long long>(t_ns),
                   sample.state.c_str(), sample.running ? 1 : 0, sample.faulted ? 1 : 0,
                   sample.output_hz, sample.measured_hz, sample.target_hz);
      std::fflush(telemetry_file);
    }
    if (sample.state != last_rig_state) {
      last_rig_state = sample.state;
      (void)events.Append({{"event", "rig_state"},
                           {"take", options.name},
                           {"t_ns", t_ns},
                           {"state", sample.state},
                           {"measured_hz", sample.measured_hz}});
    }
    if (sample.faulted) return UnavailableError("the drive tripped during the take");
    return Status::Ok();
  };

  const auto record_start = Clock::now();
  const Status trigger_status =
      trigger->Run(options.triggers, [&](const TriggerEvent& event) -> Status {
        if (state.stop) return AbortedError("stopped");
        if (options.stop_requested != nullptr && options.stop_requested->load()) {
          (void)events.Append(
              {{"event", "interrupted"}, {"take", options.name}, {"t_ns", event.time_ns}});
          state.interrupted = true;
          state.Fail("interrupted (stop requested) at trigger " + std::to_string(event.index));
          return AbortedError("interrupted");
        }
        state.trigger_time_ns[event.index] = event.time_ns;
        state.emitted.store(event.index + 1);
        if (options.telemetry && SecondsSince(last_telemetry) >= options.telemetry_period_s) {
          last_telemetry = Clock::now();
          Status status = sample_telemetry(event.time_ns);
          if (!status.ok()) {
            (void)events.Append({{"event", "rig_error"},
                                 {"take", options.name},
                                 {"t_ns", event.time_ns},
                                 {"message", status.message()}});
            state.Fail("rig: " + status.message());
            return status;
          }
        }
        for (Camera* camera : cameras) {
          Status status = camera->OnTrigger(event);
          if (!status.ok()) {
            state.Fail(camera->name() + ": " + status.message());
            return status;
          }
        }
        return Status::Ok();
      });
  result.triggers_emitted = state.emitted.load();

  // Drain: wait for every camera to catch up, or to stall.
  {
    auto last_progress = Clock::now();
    int64_t last_total = -1;
    while (!state.stop) {
      int64_t total = 0;
      bool all = true;
      for (auto& worker : workers) {
        const int64_t delivered = worker->delivered.load();
        total += delivered;
        all = all && delivered >= result.triggers_emitted;
      }
      if (all) break;
      if (total != last_total) {
        last_total = total;
        last_progress = Clock::now();
      } else if (SecondsSince(last_progress) > options.drain_timeout_s) {
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }
  for (Camera* camera : cameras) (void)camera->Disarm();
  for (auto& worker : workers) worker->thread.join();
  const Status record_status = recorder->Finish();
  report.record_wall_s = SecondsSince(record_start);
  if (telemetry_file != nullptr) std::fclose(telemetry_file);

  const std::vector<CameraRecordStats> stats = recorder->stats();
  bool clean = trigger_status.ok() && record_status.ok() && state.first_error.empty() &&
               result.triggers_emitted == options.triggers;
  std::string reason;
  for (int k = 0; k < camera_count; ++k) {
    CameraWorker& worker = *workers[k];
    worker.checker.Finish(result.triggers_emitted);
    TakeCameraResult camera;
    camera.name = cameras[k]->name();
    camera.dir = SessionWriter::CameraDirName(k);
    camera.sync = worker.checker.counts();
    camera.record = stats[k];
    report.bytes_written += static_cast<double>(stats[k].bytes_written);
    const bool camera_clean = camera.sync.Clean() && stats[k].dropped_queue_full == 0 &&
                              stats[k].error.empty() &&
                              stats[k].frames_written == result.triggers_emitted;
    if (!camera_clean && reason.empty()) {
      reason = fmt::format(
          "{}: {} missing, {} duplicated, {} out of order, {} timestamp mismatches, {} dropped "
          "(queue full), {} written of {}",
          camera.name, camera.sync.missing, camera.sync.duplicated, camera.sync.out_of_order,
          camera.sync.timestamp_mismatch, stats[k].dropped_queue_full, stats[k].frames_written,
          result.triggers_emitted);
    }
    clean = clean && camera_clean;
    result.cameras.push_back(camera);
  }
  if (!state.first_error.empty()) {
    reason = state.first_error;
  } else if (!record_status.ok()) {
    reason = record_status.message();
  } else if (!trigger_status.ok()) {
    reason = "trigger: " + trigger_status.message();
  }
  result.status = clean ? "complete" : state.interrupted ? "interrupted" : "aborted";
  result.reason = clean ? "" : reason;
  result.stop_utc = UtcNowIso8601();
  report.wall_s = SecondsSince(wall_start);
  result.extra["wall_s"] = report.wall_s;
  result.extra["record_wall_s"] = report.record_wall_s;
  FACEDYN_RETURN_IF_ERROR(session->EndTake(options.name, result));
  return report;
}

}  // namespace facedyn::capture
