// The subject's physical twin (issue 23): the face model (physics/soft_tissue.h) with a
// material identified from the platform takes a capture session already has.
//
// What goes in is what a capture has, nothing else: the actor's FaceRig (scan, blendshapes,
// markers, skull surface), and reconstructed takes — per frame the skin in the world frame and
// the estimated world_from_skull, the platform frequency the rig measured, and when the
// expression was held. The simulator's true tissue parameters and truth channels never enter
// (tests/physics/twin_test checks that channels are ignored).
//
// How (Bao et al. 2018 fit muscle activations to geometry; here the material is fitted to
// motion):
// 1. Per take, the held frames' marker vertices are brought into the skull frame; their mean is
//    fitted by the blendshapes with weights in [0, 1] (FitBlendshapeWeights, Ceres), which is
//    the expression the flesh is linearised about (and the mandible angle it implies).
// 2. Each marker's motion and the skull's are reduced to phasors at the platform frequency
//    (physics/harmonic_response.h), a constant and a drift removed.
// 3. The twin's stiffness per group of regions and its Rayleigh damping are fitted to every
//    take's phasors at once (physics/material_fit.h); takes holding the same expression share
//    one linearisation (and one sparse factorisation per evaluation).
// 4. The fitted material gives the twin's cheek mode (frequency and damping ratio), with a
//    standard deviation propagated from the fit's covariance.
// 5. Given the platform's amplitude, the body's transmissibility from platform to skull is
//    fitted to the same takes' skull motion (physics/body_transmissibility.h).
#pragma once

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"
#include "core/take.h"
#include "physics/body_transmissibility.h"
#include "physics/material_fit.h"
#include "physics/soft_tissue.h"

namespace facedyn::physics {

// The skin vertices the twin observes: per marker the vertex that carries most of its
// barycentric weight, once each, in marker order.
std::vector<int> TwinMarkerVertices(const FaceRig& rig);

// argmin |a x - b| over x in [0, 1]^n (Ceres, from `start` clipped to the box): the blendshape
// fit's solver, shared with the twin's targeting steps. Errors: sizes disagree, non-finite input.
StatusOr<Eigen::VectorXd> UnitBoxLeastSquares(const Eigen::MatrixXd& a, const Eigen::VectorXd& b,
                                              const Eigen::VectorXd& start);

// Blendshape weights in [0, 1] whose skin best matches `positions_in_skull` (3 x n, mm) at
// `vertices` in least squares, and the RMS of what is left (mm). Errors: sizes disagree, a
// vertex out of range, a rig without blendshapes.
struct BlendshapeFit {
  Eigen::VectorXd weights;
  double rms_mm = 0.0;
};
StatusOr<BlendshapeFit> FitBlendshapeWeights(const FaceRig& rig, const std::vector<int>& vertices,
                                             const Eigen::Matrix3Xd& positions_in_skull);

// Mandible rotation (rad) of the rig's jaw-opening shape ("jaw_open" or "jawOpen") at weight 1,
// fitted as a hinge about rig.jaw over JawFitVertices; 0 without such a shape. What the twin
// uses for an expression's jaw (weights times this), from the rig's geometry alone.
double FittedJawOpenAngleRad(const FaceRig& rig);
double FittedJawAngleRad(const FaceRig& rig, const Eigen::VectorXd& weights);

// A group of tetrahedra sharing one stiffness scale: those under the skin vertices of `regions`
// (a tetrahedron belongs to the region of its prism's skin vertex). One group may have no regions:
// it takes every tetrahedron the others do not.
struct StiffnessGroup {
  std::string name;
  std::vector<std::string> regions;
};
// cheeks (cheeks, mouth_corners), mouth (upper_lip, lower_lip, chin), rest (everything else).
std::vector<StiffnessGroup> DefaultStiffnessGroups();
// Group index per tetrahedron of `shell`. Errors: an unknown region, two groups without
// regions, a region in two groups, an empty group.
StatusOr<Eigen::VectorXi> TetStiffnessGroups(const FaceRig& rig, const TetShell& shell,
                                             const std::vector<StiffnessGroup>& groups);

struct TwinFitOptions {
  TissueOptions prior;  // the twin's material before the fit (the model's defaults)
  std::vector<StiffnessGroup> groups = DefaultStiffnessGroups();
  MaterialFitOptions fit;
  // Takes whose fitted weights differ by less than this (max abs) share one linearisation.
  double same_expression_tolerance = 0.05;
  // The platform's peak displacement (mm; the rig config's amplitude_mm). When > 0 the body's
  // transmissibility is fitted too (physics/body_transmissibility.h); 0: not known, not fitted.
  double platform_amplitude_mm = 0.0;
  Status Check() const;
};

// One platform take as the fit saw it.
struct TwinTake {
  std::string name;
  double platform_hz = 0.0;
  int held_frames = 0;
  Eigen::VectorXd weights;  // fitted held expression
  double blendshape_rms_mm = 0.0;
  double marker_amplitude_rms_mm = 0.0;   // RMS phasor modulus of the markers (skull frame)
  double skull_acceleration_mm_s2 = 0.0;  // modulus of the uniform acceleration load
  int linearisation = 0;                  // index of the shared linearisation
};

struct FittedTwin {
  std::string rig_name;
  TissueOptions prior;
  std::vector<StiffnessGroup> groups;
  TissueMaterial material;                 // ready for SoftTissueModel::SetMaterial
  Eigen::VectorXd group_scale;             // stiffness scale per group (relative to the prior)
  Eigen::VectorXd group_scale_log_stddev;  // standard deviation of each scale's logarithm
  double rayleigh_mass = 0.0, rayleigh_mass_log_stddev = 0.0;
  double rayleigh_stiffness = 0.0, rayleigh_stiffness_log_stddev = 0.0;
  DampedMode prior_cheek_mode;  // the prior's neutral cheek mode (continuous time)
  DampedMode cheek_mode;        // the fitted twin's
  double cheek_hz_stddev = 0.0, cheek_damping_ratio_stddev = 0.0;
  MaterialFitResult fit;
  std::vector<TwinTake> takes;
  int marker_count = 0;
  double seconds = 0.0;  // wall time of the fit
  // The body between platform and skull, when the platform amplitude was given and the takes
  // span at least three frequencies; otherwise body_note says why it was not fitted.
  std::optional<BodyFit> body;
  double platform_amplitude_mm = 0.0;
  std::string body_note;
};

// Fits the twin to `takes` (each with platform_hz; their names are for messages). Takes without
// a platform frequency, or with fewer than 8 held frames over at least two periods, are refused
// by name. Progress on stderr.
StatusOr<FittedTwin> FitTwin(const FaceRig& rig,
                             const std::vector<std::pair<std::string, const Take*>>& takes,
                             const TwinFitOptions& options);

// The twin as JSON (format "facedyn-twin" version 1): rig, prior, groups with scales and their
// uncertainty, material, cheek mode, the fit's figures and each take's, and "body" (the body
// fit, or {"fitted": false, "note"}).
Json TwinToJson(const FittedTwin& twin);

// A twin file read back for simulation: the prior's tissue options (layers, Poisson ratio,
// density, muscles) and the fitted material expanded to `rig`'s tetrahedra. Errors name the file
// and field; a twin fitted to another rig (by name) is refused.
struct LoadedTwin {
  TissueOptions tissue;
  TissueMaterial material;
  std::vector<StiffnessGroup> groups;
  DampedMode cheek_mode;
  // The fitted body (resonance, damping ratio, pitch per g), when the file has one.
  struct Body {
    double resonance_hz = 0.0, damping_ratio = 0.0, pitch_rad_per_g = 0.0;
  };
  std::optional<Body> body;
};
StatusOr<LoadedTwin> LoadTwin(const std::string& path, const FaceRig& rig);

}  // namespace facedyn::physics
