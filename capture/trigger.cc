#include "capture/trigger.h"

#include <chrono>
#include <cmath>
#include <thread>

namespace facedyn::capture {

Status CameraSettings::Check() const {
  if (width_px <= 0 || width_px > 16384)
    return InvalidArgumentError("camera width_px " + std::to_string(width_px) +
                                " is not in 1..16384");
  if (height_px <= 0 || height_px > 16384)
    return InvalidArgumentError("camera height_px " + std::to_string(height_px) +
                                " is not in 1..16384");
  if (exposure_us <= 0)
    return InvalidArgumentError("camera exposure_us " + std::to_string(exposure_us) +
                                " must be positive");
  if (!(fps > 0 && fps <= 10000))
    return InvalidArgumentError("camera fps " + std::to_string(fps) + " is not in (0, 10000]");
  if (exposure_us > 1e6 / fps) {
    return InvalidArgumentError("camera exposure_us " + std::to_string(exposure_us) +
                                " is longer than the frame period at " + std::to_string(fps) +
                                " fps");
  }
  return Status::Ok();
}

Status VirtualTriggerOptions::Check() const {
  if (!(rate_hz >= 1 && rate_hz <= 10000))
    return InvalidArgumentError("trigger rate_hz " + std::to_string(rate_hz) +
                                " is not in 1..10000");
  if (!(pace >= 0 && std::isfinite(pace)))
    return InvalidArgumentError("trigger pace must be >= 0 (0 = as fast as possible)");
  return Status::Ok();
}

int64_t VirtualTrigger::PulseTimeNs(int64_t index, double rate_hz) {
  return std::llround(static_cast<double>(index) * 1e9 / rate_hz);
}

Status VirtualTrigger::Run(int64_t count, const std::function<Status(const TriggerEvent&)>& sink) {
  FACEDYN_RETURN_IF_ERROR(options_.Check());
  stop_ = false;
  emitted_ = 0;
  const auto start = std::chrono::steady_clock::now();
  for (int64_t k = 0; k < count; ++k) {
    if (stop_) return AbortedError("trigger stopped after " + std::to_string(k) + " pulses");
    const TriggerEvent event{k, PulseTimeNs(k, options_.rate_hz)};
    if (options_.pace > 0) {
      std::this_thread::sleep_until(
          start + std::chrono::nanoseconds(static_cast<int64_t>(event.time_ns / options_.pace)));
    }
    emitted_ = k + 1;  // counted before the sink runs: some cameras may have received it
    Status status = sink(event);
    if (!status.ok()) return status;
  }
  return Status::Ok();
}

}  // namespace facedyn::capture
