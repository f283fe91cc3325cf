// SoftTissueModel: the flesh between skull and skin as a corotational linear-tetrahedron FEM,
// simulated in the skull frame, with exact ground truth for both the dynamic skin and the
// quasistatic skin (what the same skull motion and expression give without inertia).
//
// Why it is shaped this way:
// - Frame. The tissue is simulated in the skull's own (non-inertial) frame, where the
//   attached inner surface is fixed and head motion enters only as fictitious body forces
//   (sim/skull_kinematics.h) and a rotating gravity vector. Head rotation of any size is
//   therefore exact; nothing is linearised about the head pose.
// - Expressions (Bao et al. 2018, sections 5-6): blendshape-driven muscle tracks. Every flesh
//   node in an active region gets an interior target that moves linearly with the blendshape
//   weights (the skin delta blended with depth toward the mandible's motion), and a
//   zero-length spring pulls it there; its stiffness grows with the local activation, so an
//   active face is stiffer and jiggles differently. The expression's shape is the nonlinear
//   corotational equilibrium (Newton) under those springs and gravity.
// - Dynamics. Around that reference equilibrium the skin moves by millimetres, so the
//   equations of motion are linearised there: M u'' + C u' + K u = F(t), with K the
//   corotational stiffness at the reference (rotations frozen), Rayleigh damping C = aM + bK,
//   lumped mass M, and F from gravity's change of direction, fictitious forces, the change of
//   the expression's muscle targets and the mandible's prescribed motion. Newmark's average-
//   acceleration rule integrates it: unconditionally stable and energy-conserving for the
//   undamped system, one prefactored sparse solve per step. The quasistatic skin is
//   K u = F_static(t) (the same forces without inertia), one prefactored solve per frame.
// - Material. The Young's modulus is calibrated so the neutral face's lowest natural
//   frequency equals `fundamental_hz` (subspace iteration on K phi = w^2 M phi), and the
//   Rayleigh coefficients give `damping_ratio` at that frequency, so the two figures a user
//   configures are the two figures the face has.
// Units: mm, s, kg; stress in kPa (1 kg mm^-1 s^-2 = 1 kPa).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "core/face_rig.h"
#include "core/status.h"
#include "sim/skull_kinematics.h"
#include "sim/tet_shell.h"

namespace facedyn::sim {

struct TissueOptions {
  int layers = 2;                          // tetrahedral layers through the tissue thickness
  double poisson_ratio = 0.45;             // nearly incompressible flesh
  double density_kg_per_mm3 = 1.1e-6;      // 1100 kg/m^3
  double fundamental_hz = 11.0;            // neutral face's lowest natural frequency
  double damping_ratio = 0.15;             // modal damping ratio at the fundamental
  double mass_damping_share = 0.5;         // share of the damping ratio from the mass term
  double muscle_stiffness_ratio = 2.0;     // spring stiffness at full activation / node's elastic stiffness
  double activation_full_mm = 4.0;         // blendshape displacement counted as full activation
  double max_step_s = 0.004;               // largest integration step (frames are subdivided)

  Status Check() const;
};

// Skull-frame forcing at one instant.
struct TissueForcing {
  SkullKinematics kinematics;
  Eigen::VectorXd weights;    // blendshape weights
  double jaw_angle_rad = 0.0;  // mandible rotation about the rig's jaw axis
};

struct ReferenceSummary {
  bool converged = false;
  int iterations = 0;
  double max_residual = 0.0;  // largest nodal force residual, kg mm s^-2
};

class SoftTissueModel {
 public:
  // Builds the tet shell under the rig's skin, the mass, and calibrates the material.
  // Requires rig.skull to share the skin's topology.
  static StatusOr<std::unique_ptr<SoftTissueModel>> Create(const FaceRig& rig,
                                                           const TissueOptions& options);
  ~SoftTissueModel();

  const TetShell& shell() const { return shell_; }
  const TissueOptions& options() const { return options_; }
  double youngs_modulus_kpa() const { return youngs_modulus_kpa_; }
  double rayleigh_mass() const { return rayleigh_mass_; }
  double rayleigh_stiffness() const { return rayleigh_stiffness_; }
  int free_dof_count() const { return static_cast<int>(free_dofs_.size()); }

  // Lowest natural frequencies (Hz) of the current linearisation (after SetReference), or of
  // the neutral face.
  StatusOr<std::vector<double>> NaturalFrequenciesHz(int count) const;

  // Solves the expression's equilibrium (head upright, gravity -Y) and prefactors the
  // linearised system for steps of dt_s. Must be called before Reset/Step.
  StatusOr<ReferenceSummary> SetReference(const Eigen::VectorXd& weights, double jaw_angle_rad,
                                          double dt_s);

  // Starts at rest in the quasistatic state of `forcing` (zero velocity).
  void Reset(const TissueForcing& forcing);
  // Advances the dynamic state by dt_s to the instant described by `forcing`.
  void Step(const TissueForcing& forcing);

  // Skin positions in the skull frame (3 x V): dynamic state, and the quasistatic state for
  // a forcing (which does not change the dynamic state).
  Eigen::Matrix3Xd DynamicSkin() const;
  Eigen::Matrix3Xd QuasistaticSkin(const TissueForcing& forcing) const;
  // Reference (expression equilibrium) skin, skull frame.
  Eigen::Matrix3Xd ReferenceSkin() const;

  // Kinetic + elastic energy of the linearised state (u' M u' / 2 + u K u / 2).
  double Energy() const;
  // For tests: sets a velocity field (per free DOF) on the current state.
  void SetVelocity(const Eigen::VectorXd& velocity);

 private:
  SoftTissueModel() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  TetShell shell_;
  TissueOptions options_;
  double youngs_modulus_kpa_ = 1.0;
  double rayleigh_mass_ = 0.0;
  double rayleigh_stiffness_ = 0.0;
  std::vector<int> free_dofs_;
};

}  // namespace facedyn::sim
