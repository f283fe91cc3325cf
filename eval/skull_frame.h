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

#include <Eigen/Core>
#include <vector>

#include "core/json_io.h"
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

// An estimated skull pose scored against the simulator's, per frame as the error
// T_true^-1 T_est (translation: the estimated origin in the true skull frame, mm; rotation: its
// rotation vector), over `frames`: the RMS in total, the take's mean error ("constant": it only
// renames the skull frame for the whole take, e.g. a calibration's or a reference shape's bias)
// and the RMS about that mean ("varying": what leaks jiggle into every stabilised trajectory,
// issue 20). Zero for an empty range.
struct SkullPoseError {
  int frames = 0;
  double origin_rms_mm = 0.0;
  double origin_constant_mm = 0.0;
  double origin_varying_rms_mm = 0.0;
  double rotation_rms_deg = 0.0;
  double rotation_constant_deg = 0.0;
  double rotation_varying_rms_deg = 0.0;
  double origin_max_mm = 0.0;
  double rotation_max_deg = 0.0;
  Eigen::Vector3d origin_mean_mm = Eigen::Vector3d::Zero();  // true skull frame
};
// Preconditions (CHECKed): both pose lists cover `frames`.
SkullPoseError ScoreSkullPoses(const std::vector<Rigid3>& world_from_estimated_skull,
                               const std::vector<Rigid3>& world_from_true_skull,
                               dynamics::FrameRange frames);
Json SkullPoseErrorJson(const SkullPoseError& error);

// Eq. 7 with exact offsets: positions(t) - R_est(t) offsets_in_skull(t) for every vertex.
PointCache RemoveExactOffsets(const Take& reconstructed, const PointCache& exact_offsets_in_skull);

}  // namespace facedyn::eval
