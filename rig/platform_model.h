// The vibrating platform between the drive and the actor: motor electrical frequency to
// platform oscillation frequency, the closed-loop trim that holds the requested platform
// frequency, settle detection, and the actor's cumulative vibration exposure.
//
// The platform is an eccentric mass on an induction motor (directly or through a belt). Its
// oscillation frequency is
//
//     platform_hz = motor_hz * ratio * (1 - slip)
//
// with `ratio` the platform cycles per electrical cycle at zero slip (2 / pole count times the
// pulley ratio; 1 for a 2-pole motor on the shaft) and `slip` the rotor's lag, which grows with
// the load and so is only known approximately. PlatformModel inverts this with the configured
// (nominal) slip; FrequencyTrim then removes what the nominal slip gets wrong by integrating
// the error between the requested and the measured oscillation frequency into a bounded
// correction of the requested frequency. The trim integrates only while the platform is
// actually at its commanded speed (the caller says when), so ramps do not wind it up.
#pragma once

#include <deque>
#include <string>

#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::rig {

struct PlatformModelOptions {
  double ratio = 1.0;  // platform cycles per electrical cycle at zero slip
  double slip = 0.03;  // nominal slip, 0 <= slip < 0.5

  Status Check() const;  // names the field (platform.ratio, platform.slip)
};

class PlatformModel {
 public:
  explicit PlatformModel(const PlatformModelOptions& options) : options_(options) {}
  // motor_hz * ratio * (1 - slip).
  double PlatformHzFor(double motor_hz) const;
  // The inverse: the drive frequency that gives platform_hz at the nominal slip.
  double MotorHzFor(double platform_hz) const;
  const PlatformModelOptions& options() const { return options_; }

 private:
  PlatformModelOptions options_;
};

struct TrimOptions {
  bool enabled = true;
  // Integral gain: the correction changes by gain_per_s * error_hz per second.
  double gain_per_s = 0.8;
  double max_correction_hz = 0.6;  // |correction| bound, platform Hz
  // Time the drive must have been at its setpoint before the trim acts: at least the
  // averaging window of the oscillation measurement, so it sees the speed it is correcting.
  double delay_s = 0.6;

  Status Check() const;
};

// Integral trim: correction_hz += gain_per_s * (target_hz - measured_hz) * dt_s, clamped to
// +-max_correction_hz. The caller adds correction_hz to the requested platform frequency.
class FrequencyTrim {
 public:
  explicit FrequencyTrim(const TrimOptions& options) : options_(options) {}
  void Update(double target_hz, double measured_hz, double dt_s);
  // One-shot correction by the whole measured error (clamped), used once per new target when
  // the platform first reaches speed, so the integral only has to remove what is left.
  void Jump(double target_hz, double measured_hz);
  void Reset() { correction_hz_ = 0.0; }
  double correction_hz() const { return correction_hz_; }
  bool saturated() const;

 private:
  TrimOptions options_;
  double correction_hz_ = 0.0;
};

struct SettleOptions {
  double tolerance_hz = 0.05;  // |measured - target| must stay within this ...
  double time_s = 1.0;         // ... for this long

  Status Check() const;
};

// Settled once every measurement over the last time_s seconds was within tolerance_hz of the
// target and the samples span at least time_s. A new target restarts the detector.
class SettleDetector {
 public:
  explicit SettleDetector(const SettleOptions& options) : options_(options) {}
  void Restart() { since_s_ = -1.0; }
  // `eligible` is false while the controller is still ramping: then the detector restarts.
  void Update(double time_s, double target_hz, double measured_hz, bool eligible);
  bool settled() const { return settled_; }

 private:
  SettleOptions options_;
  double since_s_ = -1.0;  // time of the first in-tolerance sample of the current run
  bool settled_ = false;
};

// Cumulative whole-body vibration exposure of the person on the platform, from the platform's
// frequency and peak displacement amplitude: peak acceleration (2 pi f)^2 A, r.m.s. a = peak /
// sqrt(2) for a sinusoid, dose = integral of a^2 dt, and the energy-equivalent 8-hour value
// A(8) = sqrt(dose / 8 h) as in ISO 2631-1 / Directive 2002/44/EC. The ISO Wk frequency
// weighting is not applied (it is close to 1 between 4 and 12.5 Hz), so A(8) here is an upper
// estimate; compare with the Directive's daily exposure action value 0.5 m/s^2 and limit value
// 1.15 m/s^2.
class VibrationExposure {
 public:
  explicit VibrationExposure(double amplitude_mm) : amplitude_mm_(amplitude_mm) {}
  void Add(double platform_hz, double dt_s);
  // Continues a session from logged totals (sweep --resume), keeping the higher peak.
  void Restore(double vibrating_s, double dose_m2_s3, double peak_rms_m_s2);
  double vibrating_s() const { return vibrating_s_; }
  double dose_m2_s3() const { return dose_m2_s3_; }
  double A8_m_s2() const;
  double peak_rms_m_s2() const { return peak_rms_m_s2_; }
  Json ToJson() const;

 private:
  double amplitude_mm_;
  double vibrating_s_ = 0.0;
  double dose_m2_s3_ = 0.0;
  double peak_rms_m_s2_ = 0.0;
};

}  // namespace facedyn::rig
