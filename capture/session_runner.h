// RecordTake: one take from N cameras on one trigger into a session folder.
//
// Threads: the caller's thread runs the trigger source, whose sink forwards each pulse to
// every camera (Camera::OnTrigger), records the pulse time and samples the rig telemetry; one
// acquisition thread per camera pulls frames (Camera::NextFrame), checks them against the
// triggers (FrameSyncChecker) and hands them to the Recorder, whose writer threads put them on
// disk. After the last pulse the runner waits until every camera has delivered a frame for
// every pulse or has made no progress for `drain_timeout_s`, then disarms the cameras.
//
// Everything abnormal is an event in events.jsonl (the first `max_anomaly_events` per camera
// individually, then a count in the manifest): sync anomalies, queue drops, write errors,
// camera errors. A write error (disk full) stops the trigger at once; the take ends "aborted"
// with every frame written so far intact and a final manifest (the session's reserve makes
// room for it). A take is "complete" only when every pulse was emitted and every camera
// recorded exactly one frame per pulse with no anomaly.
#pragma once

#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include "capture/camera.h"
#include "capture/recorder.h"
#include "capture/session.h"
#include "capture/trigger.h"
#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::capture {

// One rig telemetry row; the runner stamps it with the session time of the current trigger.
struct TelemetrySample {
  bool running = false;
  bool faulted = false;
  double output_hz = 0.0;    // drive output
  double measured_hz = 0.0;  // platform oscillation frequency
  double target_hz = 0.0;
  std::string state;  // supervisor state name
};

struct TakeOptions {
  std::string name;
  int64_t triggers = 0;
  RecorderOptions recorder;
  int64_t timestamp_tolerance_ns = 100000;
  double drain_timeout_s = 5.0;
  int max_anomaly_events = 100;  // per camera
  // Rig telemetry: called from the trigger thread at most every telemetry_period_s of wall
  // time (null: no telemetry). An error is logged and stops the take (the platform is in an
  // unknown state).
  std::function<StatusOr<TelemetrySample>()> telemetry;
  double telemetry_period_s = 0.1;
  // Called once the take folder exists and before the first trigger (e.g. to write ground
  // truth beside the frames). An error aborts the take before recording.
  std::function<Status(const std::string& take_dir)> before_first_trigger;
  Json extra = Json::object();  // copied into capture.json
  // Checked at every trigger (e.g. the SIGINT/SIGTERM flag, or the supervisor's "platform
  // stopping" flag); when set the take stops cleanly and ends "interrupted", every frame
  // recorded so far kept. May be null.
  const std::atomic<bool>* stop_requested = nullptr;

  Status Check() const;
};

struct TakeReport {
  TakeResult result;
  std::string take_dir;
  double wall_s = 0.0;         // the whole call, ground truth and arming included
  double record_wall_s = 0.0;  // first trigger to the last byte on disk (files synced)
  double bytes_written = 0.0;
  double MegabytesPerSecond() const {
    return record_wall_s > 0 ? bytes_written / 1e6 / record_wall_s : 0.0;
  }
};

// Records the take. Errors are returned only when nothing could be recorded (bad options, the
// take folder could not be created); otherwise the report's result.status says complete or
// aborted and result.reason why.
StatusOr<TakeReport> RecordTake(SessionWriter* session, const std::vector<Camera*>& cameras,
                                TriggerSource* trigger, const TakeOptions& options);

}  // namespace facedyn::capture
