#include "rig/drive_profile.h"

#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>

namespace facedyn::rig {
namespace {

constexpr int kMaxAddress = 0xFFFF;

// A non-negative integer written in decimal or 0x hex. ConfigNode's integers are decimal only,
// and register maps are published in hex, so this reads the scalar text itself.
StatusOr<long> ParseUnsigned(const ConfigNode& node, long max_value) {
  FACEDYN_ASSIGN_OR_RETURN(const std::string text, node.As<std::string>());
  if (text.empty() || text[0] == '-' || text[0] == '+') {
    return node.Error(
        fmt::format("expected a non-negative integer (decimal or 0x hex), got '{}'", text));
  }
  errno = 0;
  char* end = nullptr;
  const long value = std::strtol(text.c_str(), &end, 0);
  if (errno != 0 || end == text.c_str() || *end != '\0') {
    return node.Error(fmt::format("expected an integer (decimal or 0x hex), got '{}'", text));
  }
  if (value > max_value) {
    return node.Error(fmt::format("value {} is above the maximum {}", text, max_value));
  }
  return value;
}

StatusOr<int> GetAddress(const ConfigNode& map, const std::string& key) {
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode child, map.Child(key));
  FACEDYN_ASSIGN_OR_RETURN(const long value, ParseUnsigned(child, kMaxAddress));
  return static_cast<int>(value);
}

StatusOr<uint16_t> GetWord(const ConfigNode& map, const std::string& key) {
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode child, map.Child(key));
  FACEDYN_ASSIGN_OR_RETURN(const long value, ParseUnsigned(child, 0xFFFF));
  return static_cast<uint16_t>(value);
}

StatusOr<uint16_t> GetWordOr(const ConfigNode& map, const std::string& key, uint16_t fallback) {
  if (!map.Has(key)) return fallback;
  return GetWord(map, key);
}

StatusOr<FrequencyScaling> ParseScaling(const ConfigNode& root, const std::string& key) {
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode node, root.Child(key));
  FrequencyScaling scaling;
  FACEDYN_ASSIGN_OR_RETURN(scaling.counts, node.GetInRange("counts", 1e-9, 65535.0));
  FACEDYN_ASSIGN_OR_RETURN(scaling.hz, node.GetInRange("hz", 1e-9, 10000.0));
  FACEDYN_ASSIGN_OR_RETURN(scaling.is_signed, node.GetOr<bool>("signed", false));
  return scaling;
}

}  // namespace

StatusOr<uint16_t> FrequencyScaling::HzToRegister(double frequency_hz,
                                                  const std::string& what) const {
  if (!std::isfinite(frequency_hz)) {
    return InvalidArgumentError(
        fmt::format("{}: frequency {} Hz is not a number", what, frequency_hz));
  }
  const double counts_value = std::round(frequency_hz * CountsPerHz());
  const double low = is_signed ? -32768.0 : 0.0;
  const double high = is_signed ? 32767.0 : 65535.0;
  if (counts_value < low || counts_value > high) {
    return InvalidArgumentError(fmt::format(
        "{}: {} Hz is {} counts, which does not fit the 16-bit register ({}..{}, {} counts per Hz)",
        what, frequency_hz, counts_value, low, high, CountsPerHz()));
  }
  return static_cast<uint16_t>(static_cast<int32_t>(counts_value) & 0xFFFF);
}

double FrequencyScaling::RegisterToHz(uint16_t value) const {
  const double counts_value =
      is_signed ? static_cast<double>(static_cast<int16_t>(value)) : static_cast<double>(value);
  return counts_value / CountsPerHz();
}

int DriveProfile::MaxRegister() const {
  int highest = std::max({command_register, setpoint_register, status_register,
                          output_frequency_register, fault_reset_register});
  if (fault_code_register) highest = std::max(highest, *fault_code_register);
  if (oscillation_register) highest = std::max(highest, *oscillation_register);
  if (comm_watchdog && comm_watchdog->register_address) {
    highest = std::max(highest, *comm_watchdog->register_address);
  }
  return highest;
}

std::string DriveProfile::DescribeFault(int code) const {
  const auto it = fault_codes.find(code);
  if (it == fault_codes.end()) return fmt::format("{} (unknown to profile {})", code, name);
  return fmt::format("{} ({})", code, it->second);
}

bool DriveProfile::IsRunning(uint16_t status_word) const {
  return (status_word & running_mask) == running_value;
}

bool DriveProfile::IsFaultBitSet(uint16_t status_word) const {
  return fault_mask != 0 && (status_word & fault_mask) != 0;
}

int DriveProfile::FaultCodeFrom(uint16_t fault_register_value) const {
  return (fault_register_value & fault_code_mask) >> fault_code_shift;
}

StatusOr<DriveProfile> LoadDriveProfile(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode root, ConfigNode::ReadFile(path));
  return ParseDriveProfile(root);
}

StatusOr<DriveProfile> ParseDriveProfile(const ConfigNode& root) {
  if (!root.IsMap()) return root.Error("a drive profile must be a map");
  DriveProfile p;
  p.source_path = root.source();
  FACEDYN_ASSIGN_OR_RETURN(p.name, root.Get<std::string>("name"));
  FACEDYN_ASSIGN_OR_RETURN(p.description, root.GetOr<std::string>("description", ""));
  FACEDYN_ASSIGN_OR_RETURN(p.unit_id, root.GetOr<int>("unit_id", 1));
  if (p.unit_id < 0 || p.unit_id > 247) {
    return root.Error("unit_id",
                      fmt::format("{} is outside the Modbus unit range 0..247", p.unit_id));
  }

  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode registers, root.Child("registers"));
  FACEDYN_ASSIGN_OR_RETURN(p.command_register, GetAddress(registers, "command"));
  FACEDYN_ASSIGN_OR_RETURN(p.setpoint_register, GetAddress(registers, "setpoint"));
  FACEDYN_ASSIGN_OR_RETURN(p.status_register, GetAddress(registers, "status"));
  FACEDYN_ASSIGN_OR_RETURN(p.output_frequency_register, GetAddress(registers, "output_frequency"));
  if (registers.Has("fault_code")) {
    FACEDYN_ASSIGN_OR_RETURN(p.fault_code_register, GetAddress(registers, "fault_code"));
  }
  if (registers.Has("oscillation_frequency")) {
    FACEDYN_ASSIGN_OR_RETURN(p.oscillation_register,
                             GetAddress(registers, "oscillation_frequency"));
    FACEDYN_ASSIGN_OR_RETURN(p.oscillation_scaling, ParseScaling(root, "oscillation_scaling"));
  }
  // Command and setpoint are written; sharing an address would make one overwrite the other.
  if (p.command_register == p.setpoint_register) {
    return registers.Error(
        "setpoint", fmt::format("address {} is also the command register", p.setpoint_register));
  }

  FACEDYN_ASSIGN_OR_RETURN(p.setpoint_scaling, ParseScaling(root, "setpoint_scaling"));
  FACEDYN_ASSIGN_OR_RETURN(p.output_scaling, ParseScaling(root, "output_scaling"));

  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode command, root.Child("command"));
  FACEDYN_ASSIGN_OR_RETURN(p.run_value, GetWord(command, "run"));
  FACEDYN_ASSIGN_OR_RETURN(p.stop_value, GetWord(command, "stop"));
  if (p.run_value == p.stop_value) {
    return command.Error("stop", fmt::format("equals the run value {}", p.run_value));
  }
  p.fault_reset_register = p.command_register;
  if (command.Has("fault_reset_register")) {
    FACEDYN_ASSIGN_OR_RETURN(p.fault_reset_register, GetAddress(command, "fault_reset_register"));
  }
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode resets, command.Child("fault_reset"));
  if (!resets.IsSequence() || resets.size() == 0) {
    return resets.Error("expected a non-empty list of values written in order");
  }
  for (size_t i = 0; i < resets.size(); ++i) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode item, resets.At(i));
    FACEDYN_ASSIGN_OR_RETURN(const long value, ParseUnsigned(item, 0xFFFF));
    p.fault_reset_values.push_back(static_cast<uint16_t>(value));
  }

  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode status, root.Child("status"));
  FACEDYN_ASSIGN_OR_RETURN(p.running_mask, GetWord(status, "running_mask"));
  FACEDYN_ASSIGN_OR_RETURN(p.running_value, GetWord(status, "running_value"));
  FACEDYN_ASSIGN_OR_RETURN(p.fault_mask, GetWordOr(status, "fault_mask", 0));
  if (p.running_mask == 0) return status.Error("running_mask", "must select at least one bit");
  if ((p.running_value & ~p.running_mask) != 0) {
    return status.Error("running_value",
                        fmt::format("0x{:04X} has bits outside running_mask 0x{:04X}",
                                    p.running_value, p.running_mask));
  }

  if (root.Has("fault_code")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode fault, root.Child("fault_code"));
    FACEDYN_ASSIGN_OR_RETURN(p.fault_code_mask, GetWordOr(fault, "mask", 0xFFFF));
    FACEDYN_ASSIGN_OR_RETURN(p.fault_code_shift, fault.GetOr<int>("shift", 0));
    if (p.fault_code_shift < 0 || p.fault_code_shift > 15) {
      return fault.Error("shift", fmt::format("{} is outside 0..15", p.fault_code_shift));
    }
  }
  if (!p.fault_code_register && p.fault_mask == 0) {
    return root.Error("registers",
                      "a profile needs registers.fault_code or status.fault_mask, "
                      "or a trip could never be seen");
  }
  if (root.Has("fault_codes")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode codes, root.Child("fault_codes"));
    if (!codes.IsMap()) return codes.Error("expected a map of code: text");
    for (const std::string& key : codes.Keys()) {
      FACEDYN_ASSIGN_OR_RETURN(const ConfigNode text_node, codes.Child(key));
      char* end = nullptr;
      const long parsed = std::strtol(key.c_str(), &end, 0);
      if (key.empty() || *end != '\0' || parsed < 0 || parsed > 0xFFFF) {
        return codes.Error(key, "fault code keys must be integers 0..65535");
      }
      FACEDYN_ASSIGN_OR_RETURN(p.fault_codes[static_cast<int>(parsed)],
                               text_node.As<std::string>());
    }
  }

  if (root.Has("comm_watchdog")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode wd, root.Child("comm_watchdog"));
    CommWatchdog watchdog;
    FACEDYN_ASSIGN_OR_RETURN(watchdog.parameter, wd.Get<std::string>("parameter"));
    if (wd.Has("register")) {
      FACEDYN_ASSIGN_OR_RETURN(watchdog.register_address, GetAddress(wd, "register"));
    }
    FACEDYN_ASSIGN_OR_RETURN(watchdog.counts_per_s, wd.GetOr<double>("counts_per_s", 1.0));
    FACEDYN_ASSIGN_OR_RETURN(watchdog.max_s, wd.GetOr<double>("max_s", 0.0));
    if (watchdog.counts_per_s <= 0.0) return wd.Error("counts_per_s", "must be positive");
    p.comm_watchdog = watchdog;
  }
  return p;
}

}  // namespace facedyn::rig
