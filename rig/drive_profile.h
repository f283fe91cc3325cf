// DriveProfile: one VFD family's Modbus register map, read from config/drives/*.yaml.
//
// A profile says where the command word, frequency setpoint, status word, output frequency
// and fault code live, how Hz map to register counts, which command values run, stop and
// reset the drive, and how to read "running" and "faulted" out of the status word. Keeping
// this as data (not one class per vendor) lets the client, the simulated drive and the tests
// share one map per drive, and lets a user add a drive without a rebuild.
//
// Addresses are Modbus PDU addresses, exactly as sent on the wire (0-based); a profile file
// notes how they relate to the manual's numbering. Numbers may be written in decimal or 0x hex.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/config_node.h"
#include "core/status.h"

namespace facedyn::rig {

// Linear Hz <-> register counts: `counts` counts equal `hz` hertz (Delta: 100 per 1 Hz;
// Siemens V20: 16384 per P2000 reference frequency).
struct FrequencyScaling {
  double counts = 100.0;
  double hz = 1.0;
  bool is_signed = false;  // the register is a two's-complement int16 (V20 HIW)

  double CountsPerHz() const { return counts / hz; }
  // Hz -> register value, rounded to the nearest count; refuses values that do not fit the
  // 16-bit register (0..65535, or -32768..32767 when signed). `what` names the field.
  StatusOr<uint16_t> HzToRegister(double frequency_hz, const std::string& what) const;
  double RegisterToHz(uint16_t value) const;
};

struct CommWatchdog {
  std::string parameter;                // the drive's parameter name, for messages and docs
  std::optional<int> register_address;  // when the watchdog can be written over Modbus
  double counts_per_s = 1.0;
  double max_s = 0.0;
};

struct DriveProfile {
  std::string name;
  std::string description;
  std::string source_path;  // the file it was read from, for messages
  int unit_id = 1;

  int command_register = 0;
  int setpoint_register = 0;
  int status_register = 0;
  int output_frequency_register = 0;
  std::optional<int> fault_code_register;
  // The platform's measured oscillation frequency (an accelerometer or proximity sensor wired
  // to the drive or a PLC), when the map has one; the closed-loop trim reads it.
  std::optional<int> oscillation_register;

  FrequencyScaling setpoint_scaling;
  FrequencyScaling output_scaling;
  FrequencyScaling oscillation_scaling;  // meaningful when oscillation_register is set

  uint16_t run_value = 0;
  uint16_t stop_value = 0;
  int fault_reset_register = 0;              // defaults to command_register
  std::vector<uint16_t> fault_reset_values;  // written in order (edge-triggered resets)

  uint16_t running_mask = 0;
  uint16_t running_value = 0;
  uint16_t fault_mask = 0;  // 0: the status word has no fault bit; a non-zero code means a trip

  uint16_t fault_code_mask = 0xFFFF;
  int fault_code_shift = 0;
  std::map<int, std::string> fault_codes;  // code -> text

  std::optional<CommWatchdog> comm_watchdog;

  // Highest register address the profile touches (for sizing a simulated register map).
  int MaxRegister() const;
  // "<code> (<text>)" or "<code> (unknown to profile <name>)".
  std::string DescribeFault(int code) const;
  // Decoding of a status word and the fault-code register (which may be the same register).
  bool IsRunning(uint16_t status_word) const;
  bool IsFaultBitSet(uint16_t status_word) const;
  int FaultCodeFrom(uint16_t fault_register_value) const;
};

// Reads and validates a profile; every error names file, line and field.
StatusOr<DriveProfile> LoadDriveProfile(const std::string& path);
StatusOr<DriveProfile> ParseDriveProfile(const ConfigNode& root);

}  // namespace facedyn::rig
