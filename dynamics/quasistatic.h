// Quasistatic extraction for held-expression takes, Zoss et al. 2020, Eq. (5)-(6):
//
//   y_i(t)  = T(t) * (1 / (2w+1)) * sum_{k=t-w..t+w} T(k)^-1 x_i(k)        (5)
//   dx_i(t) = T(t)^-1 (x_i(t) - y_i(t))                                     (6)
//
// with T = world_from_skull. After the rigid head motion is factored out, the skin of a held
// expression only jiggles about its rest shape, and a centred moving average over a window
// longer than a jiggle period (w = round(0.08 s * fps), 10 at 128 fps) removes the jiggle. This
// is the training target of the removal network and one of the baselines every figure is
// reported against. End policy as in features.h: frame indices are clamped to [0, F-1], i.e.
// the first and last frames are replicated, so the window always holds 2w+1 terms.
//
// Platform-synchronous extraction (QuasistaticMethod::kPlatformSynchronous, facedyn's own): on a
// vibrating platform the frequency is known (the rig logs it; Take::info.platform_hz), and a box
// window of 2w+1 frames averages a sinusoid of that frequency to zero only when it spans a whole
// number of periods, which a fixed 80 ms window does at one frequency at best (at 11 Hz and 128
// fps it spans 1.8 periods and leaves ~10% of the jiggle). Instead, per point and frame, the
// stabilised trajectory over the window is fitted by least squares with a constant plus sines and
// cosines of the platform frequency and its harmonics, and the constant is the quasistatic. The
// fit is linear with fixed basis, so it is a fixed FIR filter: weights h = A (A^T A)^-1 e_0 with
// A the (2w+1) x (1 + 2H) basis matrix of frame offsets -w..w; it passes a constant exactly and
// removes the platform frequency and its first H-1 harmonics exactly, whatever the window.
//
// Held mean (QuasistaticMethod::kHeldMean): the whole held part of the take (frames from
// FirstHeldFrame on) has one quasistatic, its mean shape in the skull frame. That is the
// definition of a held expression, so it is exact up to the mean of the jiggle itself (near
// zero for a motion without a mean acceleration), whatever the head motion: a walk as well as
// the platform, where a window of 2w+1 frames either cannot span the motion's period (a step
// at 1.5 steps/s is 0.67 s) or, as the zero-phase low-pass, rings at the take's ends. Valid only
// for held takes: a performance's changing expression would be read as dynamics.
#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/pc2.h"
#include "core/rigid3.h"
#include "core/status.h"
#include "core/take.h"

namespace facedyn::dynamics {

enum class QuasistaticMethod {
  kMovingAverage,        // Eq. (5), the paper's
  kPlatformSynchronous,  // least-squares fit at the known platform frequency (above)
  kHeldMean,             // the held part's mean shape in the skull frame (above)
};

// "moving-average", "platform-synchronous", "held-mean".
const char* QuasistaticMethodName(QuasistaticMethod method);

struct QuasistaticOptions {
  double window_s = 0.08;  // half-window w in seconds; frames = round(window_s * fps)
  QuasistaticMethod method = QuasistaticMethod::kMovingAverage;
  // Platform-synchronous only: the frequency (Hz; unset: the take's info.platform_hz), the
  // number of harmonics fitted (1 = the fundamental only), and the shortest window in periods
  // (the half-window grows to span at least this many periods when window_s is shorter).
  std::optional<double> platform_hz;
  int harmonics = 2;
  double min_periods = 1.5;
  // Platform-synchronous only: degree of the polynomial fitted with the sinusoids (0: a
  // constant). A changing expression is a trend over the window that a constant smears.
  int trend_degree = 0;
  // window_s in [0, 1] s, platform_hz > 0 when set, harmonics in 1..4, min_periods in [1, 10].
  // The message names the field.
  Status Check() const;
};

// The FIR weights (2w+1, offsets -w..w) of the platform-synchronous fit at `platform_hz` with
// `harmonics` harmonics. Errors: a harmonic at or above the Nyquist frequency, or a window too
// short for the fit to be well conditioned.
StatusOr<std::vector<double>> PlatformSynchronousWeights(double fps, double platform_hz,
                                                         int half_window_frames, int harmonics,
                                                         int trend_degree = 0);

// Like MovingAverageInSkull with any centred weights (size 2w+1, offsets -w..w; clamped frame
// indices at the ends): T(t) sum_k h_k T(t+k)^-1 x(t+k).
StatusOr<PointCache> WeightedAverageInSkull(const PointCache& positions,
                                            const std::vector<Rigid3>& world_from_skull,
                                            const std::vector<double>& weights);

// Eq. (5) for every point of a cache: `positions` (3N x F, world frame, mm) and one pose per
// frame; returns y (3N x F, world frame). A running sum in double keeps the cost O(N F)
// whatever the window. Errors when the pose count differs from the frame count.
StatusOr<PointCache> MovingAverageInSkull(const PointCache& positions,
                                          const std::vector<Rigid3>& world_from_skull,
                                          int window_frames);

// Offsets of Eq. (6): skull_from_world (x - y) per frame (3N x F, skull-frame directions, mm).
// Errors when the caches or the pose count disagree.
StatusOr<PointCache> DynamicOffsets(const PointCache& positions, const PointCache& quasistatic,
                                    const std::vector<Rigid3>& world_from_skull);

// The whole take: a copy of `take` whose positions are y (Eq. 5, the platform-synchronous
// fit or the held mean; before the hold starts the held mean is used too) for every vertex, whose only channel is "dynamic_offset" = dx (Eq. 6), with info.source
// "dynamics quasistatic" and the method and window recorded in metadata ("quasistatic_method",
// "quasistatic_window_s", "quasistatic_window_frames", "quasistatic_platform_hz"). A
// platform-synchronous request on a take without a platform frequency (and none in the options)
// is a FailedPrecondition naming platform_hz. The
// input's own channels (e.g. the simulator's exact "quasistatic") are not carried over: the
// result is an estimate, evaluate it against the input with evaluate.h.
StatusOr<Take> ExtractQuasistatic(const Take& take, const QuasistaticOptions& options);

}  // namespace facedyn::dynamics
