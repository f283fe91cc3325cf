// DriveClient: frequency, start, stop, fault reset and status of one VFD, in hertz, over a
// ModbusTransport and a DriveProfile.
//
// The client is the last software gate before the motor, so it refuses any setpoint outside
// the configured window (default 6..11 Hz, the platform's useful band) or above the absolute
// maximum, whatever the caller asks. Stop is never refused. A tripped drive is only reset by
// an explicit ResetFault(): silently clearing a trip would hide the reason it tripped.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "core/json_io.h"
#include "core/status.h"
#include "rig/drive_profile.h"
#include "rig/modbus_transport.h"

namespace facedyn::rig {

struct DriveLimits {
  double window_min_hz = 6.0;
  double window_max_hz = 11.0;
  // Hard ceiling independent of the window (e.g. the platform's mechanical limit).
  double absolute_max_hz = 11.0;

  Status Check() const;  // names the field
};

struct DriveStatus {
  bool running = false;
  bool faulted = false;
  int fault_code = 0;
  std::string fault_text;  // profile's text for fault_code, "" when not faulted
  double output_hz = 0.0;
  uint16_t status_word = 0;

  Json ToJson() const;
};

// The status a drive reports, decoded from the register values it returned: the status word,
// the output-frequency register and, when the profile has a separate fault-code register, that
// register's value (nullopt: the code is read out of the status word, or the profile has none).
// Any 16-bit values are accepted: a drive's reply is outside input.
DriveStatus DecodeDriveStatus(const DriveProfile& profile, uint16_t status_word,
                              uint16_t output_frequency_word,
                              std::optional<uint16_t> fault_code_word);

class DriveClient {
 public:
  // `transport` must outlive the client.
  DriveClient(ModbusTransport* transport, DriveProfile profile, DriveLimits limits = DriveLimits());

  // Writes the frequency setpoint; InvalidArgument naming "hz" and the value when outside the
  // window or above absolute_max_hz (nothing is written then).
  Status SetFrequencyHz(double hz);
  Status Start();
  Status Stop();
  // Writes the profile's fault-reset sequence.
  Status ResetFault();
  StatusOr<DriveStatus> ReadStatus();

  const DriveProfile& profile() const { return profile_; }
  const DriveLimits& limits() const { return limits_; }

 private:
  ModbusTransport* transport_;
  DriveProfile profile_;
  DriveLimits limits_;
};

}  // namespace facedyn::rig
