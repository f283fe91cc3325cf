#include "capture/session.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "capture/frame_file.h"
#include "core/config_node.h"
#include "core/file_util.h"
#include "core/json_io.h"

namespace facedyn::capture {
namespace fs = std::filesystem;

namespace {

constexpr char kReserveFileName[] = ".reserve";
constexpr char kLockFileName[] = ".lock";
constexpr size_t kReserveBytes = 1 << 20;  // room for the final manifest, session.json, events

Status WriteReserve(const std::string& path) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return UnavailableError(path + ": cannot create: " + std::strerror(errno));
  const int error = ::posix_fallocate(fd, 0, kReserveBytes);
  ::close(fd);
  if (error != 0) {
    ::unlink(path.c_str());
    return UnavailableError(path + ": cannot reserve " + std::to_string(kReserveBytes) +
                            " bytes for the take's manifest: " + std::strerror(error));
  }
  return Status::Ok();
}

// Why `relative` (a path from capture.json or session.json) does not name a file inside the
// folder it is relative to (`folder_kind`: "take", "session"), or "". A take's files are always
// inside its folder and a session's calibration inside the session; a file that points
// elsewhere ("../../other/frames.fdr", "/etc/shadow") is corrupt or hostile, and following it
// would make `session check` and reconstruct read, and report on, files of someone else's
// choosing. The test is lexical (no ".." component, not absolute): symlinks inside a session
// are the operator's own doing and are followed.
std::string PathLeavesFolder(const std::string& relative, const char* folder_kind) {
  const fs::path path(relative);
  if (path.empty()) return "is empty";
  if (path.is_absolute()) return "is absolute";
  for (const fs::path& part : path) {
    if (part == "..") return fmt::format("climbs out of the {} folder with '..'", folder_kind);
  }
  return "";
}

Json CamerasToJson(const std::vector<SessionCameraInfo>& cameras) {
  Json list = Json::array();
  for (const auto& camera : cameras) {
    list.push_back({{"name", camera.name},
                    {"backend", camera.backend},
                    {"width_px", camera.width_px},
                    {"height_px", camera.height_px},
                    {"pixel_format", camera.pixel_format}});
  }
  return list;
}

}  // namespace

std::string UtcNowIso8601() {
  timespec now;
  clock_gettime(CLOCK_REALTIME, &now);
  std::tm tm;
  gmtime_r(&now.tv_sec, &tm);
  char buffer[64];
  std::strftime(buffer, sizeof(buffer), "%Y-%m-%dT%H:%M:%S", &tm);
  return fmt::format("{}.{:03d}Z", buffer, static_cast<int>(now.tv_nsec / 1000000));
}

// ---------------------------------------------------------------------------- EventLog

StatusOr<std::unique_ptr<EventLog>> EventLog::Open(const std::string& path) {
  // A torn last event (kill -9, a full disk) is moved to `path`.torn first, so the next event
  // does not glue onto it and `session check` can read the log.
  size_t torn_bytes = 0;
  auto fd = OpenAppendLog(path, &torn_bytes);
  if (!fd.ok()) return fd.status().WithContext("event log");
  if (torn_bytes > 0)
    spdlog::warn("{}: its last event was torn ({} bytes): kept in {}.torn", path, torn_bytes, path);
  return std::unique_ptr<EventLog>(new EventLog(path, *fd));
}

EventLog::~EventLog() { ::close(fd_); }

Status EventLog::Append(Json event) {
  event["utc"] = UtcNowIso8601();
  const std::string line = event.dump(-1, ' ', false, kJsonReplaceInvalidUtf8) + "\n";
  std::lock_guard<std::mutex> lock(mutex_);
  // All or nothing: a short write (ENOSPC) is rolled back; a crash mid-write leaves a torn
  // last line, which readers skip and the next Open moves aside.
  FACEDYN_RETURN_IF_ERROR(AppendLogLine(fd_, line, path_).WithContext("event append"));
  if (::fsync(fd_) != 0) return UnavailableError(path_ + ": fsync failed: " + std::strerror(errno));
  return Status::Ok();
}

// ---------------------------------------------------------------------------- SessionWriter

bool IsValidTakeName(const std::string& name) {
  if (name.empty() || name.size() > 128 || name[0] == '.') return false;
  for (char c : name) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.'))
      return false;
  }
  return true;
}

StatusOr<std::unique_ptr<SessionWriter>> SessionWriter::Open(
    const std::string& dir, const std::string& clock, const std::vector<SessionCameraInfo>& cameras,
    const Json& rig) {
  if (clock != "virtual" && clock != "steady")
    return InvalidArgumentError("session clock must be virtual or steady");
  std::unique_ptr<SessionWriter> writer(new SessionWriter());
  writer->dir_ = dir;
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(JoinPath(dir, "takes")));
  // One writer per session at a time: a take found "recording" below is then known to be one
  // whose process died (the kernel drops a killed process's lock), never one being recorded.
  const std::string lock_path = JoinPath(dir, kLockFileName);
  writer->lock_fd_ = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (writer->lock_fd_ < 0)
    return UnavailableError(lock_path + ": cannot open: " + std::strerror(errno));
  if (::flock(writer->lock_fd_, LOCK_EX | LOCK_NB) != 0) {
    return FailedPreconditionError(dir + ": the session is open in another facedyn process (" +
                                   lock_path + " is locked)");
  }
  const std::string session_path = JoinPath(dir, "session.json");
  std::vector<SessionTake> dead_takes;  // "recording", but nobody is
  std::error_code ec;
  bool reopened = false;
  if (fs::exists(session_path, ec)) {
    FACEDYN_ASSIGN_OR_RETURN(const SessionInfo existing, ReadSession(dir));
    FACEDYN_ASSIGN_OR_RETURN(std::string text, ReadFileToString(session_path));
    writer->session_ = Json::parse(text, nullptr, false);
    if (writer->session_.is_discarded()) return DataLossError(session_path + ": not valid JSON");
    if (existing.cameras.size() != cameras.size()) {
      return FailedPreconditionError(session_path + ": the session has " +
                                     std::to_string(existing.cameras.size()) +
                                     " cameras, this capture " + std::to_string(cameras.size()) +
                                     "; use a new session folder");
    }
    if (existing.clock != clock) {
      return FailedPreconditionError(session_path + ": the session's clock is " + existing.clock +
                                     ", this capture's " + clock);
    }
    for (const SessionTake& take : existing.takes) {
      if (take.status == "recording") dead_takes.push_back(take);
    }
    reopened = true;
  } else {
    writer->session_ = Json{{"format", kSessionFormat},
                            {"version", kSessionFormatVersion},
                            {"name", fs::path(dir).filename().string()},
                            {"created_utc", UtcNowIso8601()},
                            {"clock", clock},
                            {"rig", rig},
                            {"cameras", CamerasToJson(cameras)},
                            {"calibration", nullptr},
                            {"takes", Json::array()}};
  }
  FACEDYN_ASSIGN_OR_RETURN(writer->events_, EventLog::Open(JoinPath(dir, "events.jsonl")));
  for (const SessionTake& take : dead_takes) {
    // A manifest that cannot be rewritten must not lock the session for good: `session check`
    // still reports that take as never stopped.
    const Status marked = writer->MarkInterrupted(take.name);
    if (!marked.ok()) spdlog::warn("{}: take {}: {}", dir, take.name, marked.message());
  }
  FACEDYN_RETURN_IF_ERROR(writer->WriteSessionJson());
  FACEDYN_RETURN_IF_ERROR(
      writer->events_->Append({{"event", reopened ? "session_reopen" : "session_open"}}));
  return writer;
}

SessionWriter::~SessionWriter() {
  if (lock_fd_ >= 0) ::close(lock_fd_);  // releases the lock
}

Status SessionWriter::MarkInterrupted(const std::string& name) {
  const std::string take_dir = TakeDir(name);
  const std::string manifest_path = JoinPath(take_dir, "capture.json");
  FACEDYN_ASSIGN_OR_RETURN(const std::string text, ReadFileToString(manifest_path));
  Json manifest = Json::parse(text, nullptr, false);
  if (!manifest.is_object()) return DataLossError(manifest_path + ": not a JSON object");
  const std::string reason =
      "the process recording it ended before the take stopped (kill, crash or power loss); "
      "the frames on disk are kept";
  manifest["status"] = "interrupted";
  manifest["reason"] = reason;
  // The counts of a take that never stopped are unknown (the frame files say what is there).
  manifest.erase("triggers_emitted");
  if (manifest.contains("cameras") && manifest["cameras"].is_array()) {
    for (Json& camera : manifest["cameras"]) {
      if (camera.is_object()) camera.erase("frames_written");
    }
  }
  manifest["interrupted_found_utc"] = UtcNowIso8601();
  ::unlink(JoinPath(take_dir, kReserveFileName).c_str());
  FACEDYN_RETURN_IF_ERROR(
      WriteFileAtomic(manifest_path, manifest.dump(2, ' ', false, kJsonReplaceInvalidUtf8) + "\n"));
  bool listed = false;
  for (auto& take : session_["takes"]) {
    if (take["name"] == name) {
      take["status"] = "interrupted";
      listed = true;
    }
  }
  if (!listed) {  // killed between writing capture.json and listing the take
    session_["takes"].push_back(
        {{"name", name}, {"dir", "takes/" + name}, {"status", "interrupted"}});
  }
  spdlog::warn("{}: take {} never stopped: marked interrupted", dir_, name);
  return events_->Append({{"event", "take_interrupted"}, {"take", name}, {"reason", reason}});
}

Status SessionWriter::WriteSessionJson() {
  return WriteFileAtomic(JoinPath(dir_, "session.json"),
                         session_.dump(2, ' ', false, kJsonReplaceInvalidUtf8) + "\n");
}

Status SessionWriter::SetCalibration(const std::string& relative_path) {
  if (const std::string why = PathLeavesFolder(relative_path, "session"); !why.empty())
    return InvalidArgumentError("session calibration '" + relative_path + "' " + why);
  session_["calibration"] = relative_path;
  return WriteSessionJson();
}

std::string SessionWriter::TakeDir(const std::string& name) const {
  return JoinPath(JoinPath(dir_, "takes"), name);
}

StatusOr<std::string> SessionWriter::BeginTake(const std::string& name, double fps,
                                               int64_t triggers_requested) {
  if (!IsValidTakeName(name)) {
    return InvalidArgumentError("take name '" + name +
                                "': use letters, digits, '_', '-', '.' (not first)");
  }
  const std::string take_dir = TakeDir(name);
  std::error_code ec;
  if (fs::exists(take_dir, ec)) {
    return InvalidArgumentError("take '" + name + "' already exists in " + dir_ +
                                "; takes are never overwritten");
  }
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(take_dir));
  const int camera_count = static_cast<int>(session_["cameras"].size());
  for (int k = 0; k < camera_count; ++k)
    FACEDYN_RETURN_IF_ERROR(MakeDirectories(JoinPath(take_dir, CameraDirName(k))));
  FACEDYN_RETURN_IF_ERROR(WriteReserve(JoinPath(take_dir, kReserveFileName)));
  TakeResult result;
  result.fps = fps;
  result.triggers_requested = triggers_requested;
  result.start_utc = UtcNowIso8601();
  for (int k = 0; k < camera_count; ++k) {
    TakeCameraResult camera;
    camera.name = session_["cameras"][k]["name"].get<std::string>();
    camera.dir = CameraDirName(k);
    result.cameras.push_back(camera);
  }
  Json manifest = TakeResultToJson(name, result);
  FACEDYN_RETURN_IF_ERROR(
      WriteFileAtomic(JoinPath(take_dir, "capture.json"),
                      manifest.dump(2, ' ', false, kJsonReplaceInvalidUtf8) + "\n"));
  session_["takes"].push_back({{"name", name}, {"dir", "takes/" + name}, {"status", "recording"}});
  FACEDYN_RETURN_IF_ERROR(WriteSessionJson());
  FACEDYN_RETURN_IF_ERROR(events_->Append({{"event", "take_start"},
                                           {"take", name},
                                           {"t_ns", 0},
                                           {"fps", fps},
                                           {"triggers_requested", triggers_requested}}));
  return take_dir;
}

Json TakeResultToJson(const std::string& name, const TakeResult& result) {
  Json cameras = Json::array();
  for (size_t k = 0; k < result.cameras.size(); ++k) {
    const TakeCameraResult& camera = result.cameras[k];
    cameras.push_back({{"index", k},
                       {"name", camera.name},
                       {"dir", camera.dir},
                       {"frame_file", camera.dir + "/" + kFrameFileName},
                       {"frames_written", camera.record.frames_written},
                       {"sync", camera.sync.ToJson()},
                       {"record", camera.record.ToJson()}});
  }
  Json json{{"format", kCaptureTakeFormat},
            {"version", kSessionFormatVersion},
            {"name", name},
            {"status", result.status},
            {"reason", result.reason},
            {"fps", result.fps},
            {"triggers_requested", result.triggers_requested},
            {"triggers_emitted", result.triggers_emitted},
            {"start_utc", result.start_utc},
            {"stop_utc", result.stop_utc.empty() ? Json(nullptr) : Json(result.stop_utc)},
            {"cameras", cameras}};
  for (auto it = result.extra.begin(); it != result.extra.end(); ++it) json[it.key()] = it.value();
  return json;
}

Status SessionWriter::EndTake(const std::string& name, const TakeResult& result) {
  const std::string take_dir = TakeDir(name);
  ::unlink(JoinPath(take_dir, kReserveFileName).c_str());
  Status status = WriteFileAtomic(
      JoinPath(take_dir, "capture.json"),
      TakeResultToJson(name, result).dump(2, ' ', false, kJsonReplaceInvalidUtf8) + "\n");
  for (auto& take : session_["takes"]) {
    if (take["name"] == name) take["status"] = result.status;
  }
  Status session_status = WriteSessionJson();
  Status event_status = events_->Append({{"event", "take_stop"},
                                         {"take", name},
                                         {"status", result.status},
                                         {"reason", result.reason},
                                         {"triggers_emitted", result.triggers_emitted}});
  FACEDYN_RETURN_IF_ERROR(status);
  FACEDYN_RETURN_IF_ERROR(session_status);
  return event_status;
}

// ---------------------------------------------------------------------------- Reading

namespace {

SessionTake ReadTakeManifest(const std::string& session_dir, const std::string& name,
                             int camera_count) {
  SessionTake take;
  take.name = name;
  take.dir = fs::absolute(JoinPath(JoinPath(session_dir, "takes"), name)).string();
  const std::string manifest_path = JoinPath(take.dir, "capture.json");
  auto fallback_cameras = [&] {
    take.cameras.clear();
    for (int k = 0; k < camera_count; ++k) {
      take.cameras.push_back(
          {k, "cam" + std::to_string(k),
           JoinPath(JoinPath(take.dir, SessionWriter::CameraDirName(k)), kFrameFileName), -1, ""});
    }
  };
  StatusOr<ConfigNode> node = ConfigNode::ReadFile(manifest_path);
  if (!node.ok()) {
    take.status = "missing";
    take.reason = node.status().message();
    fallback_cameras();
    return take;
  }
  auto status_text = node->Get<std::string>("status");
  take.status = status_text.ok() ? *status_text : "unreadable";
  take.reason =
      node->GetOr<std::string>("reason", "").ok() ? *node->GetOr<std::string>("reason", "") : "";
  if (auto fps = node->Get<double>("fps"); fps.ok()) take.fps = *fps;
  // Trigger counts size per-trigger arrays downstream (reconstruct/session_input.cc), so a
  // count no take can reach is refused here rather than allocated there.
  auto trigger_count = [&](const char* field, int64_t* out) {
    auto value = node->Get<int64_t>(field);
    if (!value.ok()) return;
    if (*value < 0 || *value > kMaxTriggersPerTake) {
      take.problems.push_back(manifest_path + ": " + field + " " + std::to_string(*value) +
                              " is outside 0.." + std::to_string(kMaxTriggersPerTake) +
                              " (no take is longer); ignored");
      return;
    }
    *out = *value;
  };
  // A take that never stopped has no final count.
  if (take.status != "recording") trigger_count("triggers_emitted", &take.triggers_emitted);
  trigger_count("triggers_requested", &take.triggers_requested);
  take.manifest = node->ToJson();
  auto cameras = node->Child("cameras");
  if (!cameras.ok() || !cameras->IsSequence()) {
    fallback_cameras();
    return take;
  }
  for (size_t k = 0; k < cameras->size(); ++k) {
    auto camera = cameras->At(k);
    SessionTakeCamera entry;
    entry.index = static_cast<int>(k);
    entry.name = camera.ok() && camera->Get<std::string>("name").ok()
                     ? *camera->Get<std::string>("name")
                     : "cam" + std::to_string(k);
    std::string frame_file =
        SessionWriter::CameraDirName(static_cast<int>(k)) + "/" + kFrameFileName;
    if (camera.ok() && camera->Get<std::string>("frame_file").ok())
      frame_file = *camera->Get<std::string>("frame_file");
    if (const std::string why = PathLeavesFolder(frame_file, "take"); !why.empty()) {
      entry.problem = manifest_path + ": cameras[" + std::to_string(k) + "].frame_file '" +
                      frame_file + "' " + why + "; refused (frame files stay in " + take.dir + ")";
    } else {
      entry.frame_file = JoinPath(take.dir, frame_file);
    }
    if (take.status != "recording" && camera.ok() && camera->Get<int64_t>("frames_written").ok()) {
      entry.frames_in_manifest = *camera->Get<int64_t>("frames_written");
    }
    take.cameras.push_back(entry);
  }
  return take;
}

}  // namespace

StatusOr<SessionInfo> ReadSession(const std::string& dir) {
  const std::string path = JoinPath(dir, "session.json");
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode root, ConfigNode::ReadFile(path));
  FACEDYN_ASSIGN_OR_RETURN(const std::string format, root.Get<std::string>("format"));
  if (format != kSessionFormat)
    return root.Error("format", "is '" + format + "', expected '" + kSessionFormat + "'");
  FACEDYN_ASSIGN_OR_RETURN(const int version, root.Get<int>("version"));
  if (version != kSessionFormatVersion) {
    return root.Error("version", std::to_string(version) + " is not supported (this build reads " +
                                     std::to_string(kSessionFormatVersion) + ")");
  }
  SessionInfo info;
  info.dir = fs::absolute(dir).string();
  FACEDYN_ASSIGN_OR_RETURN(info.name, root.Get<std::string>("name"));
  FACEDYN_ASSIGN_OR_RETURN(info.clock, root.Get<std::string>("clock"));
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode cameras, root.Child("cameras"));
  if (!cameras.IsSequence()) return cameras.Error("expected a list of cameras");
  for (size_t k = 0; k < cameras.size(); ++k) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode camera, cameras.At(k));
    SessionCameraInfo entry;
    FACEDYN_ASSIGN_OR_RETURN(entry.name, camera.Get<std::string>("name"));
    FACEDYN_ASSIGN_OR_RETURN(entry.backend, camera.Get<std::string>("backend"));
    FACEDYN_ASSIGN_OR_RETURN(entry.width_px, camera.Get<int>("width_px"));
    FACEDYN_ASSIGN_OR_RETURN(entry.height_px, camera.Get<int>("height_px"));
    FACEDYN_ASSIGN_OR_RETURN(entry.pixel_format, camera.Get<std::string>("pixel_format"));
    info.cameras.push_back(entry);
  }
  FACEDYN_ASSIGN_OR_RETURN(const std::string calibration,
                           root.GetOr<std::string>("calibration", ""));
  if (!calibration.empty()) {
    // Confined like capture.json's frame paths: calibration feeds reconstruct, and a session
    // must not make it read camera models from elsewhere.
    if (const std::string why = PathLeavesFolder(calibration, "session"); !why.empty()) {
      return root.Error("calibration", fmt::format("'{}' {}; refused (the calibration stays in {})",
                                                   calibration, why, info.dir));
    }
    info.calibration_path = JoinPath(info.dir, calibration);
  }
  std::set<std::string> listed;
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode takes, root.Child("takes"));
  for (size_t i = 0; i < takes.size(); ++i) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode take, takes.At(i));
    FACEDYN_ASSIGN_OR_RETURN(const std::string name, take.Get<std::string>("name"));
    if (!IsValidTakeName(name))
      return take.Error("name", "'" + name + "' is not a valid take name");
    listed.insert(name);
    info.takes.push_back(ReadTakeManifest(dir, name, static_cast<int>(info.cameras.size())));
  }
  // Take folders session.json does not list (a crash between mkdir and the session rewrite).
  std::error_code ec;
  std::vector<std::string> unlisted;
  for (const auto& entry : fs::directory_iterator(JoinPath(dir, "takes"), ec)) {
    const std::string name = entry.path().filename().string();
    if (entry.is_directory() && IsValidTakeName(name) && !listed.count(name))
      unlisted.push_back(name);
  }
  std::sort(unlisted.begin(), unlisted.end());
  for (const std::string& name : unlisted) {
    info.takes.push_back(ReadTakeManifest(dir, name, static_cast<int>(info.cameras.size())));
  }
  return info;
}

bool SessionCheck::Complete() const {
  if (!events_problem.empty()) return false;
  for (const TakeCheck& take : takes) {
    if (!take.complete && take.superseded_by.empty()) return false;
  }
  return true;
}

Json SessionCheck::ToJson() const {
  Json json{{"dir", dir},
            {"complete", Complete()},
            {"events", events},
            {"events_problem", events_problem.empty() ? Json(nullptr) : Json(events_problem)}};
  Json list = Json::array();
  for (const TakeCheck& take : takes) {
    Json cameras = Json::array();
    for (const CameraCheck& camera : take.cameras) {
      cameras.push_back(
          {{"name", camera.name},
           {"frames", camera.frames},
           {"unique_triggers", camera.unique_triggers},
           {"missing", camera.missing},
           {"tail_problem",
            camera.tail_problem.empty() ? Json(nullptr) : Json(camera.tail_problem)}});
    }
    list.push_back(
        {{"name", take.name},
         {"status", take.status},
         {"complete", take.complete},
         {"superseded_by", take.superseded_by.empty() ? Json(nullptr) : Json(take.superseded_by)},
         {"problems", take.problems},
         {"cameras", cameras}});
  }
  json["takes"] = list;
  return json;
}

std::string SessionCheck::ToText() const {
  std::ostringstream out;
  out << "session " << dir << ": " << (Complete() ? "complete" : "INCOMPLETE") << ", "
      << takes.size() << " take(s), " << events << " event(s)\n";
  if (!events_problem.empty()) out << "  events.jsonl: " << events_problem << "\n";
  for (const TakeCheck& take : takes) {
    out << "  take " << take.name << ": " << (take.complete ? "complete" : "incomplete")
        << " (status " << take.status << ")";
    if (!take.superseded_by.empty()) out << ", superseded by " << take.superseded_by;
    out << "\n";
    for (const CameraCheck& camera : take.cameras) {
      out << "    " << camera.name << ": " << camera.frames << " frames, " << camera.missing
          << " missing";
      if (!camera.tail_problem.empty()) out << ", " << camera.tail_problem;
      out << "\n";
    }
    for (const std::string& problem : take.problems) out << "    - " << problem << "\n";
  }
  return out.str();
}

StatusOr<SessionCheck> CheckSession(const std::string& dir) {
  FACEDYN_ASSIGN_OR_RETURN(const SessionInfo info, ReadSession(dir));
  SessionCheck check;
  check.dir = info.dir;
  // events.jsonl: every line must parse; a torn last line (crash mid-append) is reported.
  {
    std::ifstream in(JoinPath(dir, "events.jsonl"), std::ios::binary);
    if (!in) {
      check.events_problem = "events.jsonl is missing";
    } else {
      std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      size_t start = 0;
      int line_number = 0;
      while (start < text.size()) {
        const size_t end = text.find('\n', start);
        ++line_number;
        if (end == std::string::npos) {
          check.events_problem =
              "line " + std::to_string(line_number) + " is torn (no newline; a crash mid-append)";
          break;
        }
        if (Json::parse(text.substr(start, end - start), nullptr, false).is_discarded()) {
          check.events_problem = "line " + std::to_string(line_number) + " is not valid JSON";
          break;
        }
        ++check.events;
        start = end + 1;
      }
    }
  }
  for (const SessionTake& take : info.takes) {
    TakeCheck result;
    result.name = take.name;
    result.status = take.status;
    if (take.status != "complete") {
      result.problems.push_back(
          take.status == "recording"
              ? std::string("the take never stopped (interrupted while recording)")
              : "status " + take.status + (take.reason.empty() ? "" : ": " + take.reason));
    }
    result.problems.insert(result.problems.end(), take.problems.begin(), take.problems.end());
    int64_t expected = take.triggers_emitted;
    for (const SessionTakeCamera& camera : take.cameras) {
      CameraCheck camera_check;
      camera_check.name = camera.name;
      if (!camera.problem.empty()) {
        result.problems.push_back(camera.name + ": " + camera.problem);
        result.cameras.push_back(camera_check);
        continue;
      }
      auto reader = FrameFileReader::Open(camera.frame_file);
      if (!reader.ok()) {
        result.problems.push_back(camera.name + ": " + reader.status().message());
        result.cameras.push_back(camera_check);
        continue;
      }
      const FrameFileScan& scan = (*reader)->scan();
      camera_check.frames = static_cast<int64_t>(scan.records.size());
      camera_check.tail_problem = scan.tail_problem;
      std::set<int64_t> triggers;
      for (const FrameRecord& record : scan.records) triggers.insert(record.trigger_index);
      camera_check.unique_triggers = static_cast<int64_t>(triggers.size());
      if (expected >= 0) {
        int64_t present = 0;
        for (int64_t t : triggers) present += (t >= 0 && t < expected);
        camera_check.missing = expected - present;
      }
      if (!scan.tail_problem.empty())
        result.problems.push_back(camera.name + ": " + scan.tail_problem);
      for (const std::string& problem : scan.record_problems)
        result.problems.push_back(camera.name + ": " + problem);
      if (camera.frames_in_manifest >= 0 && camera.frames_in_manifest != camera_check.frames) {
        result.problems.push_back(fmt::format("{}: manifest says {} frames, the file holds {}",
                                              camera.name, camera.frames_in_manifest,
                                              camera_check.frames));
      }
      if (camera_check.missing > 0) {
        result.problems.push_back(fmt::format("{}: {} of {} triggers have no frame", camera.name,
                                              camera_check.missing, expected));
      }
      if (camera_check.unique_triggers != camera_check.frames) {
        result.problems.push_back(fmt::format("{}: {} frames for {} distinct triggers", camera.name,
                                              camera_check.frames, camera_check.unique_triggers));
      }
      result.cameras.push_back(camera_check);
    }
    if (take.triggers_requested >= 0 && take.triggers_emitted >= 0 &&
        take.triggers_emitted < take.triggers_requested) {
      result.problems.push_back(fmt::format("{} of {} requested triggers were emitted",
                                            take.triggers_emitted, take.triggers_requested));
    }
    result.complete = result.problems.empty();
    check.takes.push_back(result);
  }
  // Takes redone by a complete take that says so.
  for (size_t i = 0; i < info.takes.size(); ++i) {
    const Json& manifest = info.takes[i].manifest;
    if (!check.takes[i].complete || !manifest.is_object() || !manifest.contains("supersedes") ||
        !manifest["supersedes"].is_array())
      continue;
    for (const Json& earlier : manifest["supersedes"]) {
      if (!earlier.is_string()) continue;
      for (TakeCheck& take : check.takes) {
        if (take.name == earlier.get<std::string>() && !take.complete && take.superseded_by.empty())
          take.superseded_by = check.takes[i].name;
      }
    }
  }
  return check;
}

}  // namespace facedyn::capture
