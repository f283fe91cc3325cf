// The standing body between the vibrating platform and the head (issue 23: "the body's
// transmissibility to the skull, from skull motion against the platform sensor").
//
// Model: a base-excited single-degree-of-freedom oscillator (what sim/ also uses to move the
// simulated head), plus a head pitch proportional to the head's vertical acceleration:
//   Y_head = T(f) A,   T(f) = (1 + i 2 zeta r) / (1 - r^2 + i 2 zeta r),   r = f / f_body,
//   pitch  = k a_y / g  (rad, k in rad per g).
// Standing-body figures for orientation (sim/skull_motion.cc cites them): resonance near 5 Hz,
// damping ratio 0.3-0.5.
//
// What a capture has, and so what the fit uses: per platform take the rig's measured frequency
// (take.info.platform_hz), the platform's peak displacement A (a property of the rig, its config's
// amplitude_mm; the capture has no platform phase, so only |T| is fitted) and the reconstructed
// skull pose. Per take the skull's vertical displacement and pitch are reduced to phasors at the
// platform frequency over the held frames (physics/harmonic_response.h, constant and drift
// removed); |T| = |Y| / A. Then log f_body and log zeta are fitted to every take's log |T| (Ceres,
// bounded, started from the best point of a grid so the fit does not depend on a guess), with
// standard deviations from the residual variance and the Jacobian, and k by least squares.
// Identifying both body parameters needs at least three distinct frequencies.
#pragma once

#include <complex>
#include <string>
#include <utility>
#include <vector>

#include "core/json_io.h"
#include "core/status.h"
#include "core/take.h"

namespace facedyn::physics {

// Complex steady-state transmissibility T(f) = X_head / X_platform (formula above). |T| peaks
// above 1 near resonance and falls below 1 for r > sqrt(2); arg T is the head's phase lead.
// `resonance_hz` must be > 0.
std::complex<double> BodyTransmissibility(double hz, double resonance_hz, double zeta);

// One platform take as the body fit sees it.
struct BodyTakeResponse {
  std::string name;
  double platform_hz = 0.0;
  double head_vertical_mm = 0.0;  // |Y|, peak
  double transmissibility = 0.0;  // |Y| / A
  double pitch_rad_per_g = 0.0;   // this take's k (real part of pitch / (a_y / g))
  int frames = 0;                 // frames the phasors came from
};

struct BodyFitOptions {
  double platform_amplitude_mm = 0.0;  // A, the rig's peak displacement; must be > 0
  // Bounds of the fitted parameters (also the grid's range).
  double min_resonance_hz = 1.0, max_resonance_hz = 20.0;
  double min_damping_ratio = 0.05, max_damping_ratio = 2.0;
  Status Check() const;
};

struct BodyFit {
  double resonance_hz = 0.0, resonance_hz_stddev = 0.0;
  double damping_ratio = 0.0, damping_ratio_stddev = 0.0;
  double pitch_rad_per_g = 0.0, pitch_rad_per_g_stddev = 0.0;
  double rms_log_residual = 0.0;  // RMS of log |T| model minus measured
  bool at_bound = false;          // a parameter ended on its bound (poorly identified)
  int distinct_frequencies = 0;
  std::vector<BodyTakeResponse> takes;
};

// The take's skull response over its held frames (FirstHeldFrame on). Errors: no platform
// frequency, no skull pose per frame, fewer than 8 frames over two periods, A not > 0, a skull
// that does not move at the platform frequency.
StatusOr<BodyTakeResponse> MeasureBodyResponse(const std::string& name, const Take& take,
                                               double platform_amplitude_mm);

// Fits the body to `takes` (names for messages). Errors: those of MeasureBodyResponse naming the
// take, fewer than three distinct platform frequencies (0.05 Hz apart), bad options.
StatusOr<BodyFit> FitBodyTransmissibility(
    const std::vector<std::pair<std::string, const Take*>>& takes, const BodyFitOptions& options);

// {"model", "resonance_hz", "resonance_hz_sd", "damping_ratio", ..., "takes": [...]}.
Json BodyFitToJson(const BodyFit& fit, double platform_amplitude_mm);

}  // namespace facedyn::physics
