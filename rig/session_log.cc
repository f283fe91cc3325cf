#include "rig/session_log.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <ctime>
#include <memory>

#include "core/file_util.h"
#include "core/json_io.h"
#include "core/utf8.h"

namespace facedyn::rig {
namespace {

std::string WallClockUtc() {
  const auto now = std::chrono::system_clock::now();
  const std::time_t seconds = std::chrono::system_clock::to_time_t(now);
  const auto millis =
      std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char text[32];
  std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%S", &utc);
  return fmt::format("{}.{:03d}Z", text, static_cast<int>(millis));
}

}  // namespace

SessionLog::SessionLog(std::string path, int fd, int64_t start_t_ns)
    : path_(std::move(path)),
      fd_(fd),
      start_t_ns_(start_t_ns),
      opened_(std::chrono::steady_clock::now()) {}

StatusOr<std::unique_ptr<SessionLog>> SessionLog::Open(const std::string& path,
                                                       int64_t start_t_ns) {
  // A torn last record (kill -9, a full disk) is moved to `path`.torn so this session's
  // records start on a line of their own and --resume can read the log.
  size_t torn_bytes = 0;
  auto opened = OpenAppendLog(path, &torn_bytes);
  if (!opened.ok()) return opened.status().WithContext("the session log");
  const int fd = *opened;
  if (torn_bytes > 0) {
    spdlog::warn("{}: its last record was torn ({} bytes, a crash mid-write): kept in {}.torn",
                 path, torn_bytes, path);
  }
  return std::unique_ptr<SessionLog>(new SessionLog(path, fd, start_t_ns));
}

SessionLog::~SessionLog() {
  if (fd_ >= 0) ::close(fd_);
}

int64_t SessionLog::NowNs() const {
  return start_t_ns_ + std::chrono::duration_cast<std::chrono::nanoseconds>(
                           std::chrono::steady_clock::now() - opened_)
                           .count();
}

void SessionLog::Write(const std::string& event, Json fields) {
  Json record;
  record["t_ns"] = NowNs();
  record["wall"] = WallClockUtc();
  record["event"] = event;
  for (auto& [key, value] : fields.items()) record[key] = std::move(value);
  const std::string line = record.dump(-1, ' ', false, kJsonReplaceInvalidUtf8) + "\n";
  std::lock_guard<std::mutex> lock(mutex_);
  const Status appended = AppendLogLine(fd_, line, path_);
  if (!appended.ok() && status_.ok()) status_ = appended;
}

Status SessionLog::status() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return status_;
}

StatusOr<std::vector<Json>> ReadSessionLog(const std::string& path, bool* truncated_tail) {
  FACEDYN_ASSIGN_OR_RETURN(const std::string text, ReadFileToString(path));
  std::vector<Json> records;
  if (truncated_tail) *truncated_tail = false;
  size_t begin = 0;
  int line_number = 0;
  while (begin < text.size()) {
    ++line_number;
    const size_t end = text.find('\n', begin);
    const bool complete = end != std::string::npos;
    const std::string line = text.substr(begin, complete ? end - begin : std::string::npos);
    begin = complete ? end + 1 : text.size();
    if (!complete) {
      if (truncated_tail) *truncated_tail = true;
      break;  // a crash mid-write: the record never happened
    }
    if (line.empty()) continue;
    Json record = Json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (record.is_discarded() || !record.is_object() || !record.contains("event")) {
      return DataLossError(fmt::format("{}:{}: not a session log record: '{}'", path, line_number,
                                       EscapeInvalidUtf8(line.substr(0, 80))));
    }
    records.push_back(std::move(record));
  }
  return records;
}

}  // namespace facedyn::rig
