// The two frames every removal figure is reported in (issue 19):
//   - world: the output take's positions against the truth's quasistatic, as a viewer sees it;
//   - skull: the stabilised quasistatic expression, T_est(t)^-1 y(t) for the method (in the
//     skull frame the reconstruction estimated) against T_true(t)^-1 y_true(t) (the
//     simulator's skull), after their fixed offset is removed. This is what retargeting
//     consumes, and a skull pose that jitters shows up here even when the world figure hides it.
// And the lower reference of a removal on a reconstruction: Eq. 7 with the exact offsets,
// x(t) - R_est(t) dx_exact(t) — the error a perfect F would leave on that reconstruction
// (round 1's "perfect_removal_mm" re-posed the exact quasistatic instead, which bounds nothing:
// Eq. 7 moves points by rotated offsets, it does not re-pose a shape).
#pragma once

#include <vector>

#include "core/pc2.h"
#include "core/rigid3.h"
#include "core/take.h"
#include "dynamics/training_frames.h"

namespace facedyn::eval {

// The fixed offset between an estimated and a true skull frame: the mean over `frames` of
// estimated_skull_from_true_skull = T_est^-1 T_true (rotation: normalised quaternion mean,
// fine for the sub-degree spreads of a tracked skull). Identity for an empty range.
Rigid3 FixedSkullOffset(const std::vector<Rigid3>& world_from_estimated_skull,
                        const std::vector<Rigid3>& world_from_true_skull,
                        dynamics::FrameRange frames);

// Mean |T_est^-1 y - C T_true^-1 y_true| (mm) over `vertices` and `frames`, C the fixed offset.
// Preconditions (CHECKed): equal vertex and frame counts, poses for every frame.
double SkullFrameMeanDistance(const PointCache& predicted_world,
                              const std::vector<Rigid3>& world_from_estimated_skull,
                              const PointCache& truth_world,
                              const std::vector<Rigid3>& world_from_true_skull,
                              const std::vector<int>& vertices, dynamics::FrameRange frames);

// Eq. 7 with exact offsets: positions(t) - R_est(t) offsets_in_skull(t) for every vertex.
PointCache RemoveExactOffsets(const Take& reconstructed, const PointCache& exact_offsets_in_skull);

}  // namespace facedyn::eval
