// SoftTissueModel: the flesh between skull and skin as a linear-tetrahedron FEM simulated in
// the skull frame, with exact ground truth for both the dynamic skin and the quasistatic skin
// (what the same skull motion and expression give without inertia).
//
// Why it is shaped this way:
// - Frame. The tissue is simulated in the skull's own (non-inertial) frame, where the
//   attached inner surface is fixed and head motion enters only as fictitious body forces
//   (physics/skull_kinematics.h) and a rotating gravity vector. Head rotation of any size is
//   therefore exact: nothing is linearised about the head pose, and the elastic problem only
//   sees the millimetre-scale motion of flesh relative to bone.
// - Expressions (after Bao et al. 2018, sections 5-6): blendshape-driven muscle tracks. Every
//   flesh node gets a target that moves linearly with the blendshape weights (the skin delta
//   blended with depth toward the mandible's motion, which rotates the jaw's bone attachment).
//   The targets act twice: as the tissue's active rest shape (so a held expression reproduces
//   the blendshape exactly, as captured expressions are equilibria), and as zero-length
//   springs whose stiffness grows with the local activation, so active flesh is stiffer and
//   jiggles differently (Zoss et al. 2020's second hypothesis). Changing expressions move the
//   targets, and their acceleration loads the flesh inertially (lips flap when they move).
// - Dynamics. Relative to the moving targets the flesh moves by millimetres, so elasticity is
//   linear about the reference expression's shape: M u'' + C u' + K u = F(t), with lumped
//   mass M, Rayleigh damping C = aM + bK, K the elastic stiffness of the expression's shape
//   plus the muscle springs, and F from gravity's change of direction, fictitious forces and
//   the targets' acceleration. Every force is an exact combination of a few precomputed
//   spatial fields. Newmark's average-acceleration rule integrates it (unconditionally stable,
//   energy-conserving when undamped): one prefactored sparse solve per step. The quasistatic
//   state is K u = F_static(t), an exact combination of precomputed static responses.
// - Gravity. The neutral mesh (and every blendshape) is taken as the equilibrium under
//   upright gravity, as a scan is; gravity acts through its change of direction in the skull.
// - Material. Young's modulus and the Rayleigh coefficients are calibrated so that the
//   neutral cheeks' dominant mode (subspace iteration on K phi = w^2 M phi) rings at
//   `fundamental_hz` with `damping_ratio` in the simulated motion, not merely in the continuous
//   system. Newmark's rule shifts a mode's period and decay: calibrated for the continuous
//   system, the default 11 Hz, 0.22 mode rang at 10.77 Hz, 0.210 at the shipped 1/128 s step
//   (Prony fit of the cheeks' free vibration, SoftTissueModel.
//   ShippedStepShowsConfiguredFrequencyAndDamping, before this calibration). So E and the
//   Rayleigh coefficients are set for the continuous mode that the step maps onto the
//   configured one (NewmarkCompensatedMode; 11.25 Hz, 0.2305 at 1/128 s), which keeps the cost
//   at one step per frame; the same test now measures 11.000 Hz, 0.2200. The step is the one
//   SetReference is given, i.e. the step actually taken (performance.cc subdivides frames to
//   stay under max_step_s); until then Create calibrates for max_step_s. Only the calibrated
//   mode is exact: the other elastic modes scale with the same E, so each keeps the difference
//   between Newmark's shift at its frequency and at the fundamental (small for the cluster
//   just above it, growing with frequency), and the muscle springs are not rescaled.
// Units: mm, s, kg; stress in kPa (1 kg mm^-1 s^-2 = 1 kPa).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "core/face_rig.h"
#include "core/status.h"
#include "physics/skull_kinematics.h"
#include "physics/tet_shell.h"

namespace facedyn::physics {

struct TissueOptions {
  int layers = 2;                          // tetrahedral layers through the tissue thickness
  double poisson_ratio = 0.45;             // nearly incompressible flesh
  double density_kg_per_mm3 = 1.1e-6;      // 1100 kg/m^3
  // Natural frequency of the neutral face's cheeks: of the lowest modes, the one that
  // dominates the cheeks' vertical response to head motion (the lowest mode if the rig has no
  // "cheeks" region). Young's modulus is calibrated to it.
  double fundamental_hz = 11.0;
  // Modal damping ratio at the fundamental. Soft-tissue figures range ~0.1-0.3; 0.22 makes an
  // 11 Hz, 2 mm platform give peak cheek offsets of 4-5 mm, the range Zoss et al. 2020 show
  // (Fig. 3, up to +-5 mm).
  double damping_ratio = 0.22;
  double mass_damping_share = 0.5;         // share of the damping ratio from the mass term
  // Zero-length muscle springs: a fully active spring alone would make the flesh it holds
  // oscillate at muscle_hz (k = m (2 pi muscle_hz)^2 per node), so fully active flesh rings at
  // about sqrt(f_flesh^2 + muscle_hz^2), ~1.5x the fundamental with the defaults.
  double muscle_hz = 12.0;
  double activation_full_mm = 3.0;         // blendshape displacement counted as full activation
  // Largest integration step; frames are subdivided to stay below it. The default is one step
  // per frame at 128 fps. The calibrated mode shows fundamental_hz and damping_ratio at any
  // step (see "Material"; measured 11.000 Hz, 0.2200 on the face at 1/128 s, and on a shell
  // patch at 1/128 s and 1/256 s), so a finer step only improves the other modes, whose
  // periods Newmark's rule lengthens by about (omega dt)^2 / 12 (Bathe, FE Procedures, 9.4),
  // less the fundamental's share that the stiffer E takes back. At least four steps per
  // period of fundamental_hz are required (fundamental_hz * max_step_s <= 0.25).
  double max_step_s = 1.0 / 128.0;

  Status Check() const;
};

// Skull-frame forcing at one instant.
struct TissueForcing {
  SkullKinematics kinematics;
  Eigen::VectorXd weights;                // blendshape weights
  Eigen::VectorXd weight_accelerations;   // d^2 weights / dt^2, 1/s^2 (empty = zero)
  double jaw_angle_rad = 0.0;             // mandible rotation about the rig's jaw axis
  double jaw_angle_velocity = 0.0;        // rad/s
  double jaw_angle_acceleration = 0.0;    // rad/s^2
};

struct ReferenceSummary {
  int inverted_elements = 0;  // tetrahedra the expression turns inside out (stiffness from |V|)
  double max_target_move_mm = 0.0;  // largest displacement of a target from the neutral
};

// A damped single-degree-of-freedom mode u'' + 2 zeta omega u' + omega^2 u = 0 (or one mode
// of M u'' + C u' + K u = 0 with Rayleigh damping), by its natural frequency and damping ratio:
// poles s = -zeta omega +- omega sqrt(zeta^2 - 1).
struct DampedMode {
  double omega_rad_s = 0.0;
  double damping_ratio = 0.0;
};

// What Newmark's average-acceleration rule (beta 1/4, gamma 1/2) at step dt_s makes of a mode:
// the rule is the trapezoidal rule on (u, u'), so each pole s becomes the eigenvalue
// z = (1 + s dt/2) / (1 - s dt/2) of the step's amplification matrix (Bathe, Finite Element
// Procedures, 9.4; its third eigenvalue is 0); the returned mode has the poles ln(z) / dt,
// i.e. the frequency and decay a sampled response shows. Requires dt_s > 0.
DampedMode NewmarkApparentMode(const DampedMode& continuous, double dt_s);

// The inverse: the continuous mode that the rule at step dt_s turns into `apparent`, from
// s = (2 / dt) tanh(s_apparent dt / 2). Requires apparent's damped frequency times dt_s below
// pi (it has no preimage beyond; TissueOptions asks for at least four steps per period).
DampedMode NewmarkCompensatedMode(const DampedMode& apparent, double dt_s);

// An explicit material in place of the calibration from TissueOptions' fundamental_hz and
// damping_ratio: what a fitted twin (physics/material_fit.h) carries. Young's modulus applies to
// every tetrahedron, scaled per tetrahedron (regional stiffness); damping is Rayleigh,
// C = alpha M + beta K.
struct TissueMaterial {
  double youngs_modulus_kpa = 0.0;
  Eigen::VectorXd tet_stiffness_scale;  // one per tetrahedron of shell(); empty = all 1
  double rayleigh_mass = 0.0;           // alpha, 1/s
  double rayleigh_stiffness = 0.0;      // beta, s
};

// The linear system about the current reference, split so a method can rescale its parts:
// M u'' + (alpha M + beta K) u' + K u = F, K = sum of stiffness_by_group + diag(spring_dofs).
// Indices are free degrees of freedom (3 per free node, x y z).
struct TissueSystemParts {
  std::vector<Eigen::SparseMatrix<double>> stiffness_by_group;  // elastic, same pattern each
  Eigen::VectorXd spring_dofs;  // muscle springs (diagonal), kg s^-2
  Eigen::VectorXd mass_dofs;    // lumped mass, kg
  // Force fields (3nf x 6) whose coefficients are skull-frame loads: columns 0-2 take the
  // uniform acceleration (gravity's change in the skull frame minus the origin's acceleration,
  // mm/s^2, x y z), columns 3-5 the negated angular acceleration (rad/s^2), which acts on the
  // reference positions as -m alpha x p.
  Eigen::MatrixXd load_fields;
  std::vector<int> skin_dof;  // per skin vertex: its first free DOF, or -1 (held)
  double rayleigh_mass = 0.0;
  double rayleigh_stiffness = 0.0;
};

// The skin of a held expression at its quasistatic equilibrium, and its derivatives with respect
// to the expression (the targeting gradient of Bao et al. 2018, sections 5-6). A held expression
// (w, jaw) is its own reference: the flesh's rest shape is Targets(w, jaw) and its stiffness K(w,
// jaw) is assembled about that shape with the muscle springs of w's activation, so under a change
// dg of gravity in the skull frame the skin settles at
//   x(w, jaw) = skin targets(w) + skin rows of u,   K(w, jaw) u = M dg.
// Upright (dg = 0) that is the blendshape skin exactly; tilted, the sag depends on the
// expression through K. Derivatives by forward sensitivities on the factorised K:
//   dx/dp = d skin targets/dp - skin rows of K^-1 (dK/dp u),
// one multi-right-hand-side solve for all parameters; dK/dp is the exact derivative of the
// element stiffnesses with respect to their rest geometry plus that of the springs (activation
// min(1, |skin delta| / activation_full_mm): one-sided where the skin delta is zero or at the
// clamp). The jaw moves no skin target in this model (the skin's share of the mandible is
// carried by the blendshapes), only the flesh beneath, so its column is the sag's change.
struct HeldExpressionSkin {
  Eigen::VectorXd skin_mm;        // 3n: the requested skin vertices, skull frame, x y z per vertex
  Eigen::MatrixXd jacobian;       // 3n x (K + 1): d skin / d (w_0 .. w_{K-1}, jaw angle in rad)
  double flesh_volume_mm3 = 0.0;  // the flesh at the equilibrium (sum of |tet volumes|)
};

class SoftTissueModel {
 public:
  // Builds the tet shell under the rig's skin, the mass, and calibrates the material.
  // Requires rig.skull to share the skin's topology.
  static StatusOr<std::unique_ptr<SoftTissueModel>> Create(const FaceRig& rig,
                                                           const TissueOptions& options);
  // The same with an explicit material from the start (a fitted twin's, SetMaterial's checks):
  // skips the calibration's eigensolve (about 2 of the 3 s Create takes on the procedural face),
  // which the material would replace anyway. Same model as Create then SetMaterial, except
  // that calibrated_mode() is empty.
  static StatusOr<std::unique_ptr<SoftTissueModel>> Create(const FaceRig& rig,
                                                           const TissueOptions& options,
                                                           const TissueMaterial& material);
  ~SoftTissueModel();

  const TetShell& shell() const { return shell_; }
  const TissueOptions& options() const { return options_; }
  double youngs_modulus_kpa() const { return youngs_modulus_kpa_; }
  double rayleigh_mass() const { return rayleigh_mass_; }
  double rayleigh_stiffness() const { return rayleigh_stiffness_; }
  int free_dof_count() const { return static_cast<int>(free_dofs_.size()); }
  int blendshape_count() const;
  int skin_vertex_count() const;

  // Lowest natural frequencies (Hz) of the continuous system K phi = w^2 M phi of the current
  // linearisation (after SetReference), or of the neutral face. With the step's compensation
  // they are above what the simulated motion shows (NewmarkApparentMode maps one to the other).
  StatusOr<std::vector<double>> NaturalFrequenciesHz(int count) const;

  // Sets the expression the dynamics are linearised about (its shape is the rest shape),
  // calibrates E and the Rayleigh coefficients for steps of dt_s (see "Material"), and
  // prefactors the system for them. Must be called before Reset/Step. Fails if dt_s leaves
  // fewer than four steps per period of fundamental_hz.
  StatusOr<ReferenceSummary> SetReference(const Eigen::VectorXd& weights, double jaw_angle_rad,
                                          double dt_s);

  // The same linearisation for the quasistatic parts only (QuasistaticSkin,
  // HeldSkinWithJacobian, SystemParts): no Newmark factorisation, about half SetReference's time.
  // Reset and Step then need SetReference.
  StatusOr<ReferenceSummary> SetStaticReference(const Eigen::VectorXd& weights,
                                                double jaw_angle_rad);

  // Starts at rest in the quasistatic state of `forcing` (zero velocity).
  void Reset(const TissueForcing& forcing);
  // Advances the dynamic state by dt_s to the instant described by `forcing`.
  void Step(const TissueForcing& forcing);

  // Skin positions in the skull frame (3 x V): dynamic state (at the last Reset/Step), and
  // the quasistatic state for a forcing (which does not change the dynamic state).
  Eigen::Matrix3Xd DynamicSkin() const;
  Eigen::Matrix3Xd QuasistaticSkin(const TissueForcing& forcing) const;
  // Reference expression's skin (the blendshape shape), skull frame.
  Eigen::Matrix3Xd ReferenceSkin() const;

  // Replaces the calibrated material (fundamental_hz, damping_ratio) with an explicit one, e.g.
  // a fitted twin's. Invalidates the reference: call SetReference again before stepping.
  // Fails, naming the field, on a non-positive modulus, negative damping, or a scale vector of
  // the wrong size or with a non-positive entry.
  Status SetMaterial(const TissueMaterial& material);
  TissueMaterial material() const;

  // The mode the material is calibrated on, for the current material and linearisation (the
  // neutral face's before any SetReference): among the lowest six of K phi = w^2 M phi, the one
  // that dominates the cheeks' vertical response to vertical head motion (the lowest without a
  // "cheeks" region). Continuous-time; damping ratio alpha / (2 w) + beta w / 2.
  StatusOr<DampedMode> CheekMode() const;

  // The linear system about the current reference (requires SetReference), with the elastic
  // stiffness split by `tet_group` (one entry per tetrahedron in [0, group_count)).
  StatusOr<TissueSystemParts> SystemParts(const Eigen::VectorXi& tet_group, int group_count) const;

  // The held expression's equilibrium skin at `vertices` (empty = every skin vertex) and its
  // Jacobian, about the current reference as the held expression (SetReference(w, jaw, dt)
  // first), under a change of gravity in the skull frame (mm/s^2; GravityInSkull() -
  // kGravityInWorld). See HeldExpressionSkin. Fails on a vertex outside the skin or no reference.
  // Without `with_jacobian` only the skin and the volume (one solve instead of K + 2).
  StatusOr<HeldExpressionSkin> HeldSkinWithJacobian(const Eigen::Vector3d& gravity_change_in_skull,
                                                    const std::vector<int>& vertices,
                                                    bool with_jacobian = true) const;
  // Volume of the flesh (sum of the tetrahedra's |volume|, mm^3) with its nodes at `nodes`
  // (3 x shell().node_count()), e.g. the neutral rest shape or an expression's targets.
  double FleshVolumeMm3(const Eigen::Matrix3Xd& nodes) const;
  // Every node's target for an expression (3 x shell().node_count(), skull frame): the rest shape
  // of the flesh the expression holds (Bao's targets; see the header).
  Eigen::Matrix3Xd NodeTargets(const Eigen::VectorXd& weights, double jaw_angle_rad) const;

  // Kinetic + elastic energy of the flesh's motion relative to its targets.
  double Energy() const;
  // For tests: sets a velocity field (per free DOF) on the current state.
  void SetVelocity(const Eigen::VectorXd& velocity);
  // The neutral face's calibrated mode shape on the free DOFs (M-normalised), e.g. to excite
  // the face along it with SetVelocity. Empty for a model created with an explicit material.
  const Eigen::VectorXd& calibrated_mode() const { return calibrated_mode_; }

 private:
  SoftTissueModel() = default;
  StatusOr<ReferenceSummary> SetReferenceWith(const Eigen::VectorXd& weights, double jaw_angle_rad,
                                              double dt_s, bool dynamics);
  static StatusOr<std::unique_ptr<SoftTissueModel>> CreateWith(const FaceRig& rig,
                                                               const TissueOptions& options,
                                                               const TissueMaterial* material);
  struct Impl;
  std::unique_ptr<Impl> impl_;
  TetShell shell_;
  TissueOptions options_;
  double youngs_modulus_kpa_ = 1.0;
  double rayleigh_mass_ = 0.0;
  double rayleigh_stiffness_ = 0.0;
  std::vector<int> free_dofs_;
  Eigen::VectorXd calibrated_mode_;
};

}  // namespace facedyn::physics
