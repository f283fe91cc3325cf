#include "rig/usb_controller.h"

#include <fmt/format.h>
#include <libusb.h>

#include <cmath>

namespace facedyn::rig {
namespace {

constexpr uint8_t kVendorOut =
    LIBUSB_REQUEST_TYPE_VENDOR | LIBUSB_RECIPIENT_DEVICE | LIBUSB_ENDPOINT_OUT;
constexpr uint8_t kVendorIn =
    LIBUSB_REQUEST_TYPE_VENDOR | LIBUSB_RECIPIENT_DEVICE | LIBUSB_ENDPOINT_IN;
constexpr int kProtocolVersion = 1;
constexpr int kMaxAccelSamples = 31;

uint16_t Le16(const std::vector<uint8_t>& bytes, size_t at) {
  return static_cast<uint16_t>(bytes[at] | (bytes[at + 1] << 8));
}

Status UsbError(int code, const std::string& what) {
  if (code == LIBUSB_ERROR_PIPE) {
    return FailedPreconditionError(
        fmt::format("{}: not supported by the controller's firmware (stall)", what));
  }
  if (code == LIBUSB_ERROR_NO_DEVICE) {
    return UnavailableError(fmt::format("{}: the controller was unplugged", what));
  }
  return UnavailableError(
      fmt::format("{}: {} ({})", what, libusb_error_name(code), libusb_strerror(code)));
}

}  // namespace

Status UsbControllerOptions::Check() const {
  if (!(timeout_ms > 0 && timeout_ms <= 60000)) {
    return InvalidArgumentError(fmt::format("usb.timeout_ms: {} is outside 1..60000", timeout_ms));
  }
  return Status::Ok();
}

std::string UsbControllerOptions::Describe() const {
  std::string text = fmt::format("{:04x}:{:04x}", vendor_id, product_id);
  if (!serial.empty()) text += " serial " + serial;
  return text;
}

Json UsbControllerInfo::ToJson() const {
  Json json;
  json["protocol_version"] = protocol_version;
  json["has_drive"] = has_drive;
  json["has_accelerometer"] = has_accelerometer;
  json["has_trigger"] = has_trigger;
  json["accelerometer_rate_hz"] = accelerometer_rate_hz;
  json["max_hz"] = max_hz;
  json["firmware_version"] = firmware_version;
  return json;
}

Json UsbControllerStatus::ToJson() const {
  Json json;
  json["running"] = running;
  json["faulted"] = faulted;
  json["fault_code"] = fault_code;
  json["setpoint_hz"] = setpoint_hz;
  json["measured_hz"] = measured_hz;
  json["sequence"] = sequence;
  return json;
}

UsbPlatformController::UsbPlatformController(const UsbControllerOptions& options,
                                             libusb_context* context, libusb_device_handle* handle)
    : options_(options), context_(context), handle_(handle) {}

UsbPlatformController::~UsbPlatformController() {
  if (handle_ != nullptr) libusb_close(handle_);
  if (context_ != nullptr) libusb_exit(context_);
}

StatusOr<std::unique_ptr<UsbPlatformController>> UsbPlatformController::Open(
    const UsbControllerOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  libusb_context* context = nullptr;
  const int init = libusb_init(&context);
  if (init != 0) return UsbError(init, "USB: cannot initialise libusb");
  libusb_device** list = nullptr;
  const ssize_t count = libusb_get_device_list(context, &list);
  if (count < 0) {
    libusb_exit(context);
    return UsbError(static_cast<int>(count), "USB: cannot list devices");
  }
  libusb_device_handle* handle = nullptr;
  Status failure;
  int candidates = 0;
  for (ssize_t i = 0; i < count && handle == nullptr; ++i) {
    libusb_device_descriptor descriptor{};
    if (libusb_get_device_descriptor(list[i], &descriptor) != 0) continue;
    if (descriptor.idVendor != options.vendor_id || descriptor.idProduct != options.product_id)
      continue;
    ++candidates;
    libusb_device_handle* opened = nullptr;
    const int rc = libusb_open(list[i], &opened);
    if (rc != 0) {
      failure =
          rc == LIBUSB_ERROR_ACCESS
              ? UnavailableError(fmt::format("USB platform controller {} on bus {} device {}: "
                                             "permission denied; add a udev rule "
                                             "(SUBSYSTEM==\"usb\", ATTR{{idVendor}}==\"{:04x}\", "
                                             "ATTR{{idProduct}}==\"{:04x}\", "
                                             "MODE=\"0660\", GROUP=\"plugdev\")",
                                             options.Describe(), libusb_get_bus_number(list[i]),
                                             libusb_get_device_address(list[i]), options.vendor_id,
                                             options.product_id))
              : UsbError(
                    rc, fmt::format("USB platform controller {}: cannot open", options.Describe()));
      continue;
    }
    if (!options.serial.empty()) {
      unsigned char serial[128] = {0};
      const int n = descriptor.iSerialNumber == 0
                        ? -1
                        : libusb_get_string_descriptor_ascii(opened, descriptor.iSerialNumber,
                                                             serial, sizeof(serial));
      if (n < 0 || options.serial != reinterpret_cast<char*>(serial)) {
        libusb_close(opened);
        continue;
      }
    }
    handle = opened;
  }
  libusb_free_device_list(list, 1);
  if (handle == nullptr) {
    libusb_exit(context);
    if (!failure.ok()) return failure;
    return NotFoundError(
        fmt::format("no USB platform controller {} found ({} USB device(s) present{}); check that "
                    "it is plugged in and "
                    "powered, and compare with `lsusb`",
                    options.Describe(), count,
                    candidates > 0 ? fmt::format(", {} with this id but another serial", candidates)
                                   : std::string()));
  }
  std::unique_ptr<UsbPlatformController> controller(
      new UsbPlatformController(options, context, handle));
  FACEDYN_ASSIGN_OR_RETURN(const std::vector<uint8_t> info,
                           controller->In(UsbRequest::kGetInfo, 8, "GET_INFO"));
  controller->info_.protocol_version = info[0];
  controller->info_.has_drive = (info[1] & 0x01) != 0;
  controller->info_.has_accelerometer = (info[1] & 0x02) != 0;
  controller->info_.has_trigger = (info[1] & 0x04) != 0;
  controller->info_.accelerometer_rate_hz = Le16(info, 2);
  controller->info_.max_hz = Le16(info, 4) / 100.0;
  controller->info_.firmware_version = Le16(info, 6);
  if (controller->info_.protocol_version != kProtocolVersion) {
    return FailedPreconditionError(
        fmt::format("USB platform controller {}: protocol version {}, facedyn speaks {}",
                    options.Describe(), controller->info_.protocol_version, kProtocolVersion));
  }
  return controller;
}

Status UsbPlatformController::Out(UsbRequest request, uint16_t value, uint16_t index,
                                  const char* name) {
  std::lock_guard<std::mutex> lock(mutex_);
  const int rc =
      libusb_control_transfer(handle_, kVendorOut, static_cast<uint8_t>(request), value, index,
                              nullptr, 0, static_cast<unsigned>(options_.timeout_ms));
  if (rc < 0)
    return UsbError(rc, fmt::format("USB platform controller {}: {}", options_.Describe(), name));
  return Status::Ok();
}

StatusOr<std::vector<uint8_t>> UsbPlatformController::In(UsbRequest request, uint16_t length,
                                                         const char* name) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<uint8_t> bytes(length);
  const int rc =
      libusb_control_transfer(handle_, kVendorIn, static_cast<uint8_t>(request), 0, 0, bytes.data(),
                              length, static_cast<unsigned>(options_.timeout_ms));
  if (rc < 0)
    return UsbError(rc, fmt::format("USB platform controller {}: {}", options_.Describe(), name));
  if (request == UsbRequest::kReadAccel ? rc < 2 : rc != length) {
    return DataLossError(fmt::format("USB platform controller {}: {}: {} of {} bytes",
                                     options_.Describe(), name, rc, length));
  }
  bytes.resize(static_cast<size_t>(rc));
  return bytes;
}

Status UsbPlatformController::SetFrequencyHz(double hz) {
  if (!std::isfinite(hz) || !(hz > 0.0) || hz > info_.max_hz) {
    return InvalidArgumentError(
        fmt::format("hz: {} Hz is outside the controller's range (0, {}] Hz", hz, info_.max_hz));
  }
  return Out(UsbRequest::kSetFrequency, static_cast<uint16_t>(std::lround(hz * 100.0)), 0,
             "SET_FREQUENCY");
}

Status UsbPlatformController::Start() { return Out(UsbRequest::kStart, 0, 0, "START"); }
Status UsbPlatformController::Stop() { return Out(UsbRequest::kStop, 0, 0, "STOP"); }
Status UsbPlatformController::ResetFault() {
  return Out(UsbRequest::kResetFault, 0, 0, "RESET_FAULT");
}

StatusOr<UsbControllerStatus> UsbPlatformController::ReadStatus() {
  FACEDYN_ASSIGN_OR_RETURN(const std::vector<uint8_t> bytes,
                           In(UsbRequest::kGetStatus, 8, "GET_STATUS"));
  UsbControllerStatus status;
  status.running = (bytes[0] & 0x01) != 0;
  status.faulted = (bytes[0] & 0x02) != 0;
  status.fault_code = bytes[1];
  status.setpoint_hz = Le16(bytes, 2) / 100.0;
  status.measured_hz = Le16(bytes, 4) / 100.0;
  status.sequence = Le16(bytes, 6);
  return status;
}

StatusOr<std::vector<double>> UsbPlatformController::ReadAccelerationG() {
  if (!info_.has_accelerometer) {
    return FailedPreconditionError(fmt::format(
        "USB platform controller {}: has no accelerometer (GET_INFO)", options_.Describe()));
  }
  FACEDYN_ASSIGN_OR_RETURN(const std::vector<uint8_t> bytes,
                           In(UsbRequest::kReadAccel, 2 + 2 * kMaxAccelSamples, "READ_ACCEL"));
  const int count = Le16(bytes, 0);
  if (count > kMaxAccelSamples || bytes.size() != static_cast<size_t>(2 + 2 * count)) {
    return DataLossError(
        fmt::format("USB platform controller {}: READ_ACCEL: count {} does not match the {} bytes "
                    "received",
                    options_.Describe(), count, bytes.size()));
  }
  std::vector<double> samples_g(static_cast<size_t>(count));
  for (int i = 0; i < count; ++i)
    samples_g[i] = static_cast<int16_t>(Le16(bytes, 2 + 2 * i)) / 1000.0;
  return samples_g;
}

Status UsbPlatformController::Trigger(int pulses, double period_s) {
  if (!info_.has_trigger) {
    return FailedPreconditionError(
        fmt::format("USB platform controller {}: has no camera trigger output (GET_INFO)",
                    options_.Describe()));
  }
  if (pulses < 1 || pulses > 65535)
    return InvalidArgumentError(fmt::format("pulses: {} is outside 1..65535", pulses));
  const double period_us = std::round(period_s * 1e6);
  if (!(period_us >= 1.0 && period_us <= 65535.0)) {
    return InvalidArgumentError(fmt::format("period_s: {} s is outside 1 us..65.535 ms", period_s));
  }
  return Out(UsbRequest::kTrigger, static_cast<uint16_t>(pulses), static_cast<uint16_t>(period_us),
             "TRIGGER");
}

}  // namespace facedyn::rig
