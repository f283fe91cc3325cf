// Baselines every dynamics figure is reported against (issue 4): what a quasistatic estimate
// must beat to be worth a network.
//   - no removal: the dynamic input itself (error = the dynamic offset);
//   - low-pass: a zero-phase low-pass filter of the stabilised vertex positions
//     T(t)^-1 x(t), re-posed with T(t) — what a user would try first. A 2nd-order Butterworth
//     (bilinear transform, cutoff pre-warped) run forward then backward over time, so the
//     phase is zero and the magnitude response is |H|^2 (-6 dB at the cutoff, default 4 Hz:
//     below the 6-11 Hz platform band, above expression changes of about 1 Hz);
//   - moving average: Eq. (5) of Zoss et al. 2020 itself (quasistatic.h).
// Ends follow the policy of features.h: the signal is extended by replicating its first and
// last frames (padding of two cutoff periods, filter state started at steady state), so a
// constant take passes unchanged and nothing is read outside the arrays.
#pragma once

#include <string>
#include <vector>

#include "core/pc2.h"
#include "core/rigid3.h"
#include "core/status.h"
#include "core/take.h"

namespace facedyn::dynamics {

enum class BaselineKind { kNoRemoval, kLowPass, kMovingAverage };

// "no_removal", "lowpass", "moving_average".
const char* BaselineName(BaselineKind kind);

struct BaselineOptions {
  // Low-pass cutoff (Hz, in (0, fps / 2)); 0, the default, picks it per take by the rule of
  // LowPassCutoffByRule. Round 1 fixed it at 4 Hz for every take, walks included.
  double lowpass_cutoff_hz = 0.0;
  double window_s = 0.08;          // moving-average half-window (quasistatic.h)
  // lowpass_cutoff_hz > 0 and window_s in [0, 1] s. The message names the field.
  Status Check() const;
};

// Second-order Butterworth low-pass coefficients (b0, b1, b2, a1, a2 with a0 = 1) for
// `cutoff_hz` at `sample_hz`. Precondition: 0 < cutoff_hz < sample_hz / 2.
struct Biquad {
  double b0 = 1.0, b1 = 0.0, b2 = 0.0, a1 = 0.0, a2 = 0.0;
};
Biquad ButterworthLowPass(double cutoff_hz, double sample_hz);

// Zero-phase (forward-backward) low-pass of every row of `signal` (rows = channels, columns =
// frames, uniform sampling at sample_hz), with edge replication as described above.
// Errors when the cutoff is not in (0, sample_hz / 2).
StatusOr<Eigen::MatrixXd> ZeroPhaseLowPass(const Eigen::MatrixXd& signal, double cutoff_hz,
                                           double sample_hz);

// The dominant frequency (Hz) of the head's motion in a take, from what any capture has: the
// take's recorded platform frequency when it has one, else the largest peak of the skull
// origin's velocity spectrum (|Hann-windowed DFT of the detrended translation| * f, 0.5 Hz up
// to fps / 2) — for a walk, its step rate or a harmonic. 0 when the head does not move.
double DominantHeadMotionHz(const Take& take);

// The low-pass a user would set without any truth: one cutoff a factor 3 below the head
// motion's dominant frequency (DominantHeadMotionHz), where the forward-backward 2nd-order
// Butterworth passes 1 / (1 + 3^4) = 1.2% of a steady jiggle at that frequency; clamped to
// [0.25 Hz, 0.45 fps]. It needs only the recorded frequency or the estimated skull motion, and
// the factor is fixed by the filter's response, not fitted to any take. A head that does not
// move gets 0.45 fps (nothing to remove). eval/ reports the best cutoff against the truth
// beside it, labelled an oracle.
double LowPassCutoffByRule(const Take& take);

// The low-pass that follows a removal which already took away all but `residual_fraction` of
// the jiggle (its relative RMS error on takes it did not train on, e.g. the modal model's
// leave-one-take-out figure): the cutoff at which the filter leaves the same share of a steady
// jiggle at the dominant frequency f as LowPassCutoffByRule leaves of an untouched one,
// 1 / (1 + 3^4) = 1/82. With the filter's response 1 / (1 + (f / fc)^4) that is
// (f / fc)^4 = 82 r - 1, fc = f / (82 r - 1)^(1/4): r >= 1 gives the rule's f / 3, r = 0.3 about
// f / 2.2, r = 0.05 about f / 1.3; r <= 1/82 (the removal alone meets the budget) gives 0.45 fps,
// i.e. almost no filtering. No constant is fitted to any take: the budget is the rule's.
// Clamped as the rule, and never below it.
double LowPassCutoffAfterRemoval(const Take& take, double residual_fraction);

// Low-pass baseline positions (world frame) for all vertices of `take`.
StatusOr<PointCache> LowPassBaseline(const Take& take, double cutoff_hz);

// The baseline's positions (world frame, 3V x F) computed from a dynamic take.
StatusOr<PointCache> ComputeBaseline(const Take& take, BaselineKind kind,
                                     const BaselineOptions& options);

}  // namespace facedyn::dynamics
