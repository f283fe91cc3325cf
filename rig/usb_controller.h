// UsbPlatformController: a USB platform/sync controller (a microcontroller board between the PC,
// the platform's drive or motor, an accelerometer on the platform and the cameras' trigger
// input), driven with libusb-1.0 over facedyn's own small vendor protocol.
//
// Vendor protocol, version 1 — every request is a control transfer on endpoint 0 with
// bmRequestType 0x40 (vendor, device, host-to-device) or 0xC0 (device-to-host), wIndex 0 unless
// stated, multi-byte fields little-endian, frequencies in centihertz (0.01 Hz):
//
//   bRequest  dir  wValue           wLength  data
//   0x01      IN   0                8        GET_INFO: u8 protocol version (1), u8 capabilities
//                                            (bit 0 drive, bit 1 accelerometer, bit 2 camera
//                                            trigger), u16 accelerometer rate Hz, u16 maximum
//                                            frequency cHz, u16 firmware version
//   0x10      OUT  frequency cHz    0        SET_FREQUENCY (refused by the device above its max)
//   0x11      OUT  0                0        START
//   0x12      OUT  0                0        STOP (the controller ramps the platform down)
//   0x13      IN   0                8        GET_STATUS: u8 flags (bit 0 running, bit 1 fault),
//                                            u8 fault code, u16 setpoint cHz, u16 measured
//                                            oscillation cHz, u16 sequence number
//   0x14      OUT  0                0        RESET_FAULT
//   0x20      IN   0                2+2n     READ_ACCEL: u16 count n (n <= 31), then n int16
//                                            vertical accelerations in milli-g, oldest first,
//                                            the samples since the previous read
//   0x30      OUT  pulse count      0        TRIGGER: wIndex = pulse period in microseconds;
//                                            the controller pulses the camera trigger line
//
// A request the firmware does not implement STALLs; that is reported as "not supported by
// the controller's firmware". The device is found by vendor and product id (default 1209:0001,
// the pid.codes test id: a real board needs its own) and optionally its serial number string.
// All transfers go through one mutex: libusb's synchronous API may be called from any thread,
// but the protocol's read-since-last-time semantics (READ_ACCEL) want one reader at a time.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/json_io.h"
#include "core/status.h"

struct libusb_context;
struct libusb_device_handle;

namespace facedyn::rig {

struct UsbControllerOptions {
  uint16_t vendor_id = 0x1209;
  uint16_t product_id = 0x0001;
  std::string serial;  // "" = the first matching device
  int timeout_ms = 500;

  Status Check() const;
  std::string Describe() const;  // "1209:0001" (+ " serial X")
};

struct UsbControllerInfo {
  int protocol_version = 0;
  bool has_drive = false;
  bool has_accelerometer = false;
  bool has_trigger = false;
  int accelerometer_rate_hz = 0;
  double max_hz = 0.0;
  int firmware_version = 0;

  Json ToJson() const;
};

struct UsbControllerStatus {
  bool running = false;
  bool faulted = false;
  int fault_code = 0;
  double setpoint_hz = 0.0;
  double measured_hz = 0.0;
  int sequence = 0;

  Json ToJson() const;
};

// Request codes of the vendor protocol (see the header comment).
enum class UsbRequest : uint8_t {
  kGetInfo = 0x01,
  kSetFrequency = 0x10,
  kStart = 0x11,
  kStop = 0x12,
  kGetStatus = 0x13,
  kResetFault = 0x14,
  kReadAccel = 0x20,
  kTrigger = 0x30,
};

class UsbPlatformController {
 public:
  // Finds and opens the controller and reads GET_INFO. No matching device is NotFound (the
  // message says how many USB devices were seen and what to check); a device that cannot be
  // opened (permissions) is Unavailable; a protocol version other than 1 is FailedPrecondition.
  static StatusOr<std::unique_ptr<UsbPlatformController>> Open(const UsbControllerOptions& options);
  ~UsbPlatformController();
  UsbPlatformController(const UsbPlatformController&) = delete;
  UsbPlatformController& operator=(const UsbPlatformController&) = delete;

  // Platform frequency; refused (InvalidArgument naming "hz") outside (0, info().max_hz].
  Status SetFrequencyHz(double hz);
  Status Start();
  Status Stop();
  Status ResetFault();
  StatusOr<UsbControllerStatus> ReadStatus();
  // Vertical acceleration samples in g since the previous read.
  StatusOr<std::vector<double>> ReadAccelerationG();
  // `pulses` trigger pulses every `period_s` seconds (1..65535 pulses, 1 us..65.535 ms).
  Status Trigger(int pulses, double period_s);

  const UsbControllerInfo& info() const { return info_; }
  const UsbControllerOptions& options() const { return options_; }

 private:
  UsbPlatformController(const UsbControllerOptions& options, libusb_context* context,
                        libusb_device_handle* handle);
  Status Out(UsbRequest request, uint16_t value, uint16_t index, const char* name);
  StatusOr<std::vector<uint8_t>> In(UsbRequest request, uint16_t length, const char* name);

  UsbControllerOptions options_;
  libusb_context* context_;
  libusb_device_handle* handle_;
  UsbControllerInfo info_;
  std::mutex mutex_;
};

}  // namespace facedyn::rig
