#include "rig/platform_model.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace facedyn::rig {

Status PlatformModelOptions::Check() const {
  if (!(ratio > 0.0 && ratio <= 100.0)) {
    return InvalidArgumentError(fmt::format("platform.ratio: {} is outside (0, 100]", ratio));
  }
  if (!(slip >= 0.0 && slip < 0.5)) {
    return InvalidArgumentError(fmt::format("platform.slip: {} is outside [0, 0.5)", slip));
  }
  return Status::Ok();
}

double PlatformModel::PlatformHzFor(double motor_hz) const {
  return motor_hz * options_.ratio * (1.0 - options_.slip);
}

double PlatformModel::MotorHzFor(double platform_hz) const {
  return platform_hz / (options_.ratio * (1.0 - options_.slip));
}

Status TrimOptions::Check() const {
  if (!(gain_per_s >= 0.0 && gain_per_s <= 20.0)) {
    return InvalidArgumentError(
        fmt::format("platform.trim.gain_per_s: {} is outside [0, 20]", gain_per_s));
  }
  if (!(max_correction_hz >= 0.0 && max_correction_hz <= 5.0)) {
    return InvalidArgumentError(
        fmt::format("platform.trim.max_correction_hz: {} is outside [0, 5] Hz", max_correction_hz));
  }
  if (!(delay_s >= 0.0 && delay_s <= 30.0)) {
    return InvalidArgumentError(
        fmt::format("platform.trim.delay_s: {} is outside [0, 30] s", delay_s));
  }
  return Status::Ok();
}

void FrequencyTrim::Update(double target_hz, double measured_hz, double dt_s) {
  if (!options_.enabled || !(dt_s > 0.0) || !std::isfinite(measured_hz)) return;
  correction_hz_ += options_.gain_per_s * (target_hz - measured_hz) * dt_s;
  correction_hz_ =
      std::clamp(correction_hz_, -options_.max_correction_hz, options_.max_correction_hz);
}

void FrequencyTrim::Jump(double target_hz, double measured_hz) {
  if (!options_.enabled || !std::isfinite(measured_hz)) return;
  correction_hz_ = std::clamp(correction_hz_ + (target_hz - measured_hz),
                              -options_.max_correction_hz, options_.max_correction_hz);
}

bool FrequencyTrim::saturated() const {
  return options_.max_correction_hz > 0.0 &&
         std::abs(correction_hz_) >= options_.max_correction_hz * (1.0 - 1e-9);
}

Status SettleOptions::Check() const {
  if (!(tolerance_hz > 0.0 && tolerance_hz <= 2.0)) {
    return InvalidArgumentError(
        fmt::format("platform.settle.tolerance_hz: {} is outside (0, 2] Hz", tolerance_hz));
  }
  if (!(time_s >= 0.0 && time_s <= 120.0)) {
    return InvalidArgumentError(
        fmt::format("platform.settle.time_s: {} is outside [0, 120] s", time_s));
  }
  return Status::Ok();
}

void SettleDetector::Update(double time_s, double target_hz, double measured_hz, bool eligible) {
  if (!eligible || !(std::abs(measured_hz - target_hz) <= options_.tolerance_hz)) {
    since_s_ = -1.0;
    settled_ = false;
    return;
  }
  if (since_s_ < 0.0) since_s_ = time_s;
  settled_ = time_s - since_s_ >= options_.time_s;
}

void VibrationExposure::Add(double platform_hz, double dt_s) {
  if (!(platform_hz > 0.0) || !(dt_s > 0.0)) return;
  const double omega = 2.0 * M_PI * platform_hz;
  const double rms_m_s2 = omega * omega * amplitude_mm_ * 1e-3 / std::sqrt(2.0);
  vibrating_s_ += dt_s;
  dose_m2_s3_ += rms_m_s2 * rms_m_s2 * dt_s;
  peak_rms_m_s2_ = std::max(peak_rms_m_s2_, rms_m_s2);
}

void VibrationExposure::Restore(double vibrating_s, double dose_m2_s3, double peak_rms_m_s2) {
  vibrating_s_ = vibrating_s;
  dose_m2_s3_ = dose_m2_s3;
  peak_rms_m_s2_ = std::max(peak_rms_m_s2_, peak_rms_m_s2);
}

double VibrationExposure::A8_m_s2() const { return std::sqrt(dose_m2_s3_ / (8.0 * 3600.0)); }

Json VibrationExposure::ToJson() const {
  Json json;
  json["amplitude_mm"] = amplitude_mm_;
  json["vibrating_s"] = vibrating_s_;
  json["dose_m2_s3"] = dose_m2_s3_;
  json["a8_unweighted_m_s2"] = A8_m_s2();
  json["peak_rms_m_s2"] = peak_rms_m_s2_;
  return json;
}

}  // namespace facedyn::rig
