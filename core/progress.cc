#include "core/progress.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>

#include <fmt/format.h>

namespace facedyn {
namespace {
std::atomic<ProgressMode> g_default_mode{ProgressMode::kAuto};

std::string FormatSeconds(double s) {
  if (s < 60) return fmt::format("{:.0f}s", s);
  if (s < 3600) return fmt::format("{:.0f}m{:02.0f}s", std::floor(s / 60), std::fmod(s, 60));
  return fmt::format("{:.0f}h{:02.0f}m", std::floor(s / 3600), std::fmod(s / 60, 60));
}
}  // namespace

void SetDefaultProgressMode(ProgressMode mode) { g_default_mode = mode; }

Progress::Progress(std::string label, long total, ProgressMode mode, std::FILE* out,
                   double line_interval_s)
    : label_(std::move(label)),
      total_(std::max(0L, total)),
      mode_(mode == ProgressMode::kAuto ? g_default_mode.load() : mode),
      out_(out ? out : stderr),
      line_interval_s_(line_interval_s),
      start_(std::chrono::steady_clock::now()),
      last_print_(start_) {
  if (mode_ == ProgressMode::kAuto) {
    mode_ = ::isatty(::fileno(out_)) ? ProgressMode::kBar : ProgressMode::kLines;
  }
}

Progress::~Progress() {
  if (!finished_) Finish();
}

void Progress::Advance(long items) {
  std::lock_guard<std::mutex> lock(mutex_);
  done_ += items;
  PrintLocked(false);
}

void Progress::Update(long done, const std::string& status) {
  std::lock_guard<std::mutex> lock(mutex_);
  done_ = done;
  status_ = status;
  PrintLocked(false);
}

void Progress::Finish(const std::string& status) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished_) return;
  if (!status.empty()) status_ = status;
  if (total_ > 0) done_ = std::max(done_, total_);
  finished_ = true;
  PrintLocked(true);
}

void Progress::PrintLocked(bool final_line) {
  if (mode_ == ProgressMode::kSilent) return;
  const auto now = std::chrono::steady_clock::now();
  const double since_last = std::chrono::duration<double>(now - last_print_).count();
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  // A bar redraws at most 10 times a second; lines appear every line_interval_s_.
  const double interval = mode_ == ProgressMode::kBar ? 0.1 : line_interval_s_;
  if (!final_line && since_last < interval) return;
  last_print_ = now;

  std::string counts;
  std::string eta;
  double fraction = 0;
  if (total_ > 0) {
    fraction = std::min(1.0, double(done_) / double(total_));
    counts = fmt::format("{}/{} {:3.0f}%", done_, total_, 100 * fraction);
    if (!final_line && done_ > 0) eta = " eta " + FormatSeconds(elapsed * (1 - fraction) / fraction);
  } else {
    counts = fmt::format("{}", done_);
  }
  const std::string tail = fmt::format("{}{}{}{}", counts, final_line ? " in " + FormatSeconds(elapsed) : "",
                                       eta, status_.empty() ? "" : "  " + status_);
  if (mode_ == ProgressMode::kBar) {
    constexpr int kWidth = 30;
    std::string bar(kWidth, ' ');
    if (total_ > 0) {
      const int filled = static_cast<int>(fraction * kWidth);
      std::fill(bar.begin(), bar.begin() + filled, '=');
      if (filled < kWidth) bar[filled] = '>';
    }
    std::fprintf(out_, "\r\033[K%s [%s] %s%s", label_.c_str(), bar.c_str(), tail.c_str(),
                 final_line ? "\n" : "");
  } else {
    std::fprintf(out_, "%s: %s\n", label_.c_str(), tail.c_str());
  }
  std::fflush(out_);
}

}  // namespace facedyn
