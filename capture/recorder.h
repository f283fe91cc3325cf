// Recorder: bounded per-camera frame queues drained by one writer thread per camera into
// frame files (capture/frame_file.h).
//
// Back-pressure policy (what happens when a camera produces faster than its disk write):
//   kBlock       Push waits for space in the camera's queue, up to block_timeout_s; only then
//                is the frame dropped (and counted). Right for virtual-clock sources (the
//                trigger just slows down and nothing is lost) and for cameras with deep
//                on-device buffers. This is the default.
//   kDropNewest  A frame that does not fit is dropped at once and counted. For real-time
//                sources where blocking the acquisition thread would make the driver drop
//                frames where nobody can count them.
// Either way a dropped frame is never silent: Push returns kDropped, the per-camera counter
// goes up and the session runner writes an event. Queues are bounded in frames, so memory is
// bounded by queue_frames x cameras x frame size.
//
// Write errors (ENOSPC, EIO): the failing camera's file is truncated back to its last
// complete record, the recorder enters the failed state, the error callback fires once (the
// runner stops the trigger from it), and every further Push returns kFailed. Other cameras
// finish writing what they already queued, so everything accepted before the failure that
// fits on disk stays readable.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "capture/frame.h"
#include "capture/frame_file.h"
#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::capture {

enum class BackpressurePolicy { kBlock, kDropNewest };
const char* BackpressurePolicyName(BackpressurePolicy policy);  // "block", "drop_newest"
StatusOr<BackpressurePolicy> ParseBackpressurePolicy(const std::string& name);

struct RecorderOptions {
  int queue_frames = 16;  // per camera, 1..4096
  BackpressurePolicy policy = BackpressurePolicy::kBlock;
  double block_timeout_s = 5.0;  // kBlock: longest wait before a drop, > 0
  bool sync_on_close = true;     // fdatasync each file when the take ends

  Status Check() const;
};

struct CameraRecordStats {
  int64_t frames_written = 0;
  int64_t bytes_written = 0;
  int64_t dropped_queue_full = 0;
  int64_t discarded_after_error = 0;  // queued when the take failed, not written
  int max_queue_depth = 0;
  std::string error;  // "" unless this camera's writer failed

  Json ToJson() const;
};

enum class PushResult { kQueued, kDropped, kFailed };

class Recorder {
 public:
  // One frame file per camera at `file_paths[k]`; the folders must exist. Starts the writer
  // threads. `pool` (optional) receives written buffers back for reuse.
  static StatusOr<std::unique_ptr<Recorder>> Start(const RecorderOptions& options,
                                                   const std::vector<std::string>& file_paths,
                                                   BufferPool* pool = nullptr);
  ~Recorder();  // Finish()es if needed
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // Called once, from a writer thread, on the first write error.
  void SetErrorCallback(std::function<void(const Status&)> callback);

  // Hands a frame to camera `camera`'s queue (the frame is moved from). Thread-safe; one
  // producer per camera is the intended use.
  PushResult Push(int camera, Frame&& frame);

  // Drains every queue, joins the writers and closes the files. Returns the first write error
  // (the files are intact up to it). Idempotent.
  Status Finish();

  bool failed() const { return failed_; }
  std::vector<CameraRecordStats> stats() const;
  int camera_count() const { return static_cast<int>(queues_.size()); }

 private:
  struct Queue {
    std::mutex mutex;
    std::condition_variable not_empty;
    std::condition_variable not_full;
    std::deque<Frame> frames;
    bool closed = false;
    CameraRecordStats stats;
    std::unique_ptr<FrameFileWriter> writer;
    std::thread thread;
  };

  explicit Recorder(const RecorderOptions& options, BufferPool* pool)
      : options_(options), pool_(pool) {}
  void WriterLoop(Queue* queue);
  void Fail(const Status& status);

  RecorderOptions options_;
  BufferPool* pool_;
  std::vector<std::unique_ptr<Queue>> queues_;
  std::atomic<bool> failed_{false};
  std::mutex error_mutex_;
  Status first_error_;
  std::function<void(const Status&)> error_callback_;
  bool finished_ = false;
};

}  // namespace facedyn::capture
