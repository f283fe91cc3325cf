#include "core/take.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <sstream>

#include <fmt/format.h>

#include "core/config_node.h"
#include "core/csv.h"
#include "core/file_util.h"

namespace facedyn {
namespace {

constexpr char kTransformCsvHeader[] = "frame,time_s,qw,qx,qy,qz,tx,ty,tz";
// Quaternions are written with 9 significant digits; anything further than this from unit
// length was not written by a rigid transform.
constexpr double kUnitQuaternionTolerance = 1e-5;

}  // namespace

void Take::SetUniformTimes() {
  FACEDYN_CHECK(info.fps > 0, "SetUniformTimes needs a positive fps");
  time_s.resize(frame_count());
  for (int f = 0; f < frame_count(); ++f) time_s[f] = f / info.fps;
}

bool IsValidChannelName(const std::string& name) {
  if (name.empty() || name == "positions" || name.size() > 64) return false;
  for (char c : name) {
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_')) return false;
  }
  return true;
}

int FirstHeldFrame(const Take& take) {
  if (!take.info.hold_start_s || !(take.info.fps > 0)) return 0;
  const double frame = std::ceil(*take.info.hold_start_s * take.info.fps - 1e-9);
  return static_cast<int>(std::clamp(frame, 0.0, static_cast<double>(take.frame_count())));
}

Status Take::Validate() const {
  if (!(info.fps > 0) || !std::isfinite(info.fps)) {
    return InvalidArgumentError(fmt::format("take: fps must be positive, got {}", info.fps));
  }
  if (info.hold_start_s && !(*info.hold_start_s >= 0 && std::isfinite(*info.hold_start_s))) {
    return InvalidArgumentError(
        fmt::format("take: hold_start_s must be finite and >= 0, got {}", *info.hold_start_s));
  }
  FACEDYN_RETURN_IF_ERROR(topology.Validate("take topology"));
  if (positions.vertex_count != vertex_count()) {
    return FailedPreconditionError(fmt::format("take: positions have {} vertices, topology has {}",
                                               positions.vertex_count, vertex_count()));
  }
  if (static_cast<int>(world_from_skull.size()) != frame_count()) {
    return FailedPreconditionError(fmt::format("take: {} skull poses for {} frames",
                                               world_from_skull.size(), frame_count()));
  }
  if (static_cast<int>(time_s.size()) != frame_count()) {
    return FailedPreconditionError(
        fmt::format("take: {} frame times for {} frames", time_s.size(), frame_count()));
  }
  if (!skull_from_jaw.empty() && static_cast<int>(skull_from_jaw.size()) != frame_count()) {
    return FailedPreconditionError(
        fmt::format("take: {} jaw poses for {} frames", skull_from_jaw.size(), frame_count()));
  }
  for (const auto& [name, cache] : channels) {
    if (!IsValidChannelName(name)) return InvalidArgumentError("take: bad channel name '" + name + "'");
    if (cache.vertex_count != vertex_count() || cache.frame_count() != frame_count()) {
      return FailedPreconditionError(fmt::format(
          "take: channel '{}' is {} frames x {} vertices, the take is {} x {}", name,
          cache.frame_count(), cache.vertex_count, frame_count(), vertex_count()));
    }
  }
  return Status::Ok();
}

Status WriteTransformCsv(const std::string& path, const std::vector<double>& time_s,
                         const std::vector<Rigid3>& transforms) {
  FACEDYN_CHECK(time_s.size() == transforms.size(), "one time per transform");
  std::string text = std::string(kTransformCsvHeader) + "\n";
  for (size_t f = 0; f < transforms.size(); ++f) {
    const auto& q = transforms[f].rotation();
    const auto& t = transforms[f].translation();
    text += fmt::format("{},{:.9f},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g}\n", f,
                        time_s[f], q.w(), q.x(), q.y(), q.z(), t.x(), t.y(), t.z());
  }
  return WriteFileAtomic(path, text);
}

Status ReadTransformCsv(const std::string& path, std::vector<double>* time_s,
                        std::vector<Rigid3>* transforms) {
  time_s->clear();
  transforms->clear();
  FACEDYN_ASSIGN_OR_RETURN(const CsvTable table, CsvTable::Read(path, kTransformCsvHeader));
  for (size_t row = 0; row < table.row_count(); ++row) {
    const int frame = static_cast<int>(row);
    double v[9];
    for (int i = 0; i < 9; ++i) {
      FACEDYN_ASSIGN_OR_RETURN(v[i], table.Number(row, i));
    }
    if (v[0] != frame) {
      return table.RowError(row, fmt::format("frame number {} where frame {} was expected (frames "
                                             "must be consecutive from 0)",
                                             table.Text(row, 0), frame));
    }
    if (!time_s->empty() && !(v[1] > time_s->back())) {
      return table.RowError(row, fmt::format("frame {}: time {} s does not increase", frame, v[1]));
    }
    const Eigen::Quaterniond q(v[2], v[3], v[4], v[5]);
    if (std::abs(q.norm() - 1.0) > kUnitQuaternionTolerance) {
      return table.RowError(
          row, fmt::format("frame {}: quaternion has norm {:.6f}, expected a unit quaternion", frame, q.norm()));
    }
    time_s->push_back(v[1]);
    transforms->emplace_back(q, Eigen::Vector3d(v[6], v[7], v[8]));
  }
  return Status::Ok();
}

StatusOr<Take> LoadTake(const std::string& dir) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return NotFoundError(dir + ": no such take folder");
  const std::string json_path = JoinPath(dir, "take.json");
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode json, ConfigNode::ReadFile(json_path));
  if (!json.IsMap()) return json.Error("expected a JSON object");

  Take take;
  FACEDYN_ASSIGN_OR_RETURN(const int format_version, json.GetOr<int>("format_version", kTakeFormatVersion));
  if (format_version != kTakeFormatVersion) {
    return json.Error("format_version", fmt::format("version {} is not supported (this facedyn reads {})",
                                                    format_version, kTakeFormatVersion));
  }
  FACEDYN_ASSIGN_OR_RETURN(take.info.fps, json.GetInRange("fps", 1e-3, 1e6));
  FACEDYN_ASSIGN_OR_RETURN(const int frame_count, json.Get<int>("frame_count"));
  FACEDYN_ASSIGN_OR_RETURN(const int vertex_count, json.Get<int>("vertex_count"));
  FACEDYN_ASSIGN_OR_RETURN(const std::string units, json.Get<std::string>("units"));
  if (units != "mm") return json.Error("units", "'" + units + "' is not supported; takes are in mm");
  FACEDYN_ASSIGN_OR_RETURN(take.info.subject, json.GetOr<std::string>("subject", ""));
  FACEDYN_ASSIGN_OR_RETURN(take.info.expression, json.GetOr<std::string>("expression", ""));
  FACEDYN_ASSIGN_OR_RETURN(take.info.motion, json.GetOr<std::string>("motion", ""));
  FACEDYN_ASSIGN_OR_RETURN(take.info.source, json.GetOr<std::string>("source", ""));
  if (json.Has("platform_hz")) {
    FACEDYN_ASSIGN_OR_RETURN(take.info.platform_hz, json.GetInRange("platform_hz", 0.0, 1000.0));
  }
  if (json.Has("hold_start_s")) {
    FACEDYN_ASSIGN_OR_RETURN(take.info.hold_start_s, json.GetInRange("hold_start_s", 0.0, 1e6));
  }
  FACEDYN_ASSIGN_OR_RETURN(const std::vector<std::string> channels,
                           json.GetOr<std::vector<std::string>>("channels", {}));
  if (json.Has("metadata")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode metadata, json.Child("metadata"));
    if (!metadata.IsMap()) return json.Error("metadata", "expected an object");
    take.info.metadata = metadata.ToJson();
  }
  if (frame_count < 0) return json.Error("frame_count", "must not be negative");
  if (vertex_count <= 0) return json.Error("vertex_count", "must be positive");

  const std::string topology_path = JoinPath(dir, "topology.obj");
  FACEDYN_ASSIGN_OR_RETURN(take.topology, ReadMesh(topology_path));
  if (take.topology.vertex_count() != vertex_count) {
    return FailedPreconditionError(fmt::format("{}: has {} vertices but take.json says {}",
                                               topology_path, take.topology.vertex_count(), vertex_count));
  }

  auto load_cache = [&](const std::string& name) -> StatusOr<PointCache> {
    const std::string path = JoinPath(dir, name + ".pc2");
    FACEDYN_ASSIGN_OR_RETURN(PointCache cache, ReadPc2(path));
    if (cache.vertex_count != vertex_count) {
      return FailedPreconditionError(fmt::format("{}: has {} vertices but take.json says {}", path,
                                                 cache.vertex_count, vertex_count));
    }
    if (cache.frame_count() != frame_count) {
      return FailedPreconditionError(fmt::format("{}: has {} frames but take.json says {}", path,
                                                 cache.frame_count(), frame_count));
    }
    return cache;
  };
  FACEDYN_ASSIGN_OR_RETURN(take.positions, load_cache("positions"));

  const std::string skull_path = JoinPath(dir, "skull.csv");
  FACEDYN_RETURN_IF_ERROR(ReadTransformCsv(skull_path, &take.time_s, &take.world_from_skull));
  if (static_cast<int>(take.world_from_skull.size()) != frame_count) {
    return FailedPreconditionError(fmt::format("{}: has {} frames but take.json says {}", skull_path,
                                               take.world_from_skull.size(), frame_count));
  }
  const std::string jaw_path = JoinPath(dir, "jaw.csv");
  if (std::filesystem::exists(jaw_path, ec)) {
    std::vector<double> jaw_times;
    FACEDYN_RETURN_IF_ERROR(ReadTransformCsv(jaw_path, &jaw_times, &take.skull_from_jaw));
    if (static_cast<int>(take.skull_from_jaw.size()) != frame_count) {
      return FailedPreconditionError(fmt::format("{}: has {} frames but take.json says {}", jaw_path,
                                                 take.skull_from_jaw.size(), frame_count));
    }
  }
  for (size_t i = 0; i < channels.size(); ++i) {
    if (!IsValidChannelName(channels[i])) {
      return json.Error("channels", fmt::format("entry {} '{}' is not a valid channel name", i, channels[i]));
    }
    FACEDYN_ASSIGN_OR_RETURN(take.channels[channels[i]], load_cache(channels[i]));
  }
  FACEDYN_RETURN_IF_ERROR(take.Validate().WithContext(dir));
  return take;
}

Status SaveTake(const Take& take, const std::string& dir) {
  FACEDYN_RETURN_IF_ERROR(take.Validate());
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(dir));
  // take.json marks a complete take: remove a stale one first, write it last.
  std::error_code ec;
  std::filesystem::remove(JoinPath(dir, "take.json"), ec);
  FACEDYN_RETURN_IF_ERROR(WriteMesh(take.topology, JoinPath(dir, "topology.obj")));
  FACEDYN_RETURN_IF_ERROR(WritePc2(JoinPath(dir, "positions.pc2"), take.positions));
  FACEDYN_RETURN_IF_ERROR(WriteTransformCsv(JoinPath(dir, "skull.csv"), take.time_s, take.world_from_skull));
  if (!take.skull_from_jaw.empty()) {
    FACEDYN_RETURN_IF_ERROR(WriteTransformCsv(JoinPath(dir, "jaw.csv"), take.time_s, take.skull_from_jaw));
  } else {
    std::filesystem::remove(JoinPath(dir, "jaw.csv"), ec);
  }
  Json channel_names = Json::array();
  for (const auto& [name, cache] : take.channels) {
    FACEDYN_RETURN_IF_ERROR(WritePc2(JoinPath(dir, name + ".pc2"), cache));
    channel_names.push_back(name);
  }
  Json json;
  json["format_version"] = kTakeFormatVersion;
  json["fps"] = take.info.fps;
  json["frame_count"] = take.frame_count();
  json["vertex_count"] = take.vertex_count();
  json["units"] = "mm";
  json["subject"] = take.info.subject;
  json["expression"] = take.info.expression;
  json["motion"] = take.info.motion;
  json["platform_hz"] = take.info.platform_hz ? Json(*take.info.platform_hz) : Json(nullptr);
  if (take.info.hold_start_s) json["hold_start_s"] = *take.info.hold_start_s;
  json["source"] = take.info.source;
  json["channels"] = channel_names;
  json["metadata"] = take.info.metadata.is_object() ? take.info.metadata : Json::object();
  return WriteJsonFile(JoinPath(dir, "take.json"), json);
}

}  // namespace facedyn
