// RigConfig: one platform rig as deployed — which drive (a DriveProfile), how to reach it (a
// TransportOptions), the platform's mechanics, the frequency limits and the safety settings —
// read from config/rigs/*.yaml. Every value is validated on load and an error names the file,
// line and field; unknown fields are refused so a misspelt limit cannot silently fall back to
// its default.
#pragma once

#include <string>

#include "core/config_node.h"
#include "core/status.h"
#include "rig/drive_client.h"
#include "rig/drive_profile.h"
#include "rig/modbus_transport.h"
#include "rig/platform_model.h"

namespace facedyn::rig {

// Platform-side frequency limits (oscillation Hz) and drive-side ceiling (motor Hz).
struct RigLimits {
  double min_hz = 6.0;               // requests below are refused
  double max_hz = 11.0;              // requests above are refused
  double absolute_max_hz = 11.0;     // never exceeded, whatever max_hz says
  double motor_max_hz = 13.0;        // the drive setpoint never exceeds this (motor Hz)
  double max_ramp_hz_per_s = 1.0;    // platform frequency changes no faster than this
  double overspeed_margin_hz = 0.3;  // measured > absolute_max_hz + margin: stop

  Status Check() const;
};

struct SafetyOptions {
  double control_period_s = 0.1;  // heartbeat and control loop period
  // Written to the drive's comm-watchdog parameter where the profile has a register for it
  // (0: leave the drive's setting alone). The drive stops on its own when facedyn goes silent
  // for this long. Must be at least 3 control periods.
  double comm_watchdog_s = 1.0;
  double stop_timeout_s = 20.0;  // how long one stop command may take to reach standstill
  // With feedback "sensor": once the drive output is steady, the oscillation sensor and the
  // drive's own output frequency (through the nominal platform model) must agree within this;
  // beyond it one of them is wrong and the platform is stopped. It must exceed the model's
  // slip error (trim.max_correction_hz is a fair guide).
  double sensor_tolerance_hz = 0.8;

  Status Check() const;
};

struct RigConfig {
  std::string name;
  std::string description;
  std::string source_path;
  std::string profile_path;  // resolved against the rig file's folder
  DriveProfile profile;
  TransportOptions transport;
  RigLimits limits;
  PlatformModelOptions platform;
  double amplitude_mm = 2.0;  // platform peak displacement, for the exposure figure
  // Where the measured oscillation frequency comes from: "sensor" (the profile's
  // oscillation_frequency register) or "drive_output" (output frequency through the nominal
  // model: corrects the drive's own setpoint error only, not the slip).
  std::string feedback = "sensor";
  TrimOptions trim;
  SettleOptions settle;
  SafetyOptions safety;

  // Cross-field checks (limits against each other, feedback against the profile).
  Status Check() const;
  // The drive-side (motor Hz) limits DriveClient enforces, derived from the platform limits.
  DriveLimits MotorLimits() const;
};

StatusOr<RigConfig> LoadRigConfig(const std::string& path);
StatusOr<RigConfig> ParseRigConfig(const ConfigNode& root, const std::string& base_dir);

// Refuses keys of `node` (a map) not in `allowed`, naming the first one and the allowed set.
Status CheckKnownFields(const ConfigNode& node, const std::vector<std::string>& allowed);

}  // namespace facedyn::rig
