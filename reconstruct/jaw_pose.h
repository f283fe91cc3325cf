// Jaw pose per frame: skull_from_jaw, the mandible's rigid motion in the skull frame, from the
// labelled markers on the jaw-driven skin, with the FaceRig's jaw model (pivot, hinge axis,
// region) as the anatomical prior.
//
// Convention (the simulator's, sim/performance.cc): the jaw frame coincides with the skull
// frame when the mouth is closed, so skull_from_jaw is the identity at rest, and an opening
// by angle theta about the hinge is
//   skull_from_jaw = Translation(c) * Rotation(a, theta) * Translation(-c),
// c = rig.jaw.pivot_in_skull, a = rig.jaw.axis_in_skull (unit), theta > 0 opens (for the
// procedural and ICT rigs, a = +X and the chin moves down and back).
//
// Model. A marker m on the rigidly-following part of the jaw, rest position r_m (skull frame,
// on the neutral skin), tissue thickness t_m (skin to bone) and rest normal n_m, is observed
// at q_m = skull_from_world * p_m, and modelled as
//   q_m = c + t + R(omega) R(a, theta) (r_m - c) + P2_m d1 + P4_m d2,
// theta the hinge angle (free); omega a small off-hinge rotation and t a small translation of
// the mandible (protrusion, lateral shift), held near zero by Gaussian priors (off by
// default); d1, d2 (mm at 10 mm of tissue) the per-frame inertial deflection of the skin over
// the bone, with profiles
//   P2_m = (t_m / 10)^2 (I - (1 - r) n_m n_m^T),   P4_m = (t_m / 10)^2 P2_m.
// Energy: sum_m w_m |residual_m|^2 + priors, solved by iteratively reweighted Gauss-Newton
// from the pure-hinge solution. With all extra terms off the model is the 1-DoF hinge, whose
// weighted least-squares solution is closed-form: with s_m, e_m the components of r_m - c and
// q_m - c perpendicular to a,
//   theta = atan2(sum_m w_m a . (s_m x e_m), sum_m w_m s_m . e_m),
// a global optimum (no initial guess, no local minima).
//
// Why it is shaped this way: skin over the jaw is not bone. Under head motion it jiggles
// coherently (0.4-2.2 mm RMS at 11 Hz, 2 mm platform, growing as t^2.0 with tissue thickness
// in the simulator), and a coherent motion is no outlier: a plain hinge fit turns it into
// 0.29 deg RMS hinge error on a jaw_open take and 0.45 deg on speech. The deflection terms are
// the first two terms of a soft layer's response to an inertial body force f: a shear layer of
// thickness t bonded to bone deflects at its surface by f t^2 / (2 mu) (1 + (5/12) k^2 t^2 +
// ...), k the shear wave number at the load's frequency, so d1 is the quasi-static part and
// d2 the dynamic correction, each with its own phase under damping (one of each per frame).
// Tangential deflection dominates: for a nearly incompressible layer (Poisson 0.45) the normal
// compliance is mu / (lambda + 2 mu) ~ 0.1 of the shear compliance, hence r = 0.1. The
// thickness profile also separates d1, d2 from the rotation, which moves markers in
// proportion to their lever arm instead. Weights: tracking confidence x (t_min / t_m)^4, the
// inverse variance of a deflection whose amplitude grows as t^2 (thin chin skin counts most),
// x a Huber weight on the residual, which discounts a marker that an expression slid off the
// bone (a smile pulls the cheeks, the lower lip drags the skin under it). Measured on the
// simulator with the true skull pose and noise-free markers (jaw_open / speech, 11 Hz, hinge
// RMS error): hinge only, t^-2 weights 0.29 / 0.45 deg; t^-4 weights 0.25 / 0.38; + d1 0.13 /
// 0.29; + d2 0.11 / 0.15 (without head motion every variant is within 0.02-0.09 deg, and a
// held smile, pucker, cheek puff, ... within 0.05). Through 8 cameras at 0.2 px, tracking and
// the estimated skull pose: 0.19 / 0.21 deg (tests/reconstruct/jaw_pose_test.cc). On real faces the
// condyle also translates a few millimetres in wide opening, which a handful of skin markers 60-100
// mm away cannot separate from the rotation without a prior: hence the regularised omega and t, for
// a real subject, off by default. Markers used: those whose surface point lies entirely in the
// rig's jaw region AND in its "chin" or "cheeks" regions (the rigidly-following part, the same rule
// the rig generators use to fit the hinge; lips and the soft neck are left out), or the whole jaw
// region when that intersection holds fewer than min_markers markers.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/rigid3.h"
#include "core/status.h"
#include "reconstruct/tracking.h"

namespace facedyn::reconstruct {

// skull_from_jaw for a pure hinge rotation of `angle_rad` (see the convention above).
Rigid3 SkullFromJawHinge(const JawModel& jaw, double angle_rad);
// The hinge angle of any skull_from_jaw: the twist of its rotation about the hinge axis
// (swing-twist decomposition), in (-pi, pi]. Exact inverse of SkullFromJawHinge.
double JawHingeAngleRad(const JawModel& jaw, const Rigid3& skull_from_jaw);

struct JawPoseOptions {
  int min_markers = 4;          // fewer usable jaw markers: the frame has no jaw estimate
  double huber_mm = 0.4;        // beyond this residual a marker's weight is huber_mm / residual
  int iterations = 8;           // reweighting iterations
  bool thickness_prior = true;  // weight (t_min / t)^4; otherwise 1
  // 0: none; 1: d1 (t^2); 2: d1 and d2 (t^2 and t^4). A frame uses d1 only with at least 6
  // usable jaw markers and d2 only with at least 12 (fewer cannot separate them from theta).
  int deflection_terms = 2;
  double normal_deflection_ratio = 0.1;  // r: normal over tangential compliance of the layer
  // Priors on the extra DoF: at |t| = translation_prior_mm (|omega| =
  // extra_rotation_prior_rad) the prior costs as much as one marker of mean weight 1 mm off.
  // 0 removes the DoF; both 0 is the pure hinge.
  double translation_prior_mm = 0.0;
  double extra_rotation_prior_rad = 0.0;
  Status Check() const;
};

struct JawPoseResult {
  Rigid3 skull_from_jaw;   // identity when !ok
  double angle_rad = 0.0;  // hinge angle, positive opens
  int markers_used = 0;
  double rms_mm = 0.0;  // weighted residual of the used markers
  Eigen::Vector3d deflection_t2_mm = Eigen::Vector3d::Zero();  // d1 (see above), skull frame
  Eigen::Vector3d deflection_t4_mm = Eigen::Vector3d::Zero();  // d2
  bool ok = false;  // false: fewer than min_markers jaw markers usable in this frame
};

class JawPoseEstimator {
 public:
  // status() is Ok with has_jaw() false for a rig without a jaw (rig.jaw.region empty);
  // FailedPrecondition when the rig names a jaw region that is unknown or carries fewer than
  // min_markers markers; InvalidArgument for bad options or a zero hinge axis.
  JawPoseEstimator(const FaceRig& rig, const JawPoseOptions& options);
  Status status() const { return status_; }
  bool has_jaw() const { return has_jaw_; }

  // Rig marker indices used for the jaw, and their prior weights and tissue thickness (mm).
  const std::vector<int>& jaw_markers() const { return jaw_markers_; }
  const Eigen::VectorXd& prior_weights() const { return prior_weights_; }
  const Eigen::VectorXd& thickness_mm() const { return thickness_mm_; }
  // The chin point for error figures (skull frame, at rest): the centroid of the rig's chin
  // vertices that lie in the jaw region, or of the jaw markers when the rig has no chin.
  Eigen::Vector3d reference_point_in_skull() const { return reference_point_in_skull_; }
  const JawModel& jaw() const { return jaw_; }

  // One frame: all rig markers' positions in the skull frame (3 x markers), their states and
  // confidences. Missing markers and zero confidences are not used.
  JawPoseResult Estimate(const Eigen::Matrix3Xd& markers_in_skull,
                         const std::vector<MarkerState>& states,
                         const std::vector<double>& confidence) const;
  // Same, from a tracked frame and the frame's skull pose.
  JawPoseResult Estimate(const TrackedFrame& frame, const Rigid3& world_from_skull) const;

 private:
  JawPoseOptions options_;
  Status status_;
  bool has_jaw_ = false;
  JawModel jaw_;
  std::vector<int> jaw_markers_;
  Eigen::Matrix3Xd rest_in_skull_;  // of the jaw markers
  Eigen::VectorXd thickness_mm_;
  Eigen::VectorXd prior_weights_;
  std::vector<Eigen::Matrix3d> profile_t2_;  // P2_m of the jaw markers (see above)
  std::vector<Eigen::Matrix3d> profile_t4_;  // P4_m
  Eigen::Vector3d reference_point_in_skull_ = Eigen::Vector3d::Zero();
};

// A whole take's jaw: per frame the estimate, and for frames without one (result.ok false)
// the previous frame's skull_from_jaw carried over (identity before the first estimated
// frame, i.e. the closed-mouth rest pose). `tracked` and `world_from_skull` have one entry
// per frame.
struct JawSequence {
  std::vector<Rigid3> skull_from_jaw;
  std::vector<JawPoseResult> results;
  std::vector<bool> carried;      // true where skull_from_jaw was carried over
  std::vector<int> carried_from;  // the frame whose estimate it is; -1 for the rest pose
};
JawSequence EstimateJawSequence(const JawPoseEstimator& estimator,
                                const std::vector<TrackedFrame>& tracked,
                                const std::vector<Rigid3>& world_from_skull);

// How far an estimated skull_from_jaw is from a reference one: hinge angle difference
// (estimate - reference), and distances between where the two put the pivot and a reference
// point (e.g. reference_point_in_skull()).
struct JawPoseDifference {
  double angle_rad = 0.0;
  double pivot_mm = 0.0;
  double point_mm = 0.0;
};
JawPoseDifference CompareJawPoses(const JawModel& jaw, const Eigen::Vector3d& point_in_skull,
                                  const Rigid3& estimate, const Rigid3& reference);

}  // namespace facedyn::reconstruct
