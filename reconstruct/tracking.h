// Tracking and labelling: every triangulated point assigned to a marker of the FaceRig's
// layout, per frame, with gaps bridged and a confidence per marker.
//
// First frame (FitRigToPoints): the rig's markers are aligned to the points without known
// correspondences — candidate rotations from the prior pose (if any) and from matching the
// principal axes of both sets (the four proper sign choices), each refined by trimmed ICP; the
// best is then alternated with a gated Hungarian assignment and a least-squares fit of the
// rig's blendshape weights to the assigned markers, so a first frame that is not neutral (an
// open jaw moves markers by 20 mm) is still labelled.
//
// Later frames (MarkerTracker::AddFrame): markers are kept in the skull frame of a tracking
// pose T(t) (a robust rigid fit of all labelled markers to their last skull-frame positions).
// The prediction of marker m is T^(t) q_m^(t), with T^ the constant-velocity extrapolation of
// T and q_m^ the constant-velocity extrapolation of its skull-frame position, so head motion
// (the large part of a marker's motion) is predicted rigidly and only skin motion by the
// marker itself. Points are assigned to predictions by a gated Hungarian assignment on
// squared distance: a global optimum, so two nearby markers cannot swap to save one of them a
// little distance, and anything beyond the gate stays unlabelled rather than being forced.
// Each marker's gate is 4 times its running prediction error (at least 1.5 mm, at most
// gate_mm; gate_mm after a gap), so a stray point next to a hidden marker is not taken for it.
// Frames with fewer than 3 labelled markers get their pose interpolated in Finish().
// A marker without a point keeps being predicted (so it is re-acquired when it reappears).
//
// Finish() bridges gaps of at most max_bridge_frames: in the skull frame, the hidden marker is
// moved as its (up to 6, within 30 mm) neighbours seen at both ends and in that frame move,
// blended linearly from the observations on either side (linear interpolation alone when no
// neighbour is seen); longer gaps and gaps at the ends stay missing. Confidence: observed = point
// confidence * (1 - (innovation / gate)^2); bridged = 0.5 * the smaller neighbour confidence * (1 -
// gap / (max_bridge_frames + 1)); missing 0.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <vector>

#include "core/face_rig.h"
#include "core/rigid3.h"
#include "core/status.h"
#include "reconstruct/triangulation.h"

namespace facedyn::reconstruct {

struct TrackingOptions {
  double gate_mm = 4.0;              // largest prediction error accepted per frame
  double first_frame_gate_mm = 8.0;  // assignment gate when fitting the rig
  int max_bridge_frames = 16;
  std::optional<Rigid3> initial_world_from_skull;  // prior for the first frame
  // The skull pose is known and constant: initial_world_from_skull (identity when unset) on every
  // frame, never searched or refitted. Head-mounted cameras, whose frame is the helmet's: a
  // rigid search there can only trade true labels for a better-fitting wrong alignment.
  bool pose_fixed = false;
  Status Check() const;
};

enum class MarkerState { kObserved, kBridged, kMissing };

struct RigFit {
  Rigid3 world_from_skull;
  Eigen::VectorXd blendshape_weights;
  std::vector<int> point_of_marker;  // -1 when unassigned
  double rms_mm = 0.0;               // assigned markers against the posed rig
  int assigned = 0;
};

// Labels one frame's points by fitting the rig (see above). FailedPrecondition when fewer
// than 6 points, or when no alignment assigns at least a third of the markers.
StatusOr<RigFit> FitRigToPoints(const FaceRig& rig, const Eigen::Matrix3Xd& points_in_world,
                                const TrackingOptions& options);

struct TrackedFrame {
  Eigen::Matrix3Xd positions_in_world;  // 3 x markers (predicted when missing)
  std::vector<MarkerState> states;
  std::vector<double> confidence;
  std::vector<int> point_of_marker;  // index into that frame's points, -1 if none
  Rigid3 world_from_skull_tracking;  // the tracker's own pose (see skull_pose.h for the real one)
  int points = 0;
  int unlabelled_points = 0;
  int observed() const;
};

class MarkerTracker {
 public:
  MarkerTracker(const FaceRig& rig, const TrackingOptions& options);

  // Labels the next frame. The first frame with at least 6 points is labelled by
  // FitRigToPoints; frames before it (and frames without points) are all missing. Returns the
  // frame as labelled now (Finish() may still bridge it).
  StatusOr<TrackedFrame> AddFrame(const std::vector<TriangulatedPoint>& points);
  // All frames, with gaps bridged.
  std::vector<TrackedFrame> Finish();

  int marker_count() const { return static_cast<int>(rest_in_skull_.cols()); }

 private:
  const FaceRig& rig_;
  TrackingOptions options_;
  Eigen::Matrix3Xd rest_in_skull_;
  std::vector<TrackedFrame> frames_;
  bool initialised_ = false;
  std::vector<Rigid3> poses_;             // tracking pose per frame
  Eigen::Matrix3Xd last_in_skull_;        // latest skull-frame position per marker
  Eigen::Matrix3Xd velocity_in_skull_;    // mm per frame
  std::vector<int> last_observed_frame_;  // -1 never
  Eigen::VectorXd innovation_rms_mm_;     // running RMS of each marker's prediction error
};

}  // namespace facedyn::reconstruct
