// Session folder: everything one capture session records, laid out so that a session cut
// short at any instant (kill -9, power, a full disk) stays readable.
//
//   DIR/session.json        format, name, created_utc, clock, rig, cameras, calibration
//                           reference, takes [{name, dir, status}] — rewritten atomically
//                           (temp + fsync + rename) at every take start and stop
//   DIR/events.jsonl        one JSON object per line, append-only, fsync'd per line:
//                           session_open, take_start, take_stop, frame anomalies, drops, write
//                           errors, rig states. Each carries "utc" and, when on the session
//                           clock, "t_ns"
//   DIR/calibration.yaml    camera models (capture/camera_model.h), when known
//   DIR/takes/<take>/capture.json   the take's manifest: status recording|complete|aborted,
//                           reason, fps, triggers emitted, per-camera counts and sync counts
//                           (written at start with status "recording", rewritten at stop)
//   DIR/takes/<take>/cam<k>/frames.fdr   camera k's frames (capture/frame_file.h)
//   DIR/takes/<take>/telemetry.csv       rig telemetry on the session clock
//   DIR/takes/<take>/ground_truth/       simulated takes only: what the simulator knows
//
// The take folder gets a small reserve file at start, removed before the manifest is
// rewritten at stop, so a take that filled the disk can still write its final manifest.
//
// CheckSession reads all of it without trusting any single file: frame files are scanned
// record by record, so a take killed mid-write reports how many frames each camera has.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "capture/frame_sync.h"
#include "capture/recorder.h"
#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::capture {

inline constexpr char kSessionFormat[] = "facedyn-session";
inline constexpr char kCaptureTakeFormat[] = "facedyn-capture-take";
inline constexpr int kSessionFormatVersion = 1;

std::string UtcNowIso8601();

// Append-only JSON-lines log; each Append is one write() and one fsync(). Thread-safe.
class EventLog {
 public:
  static StatusOr<std::unique_ptr<EventLog>> Open(const std::string& path);
  ~EventLog();
  EventLog(const EventLog&) = delete;
  EventLog& operator=(const EventLog&) = delete;

  // Adds "utc" (and keeps the caller's fields, "event" first by convention).
  Status Append(Json event);
  const std::string& path() const { return path_; }

 private:
  EventLog(std::string path, int fd) : path_(std::move(path)), fd_(fd) {}
  std::string path_;
  int fd_;
  std::mutex mutex_;
};

struct SessionCameraInfo {
  std::string name;
  std::string backend;  // sim | opencv | aravis
  int width_px = 0;
  int height_px = 0;
  std::string pixel_format = "mono8";
};

// Per-camera result of a take, as written in capture.json.
struct TakeCameraResult {
  std::string name;
  std::string dir;  // relative to the take folder, "cam<k>"
  SyncCounts sync;
  CameraRecordStats record;
};

struct TakeResult {
  // recording | complete | aborted (an error) | interrupted (a stop request, or the process
  // that recorded it died: marked when the session is next opened)
  std::string status = "recording";
  std::string reason;                // why it is not complete, "" when complete
  double fps = 0.0;
  int64_t triggers_requested = 0;
  int64_t triggers_emitted = 0;
  std::string start_utc;
  std::string stop_utc;
  std::vector<TakeCameraResult> cameras;
  Json extra = Json::object();  // platform, telemetry and ground-truth references, ...
};

// Writes a session folder. Opening an existing session appends to it (new takes only).
class SessionWriter {
 public:
  // Creates DIR (and events.jsonl, session.json) or reopens an existing session there.
  // `clock` is "virtual" or "steady". `rig` is free-form (the capture config's summary).
  // The writer holds DIR/.lock (flock) while it lives: a second writer is refused, and a take
  // found "recording" on reopening is one whose process died, marked "interrupted".
  static StatusOr<std::unique_ptr<SessionWriter>> Open(
      const std::string& dir, const std::string& clock,
      const std::vector<SessionCameraInfo>& cameras, const Json& rig);

  ~SessionWriter();
  SessionWriter(const SessionWriter&) = delete;
  SessionWriter& operator=(const SessionWriter&) = delete;

  const std::string& dir() const { return dir_; }
  EventLog& events() { return *events_; }
  // Records that DIR/calibration.yaml holds the camera models (written by the caller).
  Status SetCalibration(const std::string& relative_path);

  // Creates takes/<name>/ and cam<k>/ folders, the reserve file, capture.json (recording) and
  // lists the take in session.json. An existing take name is an InvalidArgument error: takes
  // are never overwritten. Take names: letters, digits, '_', '-', '.', not starting with '.'.
  StatusOr<std::string> BeginTake(const std::string& name, double fps, int64_t triggers_requested);
  // Removes the reserve, rewrites capture.json and session.json with the result, logs take_stop.
  Status EndTake(const std::string& name, const TakeResult& result);

  std::string TakeDir(const std::string& name) const;
  static std::string CameraDirName(int camera_index) {
    return "cam" + std::to_string(camera_index);
  }

 private:
  SessionWriter() = default;
  Status WriteSessionJson();
  // A take left "recording" by a process that died: capture.json says "interrupted" (its
  // counts removed: unknown), session.json too, and events.jsonl says when it was found.
  Status MarkInterrupted(const std::string& name);

  std::string dir_;
  Json session_;
  std::unique_ptr<EventLog> events_;
  int lock_fd_ = -1;  // DIR/.lock, flock'ed for the writer's lifetime
};

bool IsValidTakeName(const std::string& name);
Json TakeResultToJson(const std::string& name, const TakeResult& result);

// ---- Reading (reconstruct/ and `facedyn session check`) ----

struct SessionTakeCamera {
  int index = 0;
  std::string name;
  std::string frame_file;           // absolute path of frames.fdr; "" when `problem` is set
  int64_t frames_in_manifest = -1;  // -1 when the manifest does not say (take not stopped)
  // Why the manifest's entry for this camera was refused (a frame_file outside the take
  // folder), naming capture.json and the entry; "" when it was not.
  std::string problem;
};

struct SessionTake {
  std::string name;
  std::string dir;     // absolute
  std::string status;  // from capture.json ("recording" when the take never stopped), or "missing"
  std::string reason;
  double fps = 0.0;
  int64_t triggers_emitted = -1;
  int64_t triggers_requested = -1;
  std::vector<SessionTakeCamera> cameras;
  Json manifest;  // capture.json as read (null when missing or unreadable)
  // Values in capture.json that were refused (each names the file, field and value); the
  // field is then treated as absent.
  std::vector<std::string> problems;
};

struct SessionInfo {
  std::string dir;
  std::string name;
  std::string clock;
  std::vector<SessionCameraInfo> cameras;
  std::string calibration_path;    // absolute, "" when the session has none
  std::vector<SessionTake> takes;  // session.json order, then take folders it does not list
};

// Reads session.json and every take's capture.json. Only a missing or unparsable
// session.json is an error; problems with takes are reported in the takes' status.
StatusOr<SessionInfo> ReadSession(const std::string& dir);

struct CameraCheck {
  std::string name;
  int64_t frames = 0;  // complete records on disk
  int64_t unique_triggers = 0;
  int64_t missing = 0;  // relative to the take's triggers_emitted
  std::string tail_problem;
};

struct TakeCheck {
  std::string name;
  std::string status;
  bool complete = false;
  // The complete take that redid this one (its capture.json lists this name in "supersedes",
  // e.g. a sweep step recorded again after a kill); "" when none. A superseded take is kept
  // and reported, but does not make the session incomplete.
  std::string superseded_by;
  std::vector<std::string> problems;
  std::vector<CameraCheck> cameras;
};

struct SessionCheck {
  std::string dir;
  int64_t events = 0;
  std::string events_problem;  // e.g. a torn last line
  std::vector<TakeCheck> takes;

  bool Complete() const;
  Json ToJson() const;
  std::string ToText() const;
};

// A take is complete when its manifest says "complete", every camera's file scans cleanly and
// holds exactly one frame for every emitted trigger, and the counts agree with the manifest.
// The session is complete when events.jsonl reads cleanly and every take is complete or
// superseded by a complete one.
StatusOr<SessionCheck> CheckSession(const std::string& dir);

}  // namespace facedyn::capture
