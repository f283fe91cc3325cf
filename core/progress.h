// Progress: how long work tells the user where it is.
//
// On a terminal it redraws one bar line ("reconstruct  [=====>    ] 412/1000  41%  eta 12s");
// when stderr is not a terminal (CI logs, pipes) it prints a plain line at most every
// `line_interval_s` seconds and at the end, so logs stay readable; with --quiet it prints
// nothing. The reporter is cheap to call per item: it only formats when it will print.
// Thread-safe: workers may call Advance() concurrently.
#pragma once

#include <chrono>
#include <cstdio>
#include <mutex>
#include <string>

namespace facedyn {

enum class ProgressMode { kAuto, kBar, kLines, kSilent };

// The mode used by reporters created with kAuto; set from --quiet by the app.
void SetDefaultProgressMode(ProgressMode mode);

class Progress {
 public:
  // `total` items (0 when unknown). `out` defaults to stderr.
  Progress(std::string label, long total, ProgressMode mode = ProgressMode::kAuto,
           std::FILE* out = nullptr, double line_interval_s = 5.0);
  ~Progress();  // finishes the line if Finish() was not called
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  void Advance(long items = 1);
  // Sets the position and an optional short status shown after the counts ("loss 0.0123").
  void Update(long done, const std::string& status = "");
  void Finish(const std::string& status = "");

  ProgressMode mode() const { return mode_; }

 private:
  void PrintLocked(bool final_line);

  std::string label_;
  long total_;
  long done_ = 0;
  std::string status_;
  ProgressMode mode_;
  std::FILE* out_;
  double line_interval_s_;
  bool finished_ = false;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_print_;
  std::mutex mutex_;
};

}  // namespace facedyn
