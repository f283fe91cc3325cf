// SessionLog: the rig's JSON Lines journal — one JSON object per line for every command sent
// to the drive, every reply read back, every state change of the supervisor and every sweep
// step event. It is both the audit trail of what the platform did to the person standing on
// it and the state `facedyn sweep --resume` continues from, so each line goes to the file
// with a single write(2) on an O_APPEND descriptor: a kill -9 loses at most the line being
// written and never leaves one half-interleaved with another. (There is no fsync per line;
// a power cut may lose the last lines the kernel had not written back.)
//
// Every record carries "t_ns" (nanoseconds on the session's steady clock, which starts at 0
// when the log is opened and continues from the last record on --resume), "wall" (UTC, ISO
// 8601) and "event".
#pragma once

#include <chrono>
#include <mutex>
#include <string>
#include <vector>

#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::rig {

class SessionLog {
 public:
  // Opens (creating or appending to) `path`. `start_t_ns` continues an earlier session clock.
  static StatusOr<std::unique_ptr<SessionLog>> Open(const std::string& path,
                                                    int64_t start_t_ns = 0);
  ~SessionLog();
  SessionLog(const SessionLog&) = delete;
  SessionLog& operator=(const SessionLog&) = delete;

  // Appends {"t_ns", "wall", "event": event, ...fields}. Thread-safe. A failed write is
  // remembered and returned by status(): the caller decides whether to stop the platform.
  void Write(const std::string& event, Json fields = Json::object());
  Status status() const;
  int64_t NowNs() const;
  const std::string& path() const { return path_; }

 private:
  SessionLog(std::string path, int fd, int64_t start_t_ns);

  std::string path_;
  int fd_ = -1;
  int64_t start_t_ns_ = 0;
  std::chrono::steady_clock::time_point opened_;
  mutable std::mutex mutex_;
  Status status_;
};

// Reads a session log back. Lines that are not JSON objects are an error naming the line —
// except a last line without its newline, which is what a crash mid-write leaves and is
// skipped (reported through *truncated_tail when given).
StatusOr<std::vector<Json>> ReadSessionLog(const std::string& path, bool* truncated_tail = nullptr);

}  // namespace facedyn::rig
