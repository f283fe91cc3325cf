// Targeting 3D geometry with the twin (Bao et al. 2018, section 6, "shape targeting"): the
// expression whose held equilibrium in the twin's flesh best matches a captured frame's markers,
// beside the plain blendshape fit.
//
// Why it differs from the blendshape fit: a captured expression is an equilibrium under the
// gravity the head had. Upright, the twin's held skin is the blendshape skin exactly (the
// blendshapes are scans, equilibria under upright gravity), so the two fits agree. Once the head
// is tilted (lying back, a nod held, a scan on a couch), the flesh sags by up to g / w^2 (about
// 3 mm for a 9 Hz cheek per g of gravity change), and a blendshape fit can only explain the sag
// with wrong expression weights. The twin's fit models the sag with its fitted material, from
// the frame's skull pose (gravity in the skull frame), so its weights are the expression's.
//
// The residual and its Jacobian come from SoftTissueModel::HeldSkinWithJacobian (forward
// sensitivities, exact; tests/physics/soft_tissue_test); projected Gauss-Newton with the weights
// bounded to [0, 1] (each step's linear problem solved in the box, halved until the cost
// decreases), started from the blendshape fit. (Ceres' bounded Levenberg-Marquardt, tried first,
// accepted steps that raised this cost by 3% on upright frames of the procedural face and ran to
// its iteration limit.) The jaw follows the rig's
// jaw-opening shape (FittedJawAngleRad, as the twin's linearisations do): in this model the jaw
// moves no skin target itself, so the skin alone cannot tell it apart from the jaw shape.
//
// Uses what a capture has: marker positions in the skull frame, the skull's orientation (for
// gravity), the face rig and the fitted twin's material. Never a truth channel.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/status.h"
#include "core/take.h"
#include "physics/soft_tissue.h"

namespace facedyn::physics {

struct TargetingOptions {
  // Gauss-Newton steps of the twin fit; each evaluation re-factorises the flesh about the
  // candidate expression (about 0.5 s on the procedural face's 29,592 degrees of freedom).
  int max_iterations = 10;
  // Stops when a step lowers the cost by less than this fraction (1e-4 of the cost is 5e-5 of
  // the RMS residual), or moves no weight by more than parameter_tolerance (1e-5 of a
  // blendshape's displacement).
  double function_tolerance = 1e-4;
  double parameter_tolerance = 1e-5;
  // Both fits also correct the skull frame by a small rigid motion (rotation about the markers'
  // centroid, translation), fitted with the weights: the estimated skull pose comes from stable
  // markers that sag too when the head tilts, so the skull-frame markers of a tilted frame are
  // off by a rigid motion the expression cannot explain. On by default with the robust loss
  // below: chosen on twin_bench's validation seeds 11-13 (lying back 45 degrees, reconstructed
  // frames), where the twin's expression error was 0.071 +- 0.010 mm with both against
  // 0.136 +- 0.024 least squares, 0.121 +- 0.076 aligned only, 0.114 +- 0.020 robust only.
  bool align_skull = true;
  // Cauchy loss of this scale (mm) on each marker's 3D distance in both fits (iteratively
  // reweighted), so a gross marker error (a mislabelled or misdetected dot) pulls far less than
  // its square; 0 = least squares. The reported marker RMS is over every marker either way.
  // 0.5 mm is the scale of that validation run; no other scale was tried.
  double robust_scale_mm = 0.5;
};

struct ExpressionTargetingFit {
  Eigen::VectorXd weights;
  double jaw_angle_rad = 0.0;
  double rms_mm = 0.0;               // marker residual (RMS of the 3D distances)
  // RMS over the markers that both fits hold within 3 robust scales (with least squares, every
  // marker: then equal to rms_mm). With a robust loss, rms_mm includes the gross errors each fit
  // chose to ignore, and the two fits ignore different ones; this compares them on the same
  // markers.
  double common_inlier_rms_mm = 0.0;
  int common_inlier_markers = 0;
  Eigen::VectorXd marker_distance_mm;  // per marker, the 3D distance at the solution
  double flesh_volume_change = 0.0;  // flesh volume / neutral flesh volume - 1
  double skull_rotation_deg = 0.0;   // the alignment's rigid correction (0 without)
  double skull_translation_mm = 0.0;
  int outlier_markers = 0;  // with a robust loss: markers more than 3 scales off at the end
  int iterations = 0;
  std::vector<double> cost_history;  // the twin fit's cost (1/2 sum of squares, mm^2) per iteration
  std::string termination;           // why the twin fit stopped
  double seconds = 0.0;
};

struct ExpressionTargeting {
  ExpressionTargetingFit blendshape;  // plain blendshape fit; its flesh = the targets (no sag)
  ExpressionTargetingFit twin;        // the twin's held equilibrium under the frame's gravity
};

// Fits one frame (positions_in_skull: 3 x vertices.size(), mm) whose skull frame sees gravity
// changed by gravity_change_in_skull (GravityInSkull() - kGravityInWorld, mm/s^2) from upright.
// `model` is the twin's tissue model (its material set); it is left at the twin fit's
// expression as a static reference (SetReference before stepping it).
// Errors: sizes disagree, a vertex off the skin, non-finite input, a rig without blendshapes.
StatusOr<ExpressionTargeting> TargetHeldExpression(SoftTissueModel& model, const FaceRig& rig,
                                                   const std::vector<int>& vertices,
                                                   const Eigen::Matrix3Xd& positions_in_skull,
                                                   const Eigen::Vector3d& gravity_change_in_skull,
                                                   const TargetingOptions& options = {});

// A take's frames [first, end) reduced to one held frame: the mean of `vertices` in the skull
// frame (3 x n, through each frame's estimated world_from_skull) and the mean change of gravity
// there (GravityInSkull() - kGravityInWorld, mm/s^2; the world frame is +Y up). What
// TargetHeldExpression takes. Errors: an empty or out-of-range window, a vertex off the take.
struct HeldWindow {
  Eigen::Matrix3Xd positions_in_skull;
  Eigen::Vector3d gravity_change_in_skull = Eigen::Vector3d::Zero();
  int frames = 0;
};
StatusOr<HeldWindow> MeanHeldWindow(const Take& take, const std::vector<int>& vertices, int first,
                                    int end);

}  // namespace facedyn::physics
