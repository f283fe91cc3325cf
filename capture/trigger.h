// TriggerSource: the one clock every camera of a take is exposed by.
//
// A trigger source emits pulses 0, 1, 2, ... at a fixed rate and calls a sink for each (the
// session runner's sink forwards the pulse to every camera and samples the rig). The pulse
// time is on the session clock, in nanoseconds from the take's arm time.
//
// VirtualTrigger runs on a virtual clock: pulse k is at round(k * 1e9 / rate_hz) ns exactly,
// and the source advances as fast as the sink accepts pulses (pace 0) or at a multiple of real
// time (pace 1 = real time). Simulated stages use pace 0 so a take renders at whatever speed
// the machine manages and still carries exact, deterministic timestamps. A hardware sync
// controller (rig issue) implements the same interface with its own pulse counter.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>

#include "capture/camera.h"
#include "core/status.h"

namespace facedyn::capture {

class TriggerSource {
 public:
  virtual ~TriggerSource() = default;
  virtual double rate_hz() const = 0;
  // True when pulse times are on a virtual clock.
  virtual bool virtual_clock() const = 0;
  // Emits pulses 0 .. count-1, calling `sink` for each in order. Returns the sink's first
  // error, Aborted when Stop() was called, OK after the last pulse.
  virtual Status Run(int64_t count, const std::function<Status(const TriggerEvent&)>& sink) = 0;
  // Makes Run() return after the current pulse. Callable from any thread.
  virtual void Stop() = 0;
  // Pulses emitted by the last Run().
  virtual int64_t emitted() const = 0;
};

struct VirtualTriggerOptions {
  double rate_hz = 128.0;  // 1..10000
  // 0: as fast as the sink accepts; otherwise the multiple of real time to run at.
  double pace = 0.0;

  Status Check() const;
};

class VirtualTrigger : public TriggerSource {
 public:
  explicit VirtualTrigger(const VirtualTriggerOptions& options) : options_(options) {}

  // Time of pulse k on the virtual clock.
  static int64_t PulseTimeNs(int64_t index, double rate_hz);

  double rate_hz() const override { return options_.rate_hz; }
  bool virtual_clock() const override { return true; }
  Status Run(int64_t count, const std::function<Status(const TriggerEvent&)>& sink) override;
  void Stop() override { stop_ = true; }
  int64_t emitted() const override { return emitted_; }

 private:
  VirtualTriggerOptions options_;
  std::atomic<bool> stop_{false};
  std::atomic<int64_t> emitted_{0};
};

}  // namespace facedyn::capture
