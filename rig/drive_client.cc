#include "rig/drive_client.h"

#include <fmt/format.h>

#include <cmath>
#include <utility>

#include "core/check.h"

namespace facedyn::rig {

Status DriveLimits::Check() const {
  if (!(window_min_hz > 0.0)) {
    return InvalidArgumentError(
        fmt::format("limits.window_min_hz: {} must be positive", window_min_hz));
  }
  if (!(window_max_hz >= window_min_hz)) {
    return InvalidArgumentError(fmt::format("limits.window_max_hz: {} is below window_min_hz {}",
                                            window_max_hz, window_min_hz));
  }
  if (!(absolute_max_hz > 0.0) || !std::isfinite(absolute_max_hz)) {
    return InvalidArgumentError(
        fmt::format("limits.absolute_max_hz: {} must be positive", absolute_max_hz));
  }
  return Status::Ok();
}

Json DriveStatus::ToJson() const {
  Json json;
  json["running"] = running;
  json["faulted"] = faulted;
  json["fault_code"] = fault_code;
  json["fault_text"] = fault_text;
  json["output_hz"] = output_hz;
  json["status_word"] = status_word;
  return json;
}

DriveClient::DriveClient(ModbusTransport* transport, DriveProfile profile, DriveLimits limits)
    : transport_(transport), profile_(std::move(profile)), limits_(limits) {
  FACEDYN_CHECK(transport_ != nullptr, "DriveClient needs a transport");
}

Status DriveClient::SetFrequencyHz(double hz) {
  if (!std::isfinite(hz)) return InvalidArgumentError(fmt::format("hz: {} is not a number", hz));
  if (hz > limits_.absolute_max_hz) {
    return InvalidArgumentError(
        fmt::format("hz: {} Hz is above the configured maximum {} Hz "
                    "(limits.absolute_max_hz)",
                    hz, limits_.absolute_max_hz));
  }
  if (hz < limits_.window_min_hz || hz > limits_.window_max_hz) {
    return InvalidArgumentError(fmt::format("hz: {} Hz is outside the allowed window {}..{} Hz", hz,
                                            limits_.window_min_hz, limits_.window_max_hz));
  }
  FACEDYN_ASSIGN_OR_RETURN(const uint16_t counts,
                           profile_.setpoint_scaling.HzToRegister(hz, profile_.name + " setpoint"));
  return transport_->WriteRegister(profile_.setpoint_register, counts)
      .WithContext(fmt::format("drive {} set {} Hz", profile_.name, hz));
}

Status DriveClient::Start() {
  return transport_->WriteRegister(profile_.command_register, profile_.run_value)
      .WithContext(fmt::format("drive {} start", profile_.name));
}

Status DriveClient::Stop() {
  return transport_->WriteRegister(profile_.command_register, profile_.stop_value)
      .WithContext(fmt::format("drive {} stop", profile_.name));
}

Status DriveClient::ResetFault() {
  for (const uint16_t value : profile_.fault_reset_values) {
    FACEDYN_RETURN_IF_ERROR(transport_->WriteRegister(profile_.fault_reset_register, value)
                                .WithContext(fmt::format("drive {} fault reset", profile_.name)));
  }
  return Status::Ok();
}

DriveStatus DecodeDriveStatus(const DriveProfile& profile, uint16_t status_word,
                              uint16_t output_frequency_word,
                              std::optional<uint16_t> fault_code_word) {
  DriveStatus status;
  status.status_word = status_word;
  status.output_hz = profile.output_scaling.RegisterToHz(output_frequency_word);
  if (profile.fault_code_register) {
    status.fault_code = profile.FaultCodeFrom(fault_code_word ? *fault_code_word : status_word);
  }
  status.faulted = profile.IsFaultBitSet(status.status_word) || status.fault_code != 0;
  status.running = !status.faulted && profile.IsRunning(status.status_word);
  if (status.faulted) status.fault_text = profile.DescribeFault(status.fault_code);
  return status;
}

StatusOr<DriveStatus> DriveClient::ReadStatus() {
  const std::string context = fmt::format("drive {} status", profile_.name);
  auto status_words = transport_->ReadRegisters(profile_.status_register, 1);
  if (!status_words.ok()) return status_words.status().WithContext(context);
  auto output_words = transport_->ReadRegisters(profile_.output_frequency_register, 1);
  if (!output_words.ok()) return output_words.status().WithContext(context);
  std::optional<uint16_t> fault_word;
  if (profile_.fault_code_register && *profile_.fault_code_register != profile_.status_register) {
    auto words = transport_->ReadRegisters(*profile_.fault_code_register, 1);
    if (!words.ok()) return words.status().WithContext(context);
    fault_word = (*words)[0];
  }
  return DecodeDriveStatus(profile_, (*status_words)[0], (*output_words)[0], fault_word);
}

}  // namespace facedyn::rig
