// Skull pose per frame: world_from_skull (the paper's T(t)) from the labelled markers on the
// FaceRig's stable regions (forehead, nose bridge, temples), with robust weighting and the
// rig's anatomy as prior.
//
// Why it is shaped this way: even the stable regions jiggle (~0.3-1 mm peak at 11 Hz in the
// simulator, growing with tissue thickness), and that motion is coherent across the region,
// so no outlier test removes it and a plain rigid fit passes it into the pose (0.29 mm RMS at
// the skull origin on a noise-free simulated 11 Hz take). Three anatomical priors keep it out:
//  (a) an inertial deflection model: a soft layer of thickness t bonded to bone and loaded by
//      a body force (its own inertia) deflects at the surface in proportion to t^2, so the
//      stable markers' skull-frame positions are modelled as rest_i + (t_i / 5 mm)^2 d(t) with
//      one unknown deflection d per frame, estimated with the pose by alternating weighted
//      least squares (d given T is linear; T given d is a weighted Kabsch). Thickness varies
//      (about 4.5-8 mm over forehead, nose bridge and temples), which makes d separable from
//      the pose's translation;
//  (b) weights: a marker's prior weight is (t_min / t)^4, the inverse variance of a jiggle
//      that grows as t^2, times its tracking confidence, times a robust Huber weight
//      (discounting a frown or a mislabelled point). Bridged markers enter at their (lower)
//      confidence, missing ones not;
//  (c) the jiggle slides the skin along itself (2-4% of its energy along the normal), so the
//      translation is re-fitted to the markers' normal components (translation_from_normals);
//  (d) by default the t^2 law of (a) is then replaced, for the translation, by the tissue
//      model's own deflection shapes (DeflectionShape::kTissueModel below);
//  (e) over a whole take (EstimateTake, what the pipeline runs) the stable markers' reference
//      shape is re-estimated from the take, so that a static per-marker bias of the measured
//      markers does not become a constant pose error (see there).
// On the noise-free take above (a)-(c) leave 0.048 mm and 0.020 degrees RMS, and (d) brings the
// origin to 0.019 mm with the rotation unchanged (bench/skull_pose_bench seed 1, the default
// subject; README, "Skull pose"). Thickness is the skin-to-skull
// distance under each marker (the same surface point on the skull when the skull shares the
// skin's topology, as physics/face_anatomy.h rigs do; otherwise the nearest skull vertex).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/rigid3.h"
#include "core/status.h"
#include "physics/inertial_deflection.h"
#include "reconstruct/tracking.h"

namespace facedyn::reconstruct {

// The shape of the stable markers' jiggle that the deflection model fits per frame.
enum class DeflectionShape {
  // (a) above: rest_i + (t_i / 5 mm)^2 d, one 3-vector d per frame.
  kThicknessSquared,
  // The tissue model's own shapes (physics/inertial_deflection.h): the static deflection of the
  // face's flesh under uniform acceleration along the skull's three axes, and one Krylov block
  // more (K^-1 M times it: what inertia does to that shape as the frequency rises), six
  // coefficients per frame. They carry what the t^2 law leaves out (the skin slides along the
  // bone in directions set by the layer's shape and boundary). Shapes only: computed with a
  // unit Young's modulus, so no parameter of the subject's tissue enters. The pose's
  // translation and the six coefficients are fitted jointly (Gauss-Newton, the same weights)
  // after the t^2 law's fit, whose rotation is kept unless rotation_from_thickness_law is off
  // (see there). Needs a rig whose skull shares the skin's topology (physics/face_anatomy.h);
  // other rigs fall back to the t^2 law (deflection_shape_used() says which). Figures in the
  // README, "Skull pose" (bench/skull_pose_bench, bench/reconstruct_bench).
  kTissueModel,
};

// The shapes DeflectionShape::kTissueModel uses: the three uniform loads (the angular loads'
// static shapes in place of the second block did worse: skull_pose_bench's static6 variant) and
// two Krylov blocks (a third was no better).
physics::InertialDeflectionOptions TissueModelDeflectionOptions();

struct SkullPoseOptions {
  double huber_mm = 0.25;
  int iterations = 8;
  bool thickness_prior = true;
  // The prior weight is (t_min / t)^thickness_weight_power. 4: the inverse variance of a
  // marker whose jiggle grows as t^2 (the deflection model's law), as jaw_pose.h weights;
  // bench/skull_pose_bench measures 2, 4, 6 and 8 (README, "Skull pose").
  double thickness_weight_power = 4.0;
  bool deflection_model = true;
  // After the fit above, re-fit the pose's translation (rotation kept) to the stable markers'
  // components along their skin normals only (point-to-plane, Gauss-Newton, the same weights):
  // the jiggle is almost all tangential (2-4% of its energy along the normal on the simulated
  // stage), so the normal components see the skull's translation with little leak; rotation is
  // not refitted because the stable regions are close to a sphere, whose rotations about its
  // centre no normal sees. bench/skull_pose_bench, noise-free markers of the simulated
  // neutral face, weight power 2: origin error RMS 0.143 -> 0.075 mm at 11 Hz, 0.090 -> 0.042
  // at 6 Hz, 0.341 -> 0.094 on a run in place (rotation unchanged; README, "Skull pose").
  bool translation_from_normals = true;
  DeflectionShape deflection_shape = DeflectionShape::kTissueModel;
  // An explicit shape basis, which overrides deflection_shape: (3 x rig markers) x K, row
  // 3m + axis for rig.markers[m], skull frame. Each frame then has K deflection coefficients
  // instead of d, fitted like d (bench/skull_pose_bench compares bases).
  Eigen::MatrixXd deflection_basis;
  // With the tissue model's shapes: keep the rotation of the t^2 law's fit and fit only the
  // translation with the shapes. Fitting the rotation with them too leaks less of noise-free
  // simulated jiggle (skull_pose_bench) but passes more of the triangulation's noise into the
  // rotation: on reconstruct_bench's 11 Hz take through 8 cameras at 0.2 px, 0.034 degrees RMS
  // against the law's 0.027. The shapes come close to a rotation on the stable markers.
  bool rotation_from_thickness_law = true;
  // EstimateTake only: the stable markers' reference shape is re-estimated from the take (see
  // there) when the take has at least take_reference_min_frames posed frames.
  bool take_reference = true;
  int take_reference_min_frames = 32;
  int min_markers = 4;
  Status Check() const;
};

struct SkullPoseResult {
  Rigid3 world_from_skull;
  int markers_used = 0;
  double rms_mm = 0.0;  // weighted residual of the stable markers
  // d (see above), skull frame: the t^2 law's fit, which the tissue model's shapes start from.
  Eigen::Vector3d deflection_mm = Eigen::Vector3d::Zero();
  bool ok = false;  // false: too few stable markers (the pose is the initial one)
};

// What EstimateTake's take-level reference changed.
struct TakeReferenceResult {
  bool applied = false;
  std::string reason;              // why not, when not applied
  int markers_refined = 0;         // stable markers observed on enough frames to be re-estimated
  double correction_rms_mm = 0.0;  // |new - rig reference| over those markers, skull frame
  double correction_max_mm = 0.0;
};

class SkullPoseEstimator {
 public:
  // FailedPrecondition (via ok()) when the rig names no stable region or none carries markers.
  SkullPoseEstimator(const FaceRig& rig, const SkullPoseOptions& options);
  Status status() const { return status_; }

  const std::vector<int>& stable_markers() const { return stable_markers_; }
  // Prior weight of each stable marker (same order).
  const Eigen::VectorXd& prior_weights() const { return prior_weights_; }
  const Eigen::VectorXd& thickness_mm() const { return thickness_mm_; }
  // The deflection shape in use: "thickness_squared", "tissue_model", "explicit basis", or
  // "none" (deflection_model off); with the reason when kTissueModel fell back.
  const std::string& deflection_shape_used() const { return deflection_shape_used_; }

  // One frame: all rig markers' world positions (3 x markers), their states and confidences.
  SkullPoseResult Estimate(const Eigen::Matrix3Xd& markers_in_world,
                           const std::vector<MarkerState>& states,
                           const std::vector<double>& confidence, const Rigid3& initial) const;
  SkullPoseResult Estimate(const TrackedFrame& frame) const {
    return Estimate(frame.positions_in_world, frame.states, frame.confidence,
                    frame.world_from_skull_tracking);
  }

  // A whole take. Per frame as Estimate; then, with options.take_reference, the stable
  // markers' reference shape is re-estimated from the take and every frame estimated again:
  // each stable marker's reference becomes the mean over the frames that observed it of its
  // skull-frame position under the first poses (samples more than 1 mm and 6 robust standard
  // deviations from their median left out), the means rigidly aligned (prior weights) to
  // the rig's reference so that the correction carries no rigid motion, and markers observed
  // on fewer than a quarter of the posed frames keep the rig's.
  // Why: a static per-marker mismatch between the rig's reference and what the cameras measure
  // (a detector's centre bias on a dot seen obliquely, paint applied off the rig's points, a
  // held expression that moves the brows) is not a rigid motion, so the per-frame fit spreads
  // it over the pose and the deflection shapes, and the two are nearly interchangeable on the
  // stable markers: on reconstruct_bench's filmed 11 Hz take a 0.026 mm RMS per-marker bias
  // became a 0.17 mm constant error of the skull origin (--stage skull_offset). A take's jiggle
  // averages out over the take, so its mean shape is the reference plus that bias. What a
  // take-level reference cannot see is a mismatch that is itself a rigid motion (it is one
  // with the pose) and a deflection that lasts the whole take (e.g. a changed gravity load).
  std::vector<SkullPoseResult> EstimateTake(const std::vector<TrackedFrame>& frames,
                                            TakeReferenceResult* reference = nullptr) const;

 private:
  SkullPoseOptions options_;
  Status status_;
  std::vector<int> stable_markers_;
  Eigen::Matrix3Xd rest_in_skull_;  // of the stable markers
  Eigen::Matrix3Xd normal_in_skull_;  // unit skin normals at the stable markers (neutral)
  Eigen::VectorXd thickness_mm_;
  Eigen::VectorXd prior_weights_;
  Eigen::MatrixXd deflection_basis_;  // (3 x rig markers) x K, or empty: the t^2 law
  std::string deflection_shape_used_;
};

}  // namespace facedyn::reconstruct
