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
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/pc2.h"
#include "core/rigid3.h"
#include "core/status.h"
#include "core/take.h"

namespace facedyn::dynamics {

struct QuasistaticOptions {
  double window_s = 0.08;  // half-window w in seconds; frames = round(window_s * fps)
  // window_s in [0, 1] s. The message names the field.
  Status Check() const;
};

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

// The whole take: a copy of `take` whose positions are y (Eq. 5) for every vertex, whose only
// channel is "dynamic_offset" = dx (Eq. 6), with info.source "dynamics quasistatic" and the
// window recorded in metadata ("quasistatic_window_s", "quasistatic_window_frames"). The
// input's own channels (e.g. the simulator's exact "quasistatic") are not carried over: the
// result is an estimate, evaluate it against the input with evaluate.h.
StatusOr<Take> ExtractQuasistatic(const Take& take, const QuasistaticOptions& options);

}  // namespace facedyn::dynamics
