#include "rig/rig_config.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>

namespace facedyn::rig {
namespace {

std::string DirectoryOf(const std::string& path) {
  const size_t slash = path.rfind('/');
  return slash == std::string::npos ? "." : path.substr(0, slash);
}

std::string Resolve(const std::string& base_dir, const std::string& path) {
  if (path.empty() || path[0] == '/') return path;
  return base_dir + "/" + path;
}

// Optional number in [min, max]; `value` keeps its default when the field is absent.
Status GetNumber(const ConfigNode& node, const std::string& key, double min, double max,
                 double* value) {
  if (!node.Has(key)) return Status::Ok();
  FACEDYN_ASSIGN_OR_RETURN(*value, node.GetInRange(key, min, max));
  return Status::Ok();
}

Status GetInt(const ConfigNode& node, const std::string& key, int min, int max, int* value) {
  if (!node.Has(key)) return Status::Ok();
  FACEDYN_ASSIGN_OR_RETURN(*value, node.Get<int>(key));
  if (*value < min || *value > max) {
    return node.Error(key,
                      fmt::format("{} is outside the allowed range [{}, {}]", *value, min, max));
  }
  return Status::Ok();
}

Status ParseTransport(const ConfigNode& node, TransportOptions* t) {
  FACEDYN_RETURN_IF_ERROR(CheckKnownFields(
      node, {"kind", "host", "port", "device", "baud", "parity", "data_bits", "stop_bits",
             "rtu_gap_s", "response_timeout_s", "retries", "healthy_after"}));
  FACEDYN_ASSIGN_OR_RETURN(const std::string kind, node.Get<std::string>("kind"));
  if (kind == "tcp") {
    t->kind = TransportOptions::Kind::kTcp;
    FACEDYN_ASSIGN_OR_RETURN(t->host, node.Get<std::string>("host"));
    FACEDYN_ASSIGN_OR_RETURN(t->port, node.Get<int>("port"));
    if (t->port < 1 || t->port > 65535)
      return node.Error("port", fmt::format("{} is outside 1..65535", t->port));
    for (const char* rtu_only :
         {"device", "baud", "parity", "data_bits", "stop_bits", "rtu_gap_s"}) {
      if (node.Has(rtu_only)) return node.Error(rtu_only, "only applies to kind: rtu");
    }
  } else if (kind == "rtu") {
    t->kind = TransportOptions::Kind::kRtu;
    FACEDYN_ASSIGN_OR_RETURN(t->device, node.Get<std::string>("device"));
    FACEDYN_RETURN_IF_ERROR(GetInt(node, "baud", 300, 1000000, &t->baud));
    if (node.Has("parity")) {
      FACEDYN_ASSIGN_OR_RETURN(const std::string parity, node.Get<std::string>("parity"));
      if (parity != "N" && parity != "E" && parity != "O") {
        return node.Error("parity", fmt::format("'{}' is not N, E or O", parity));
      }
      t->parity = parity[0];
    }
    FACEDYN_RETURN_IF_ERROR(GetInt(node, "data_bits", 5, 8, &t->data_bits));
    FACEDYN_RETURN_IF_ERROR(GetInt(node, "stop_bits", 1, 2, &t->stop_bits));
    FACEDYN_RETURN_IF_ERROR(GetNumber(node, "rtu_gap_s", 0.0, 1.0, &t->rtu_gap_s));
    for (const char* tcp_only : {"host", "port"}) {
      if (node.Has(tcp_only)) return node.Error(tcp_only, "only applies to kind: tcp");
    }
  } else {
    return node.Error("kind", fmt::format("'{}' is not tcp or rtu", kind));
  }
  FACEDYN_RETURN_IF_ERROR(
      GetNumber(node, "response_timeout_s", 0.01, 60.0, &t->response_timeout_s));
  FACEDYN_RETURN_IF_ERROR(GetInt(node, "retries", 0, 20, &t->retries));
  FACEDYN_RETURN_IF_ERROR(GetInt(node, "healthy_after", 1, 1000, &t->healthy_after));
  return Status::Ok();
}

Status ParseLimits(const ConfigNode& node, RigLimits* l) {
  FACEDYN_RETURN_IF_ERROR(
      CheckKnownFields(node, {"min_hz", "max_hz", "absolute_max_hz", "motor_max_hz",
                              "max_ramp_hz_per_s", "overspeed_margin_hz"}));
  FACEDYN_RETURN_IF_ERROR(GetNumber(node, "min_hz", 0.1, 100.0, &l->min_hz));
  FACEDYN_RETURN_IF_ERROR(GetNumber(node, "max_hz", 0.1, 100.0, &l->max_hz));
  FACEDYN_RETURN_IF_ERROR(GetNumber(node, "absolute_max_hz", 0.1, 100.0, &l->absolute_max_hz));
  FACEDYN_RETURN_IF_ERROR(GetNumber(node, "motor_max_hz", 0.1, 400.0, &l->motor_max_hz));
  FACEDYN_RETURN_IF_ERROR(GetNumber(node, "max_ramp_hz_per_s", 0.01, 20.0, &l->max_ramp_hz_per_s));
  FACEDYN_RETURN_IF_ERROR(
      GetNumber(node, "overspeed_margin_hz", 0.01, 5.0, &l->overspeed_margin_hz));
  if (l->max_hz < l->min_hz) {
    return node.Error("max_hz", fmt::format("{} Hz is below min_hz {} Hz", l->max_hz, l->min_hz));
  }
  if (l->max_hz > l->absolute_max_hz) {
    return node.Error("max_hz", fmt::format("{} Hz is above absolute_max_hz {} Hz", l->max_hz,
                                            l->absolute_max_hz));
  }
  return Status::Ok();
}

}  // namespace

Status CheckKnownFields(const ConfigNode& node, const std::vector<std::string>& allowed) {
  if (!node.IsMap()) return node.Error("expected a map");
  for (const std::string& key : node.Keys()) {
    if (std::find(allowed.begin(), allowed.end(), key) == allowed.end()) {
      return node.Error(
          key, fmt::format("unknown field (expected one of: {})", fmt::join(allowed, ", ")));
    }
  }
  return Status::Ok();
}

Status RigLimits::Check() const {
  if (!(min_hz > 0.0))
    return InvalidArgumentError(fmt::format("limits.min_hz: {} must be positive", min_hz));
  if (!(max_hz >= min_hz)) {
    return InvalidArgumentError(
        fmt::format("limits.max_hz: {} Hz is below min_hz {} Hz", max_hz, min_hz));
  }
  if (!(absolute_max_hz >= max_hz)) {
    return InvalidArgumentError(fmt::format("limits.max_hz: {} Hz is above absolute_max_hz {} Hz",
                                            max_hz, absolute_max_hz));
  }
  if (!(motor_max_hz > 0.0)) {
    return InvalidArgumentError(
        fmt::format("limits.motor_max_hz: {} must be positive", motor_max_hz));
  }
  if (!(max_ramp_hz_per_s > 0.0)) {
    return InvalidArgumentError(
        fmt::format("limits.max_ramp_hz_per_s: {} must be positive", max_ramp_hz_per_s));
  }
  if (!(overspeed_margin_hz > 0.0)) {
    return InvalidArgumentError(
        fmt::format("limits.overspeed_margin_hz: {} must be positive", overspeed_margin_hz));
  }
  return Status::Ok();
}

Status SafetyOptions::Check() const {
  if (!(control_period_s >= 0.01 && control_period_s <= 1.0)) {
    return InvalidArgumentError(
        fmt::format("safety.control_period_s: {} is outside [0.01, 1] s", control_period_s));
  }
  if (!(comm_watchdog_s == 0.0 || comm_watchdog_s >= 3.0 * control_period_s)) {
    return InvalidArgumentError(fmt::format(
        "safety.comm_watchdog_s: {} s is shorter than 3 control periods ({} s); the drive would "
        "stop between heartbeats",
        comm_watchdog_s, 3.0 * control_period_s));
  }
  if (!(stop_timeout_s > 0.0 && stop_timeout_s <= 600.0)) {
    return InvalidArgumentError(
        fmt::format("safety.stop_timeout_s: {} is outside (0, 600] s", stop_timeout_s));
  }
  if (!(sensor_tolerance_hz >= 0.05 && sensor_tolerance_hz <= 5.0)) {
    return InvalidArgumentError(fmt::format(
        "safety.sensor_tolerance_hz: {} is outside [0.05, 5] Hz", sensor_tolerance_hz));
  }
  return Status::Ok();
}

Status RigConfig::Check() const {
  FACEDYN_RETURN_IF_ERROR(transport.Check());
  FACEDYN_RETURN_IF_ERROR(limits.Check());
  FACEDYN_RETURN_IF_ERROR(platform.Check());
  FACEDYN_RETURN_IF_ERROR(trim.Check());
  FACEDYN_RETURN_IF_ERROR(settle.Check());
  FACEDYN_RETURN_IF_ERROR(safety.Check());
  if (!(amplitude_mm > 0.0 && amplitude_mm <= 50.0)) {
    return InvalidArgumentError(
        fmt::format("platform.amplitude_mm: {} is outside (0, 50] mm", amplitude_mm));
  }
  if (feedback != "sensor" && feedback != "drive_output") {
    return InvalidArgumentError(
        fmt::format("platform.feedback: '{}' is not sensor or drive_output", feedback));
  }
  if (feedback == "sensor" && !profile.oscillation_register) {
    return InvalidArgumentError(
        fmt::format("platform.feedback: 'sensor' needs registers.oscillation_frequency in drive "
                    "profile {} ({}); "
                    "use drive_output",
                    profile.name, profile_path));
  }
  if (profile.comm_watchdog && profile.comm_watchdog->max_s > 0.0 &&
      safety.comm_watchdog_s > profile.comm_watchdog->max_s) {
    return InvalidArgumentError(fmt::format(
        "safety.comm_watchdog_s: {} s is above the {} s the drive's {} allows",
        safety.comm_watchdog_s, profile.comm_watchdog->max_s, profile.comm_watchdog->parameter));
  }
  const PlatformModel model(platform);
  const double top_motor_hz = model.MotorHzFor(limits.max_hz + trim.max_correction_hz);
  if (top_motor_hz > limits.motor_max_hz) {
    return InvalidArgumentError(fmt::format(
        "limits.motor_max_hz: {} Hz is below the {:.2f} Hz the drive needs for max_hz {} Hz plus "
        "the full trim {} Hz at ratio {} and slip {}",
        limits.motor_max_hz, top_motor_hz, limits.max_hz, trim.max_correction_hz, platform.ratio,
        platform.slip));
  }
  // The setpoint is capped at absolute_max_hz / ratio (zero slip, see RigSupervisor): max_hz
  // must be reachable under that cap at the nominal slip.
  const double cap_motor_hz = limits.absolute_max_hz / platform.ratio;
  if (model.MotorHzFor(limits.max_hz) > cap_motor_hz) {
    return InvalidArgumentError(fmt::format(
        "limits.absolute_max_hz: {} Hz leaves no headroom for max_hz {} Hz: at slip {} the "
        "drive needs {:.2f} Hz, above the zero-slip cap {:.2f} Hz; raise absolute_max_hz or "
        "lower max_hz",
        limits.absolute_max_hz, limits.max_hz, platform.slip, model.MotorHzFor(limits.max_hz),
        cap_motor_hz));
  }
  return Status::Ok();
}

DriveLimits RigConfig::MotorLimits() const {
  const PlatformModel model(platform);
  DriveLimits motor;
  motor.window_min_hz = model.MotorHzFor(std::max(0.1, limits.min_hz - trim.max_correction_hz));
  motor.window_max_hz =
      std::min({limits.motor_max_hz, model.MotorHzFor(limits.max_hz + trim.max_correction_hz),
                limits.absolute_max_hz / platform.ratio});
  motor.absolute_max_hz = limits.motor_max_hz;
  return motor;
}

StatusOr<RigConfig> LoadRigConfig(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode root, ConfigNode::ReadFile(path));
  return ParseRigConfig(root, DirectoryOf(path));
}

StatusOr<RigConfig> ParseRigConfig(const ConfigNode& root, const std::string& base_dir) {
  if (!root.IsMap()) return root.Error("a rig config must be a map");
  FACEDYN_RETURN_IF_ERROR(
      CheckKnownFields(root, {"name", "description", "drive_profile", "transport", "limits",
                              "platform", "safety", "sim"}));
  RigConfig c;
  c.source_path = root.source();
  FACEDYN_ASSIGN_OR_RETURN(c.name, root.Get<std::string>("name"));
  FACEDYN_ASSIGN_OR_RETURN(c.description, root.GetOr<std::string>("description", ""));
  FACEDYN_ASSIGN_OR_RETURN(const std::string profile, root.Get<std::string>("drive_profile"));
  c.profile_path = Resolve(base_dir, profile);
  auto loaded = LoadDriveProfile(c.profile_path);
  if (!loaded.ok()) return root.Error("drive_profile", loaded.status().message());
  c.profile = std::move(loaded).value();
  c.transport.unit_id = c.profile.unit_id;

  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode transport, root.Child("transport"));
  FACEDYN_RETURN_IF_ERROR(ParseTransport(transport, &c.transport));

  if (root.Has("limits")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode limits, root.Child("limits"));
    FACEDYN_RETURN_IF_ERROR(ParseLimits(limits, &c.limits));
  }
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode platform, root.Child("platform"));
  FACEDYN_RETURN_IF_ERROR(
      CheckKnownFields(platform, {"ratio", "slip", "amplitude_mm", "feedback", "trim", "settle"}));
  FACEDYN_ASSIGN_OR_RETURN(c.platform.ratio, platform.GetInRange("ratio", 1e-3, 100.0));
  FACEDYN_ASSIGN_OR_RETURN(c.platform.slip, platform.GetInRange("slip", 0.0, 0.49));
  FACEDYN_ASSIGN_OR_RETURN(c.amplitude_mm, platform.GetInRange("amplitude_mm", 0.01, 50.0));
  FACEDYN_ASSIGN_OR_RETURN(c.feedback, platform.Get<std::string>("feedback"));
  if (c.feedback != "sensor" && c.feedback != "drive_output") {
    return platform.Error("feedback",
                          fmt::format("'{}' is not sensor or drive_output", c.feedback));
  }
  if (c.feedback == "sensor" && !c.profile.oscillation_register) {
    return platform.Error("feedback",
                          fmt::format("'sensor' needs registers.oscillation_frequency in "
                                      "drive profile {}; use drive_output",
                                      c.profile_path));
  }
  if (platform.Has("trim")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode trim, platform.Child("trim"));
    FACEDYN_RETURN_IF_ERROR(
        CheckKnownFields(trim, {"enabled", "gain_per_s", "max_correction_hz", "delay_s"}));
    FACEDYN_RETURN_IF_ERROR(GetNumber(trim, "delay_s", 0.0, 30.0, &c.trim.delay_s));
    FACEDYN_ASSIGN_OR_RETURN(c.trim.enabled, trim.GetOr<bool>("enabled", true));
    FACEDYN_RETURN_IF_ERROR(GetNumber(trim, "gain_per_s", 0.0, 20.0, &c.trim.gain_per_s));
    FACEDYN_RETURN_IF_ERROR(
        GetNumber(trim, "max_correction_hz", 0.0, 5.0, &c.trim.max_correction_hz));
  }
  if (platform.Has("settle")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode settle, platform.Child("settle"));
    FACEDYN_RETURN_IF_ERROR(CheckKnownFields(settle, {"tolerance_hz", "time_s"}));
    FACEDYN_RETURN_IF_ERROR(GetNumber(settle, "tolerance_hz", 1e-3, 2.0, &c.settle.tolerance_hz));
    FACEDYN_RETURN_IF_ERROR(GetNumber(settle, "time_s", 0.0, 120.0, &c.settle.time_s));
  }
  if (root.Has("safety")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode safety, root.Child("safety"));
    FACEDYN_RETURN_IF_ERROR(
        CheckKnownFields(safety, {"control_period_s", "comm_watchdog_s", "stop_timeout_s",
                                  "sensor_tolerance_hz"}));
    FACEDYN_RETURN_IF_ERROR(
        GetNumber(safety, "control_period_s", 0.01, 1.0, &c.safety.control_period_s));
    FACEDYN_RETURN_IF_ERROR(
        GetNumber(safety, "comm_watchdog_s", 0.0, 600.0, &c.safety.comm_watchdog_s));
    FACEDYN_RETURN_IF_ERROR(
        GetNumber(safety, "stop_timeout_s", 0.1, 600.0, &c.safety.stop_timeout_s));
    FACEDYN_RETURN_IF_ERROR(
        GetNumber(safety, "sensor_tolerance_hz", 0.05, 5.0, &c.safety.sensor_tolerance_hz));
  }
  const Status valid = c.Check();
  if (!valid.ok())
    return InvalidArgumentError(fmt::format("{}: {}", c.source_path, valid.message()));
  return c;
}

}  // namespace facedyn::rig
