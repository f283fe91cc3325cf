// HarmonicTissueResponse: the steady-state response of the soft-tissue model to a sinusoidal
// skull motion (a held expression on the vibrating platform), and its derivatives with respect
// to the material — what material identification (physics/material_fit.h) fits to the
// platform takes of a capture session.
//
// Why it is shaped this way:
// - A platform take with a held expression is, after its settle time, a linear system driven at
//   one frequency. Its steady state is exact in the frequency domain: with phasors
//   (x(t) = Re(X e^{i w t})), M u'' + C u' + K u = F becomes A(w) U = F,
//   A = (1 + i w beta) K + (i w alpha - w^2) M, for Rayleigh damping C = alpha M + beta K.
//   No time stepping, so no integrator error and nothing to settle: one sparse complex LU per
//   take and evaluation (UMFPACK, SuiteSparse), and the continuous-time material — the one a
//   real actor's face has — is what the fit identifies.
// - The material is the model's own (SoftTissueModel::SystemParts) rescaled by parameters, all
//   logarithms so every value stays positive: theta = [log s_g for each stiffness group g,
//   log alpha, log beta], K = sum_g s_g K_g + springs. InitialParameters() reproduces the model.
// - Derivatives are forward sensitivities, dU/dtheta_j = -A^{-1} (dA/dtheta_j) U: one extra
//   solve with the same factorisation per parameter, fewer than the residuals (thousands of
//   marker coordinates) by far, so cheaper than an adjoint per residual. The finite-difference
//   test checks every parameter.
// - The load is the skull motion's phasor in the skull frame: the uniform acceleration field
//   (gravity's change in the skull frame minus the origin's acceleration) and the angular
//   acceleration. The centripetal and Coriolis terms are second order in the motion's amplitude
//   and are left out (at 2 mm and 11 Hz they are below 1e-3 of the linear terms).
// - Reduction. A full evaluation factorises the complex system (30,000 DOFs on the procedural
//   face: seconds), and a fit needs dozens. ReduceAt(theta) projects the system on
//   load-dependent Ritz vectors (Wilson, Yuan & Dickens 1982): the block Krylov space of
//   K^-1 M on K^-1 F, M-orthonormal, for the stiffness at theta. For that stiffness it is exact
//   at every frequency and damping up to the truncation ((1 + i w beta) K + c M = K (1 + i w beta
//   + c K^-1 M), whose inverse is a power series in K^-1 M), so a fit refreshes the basis at its
//   current parameters until they stop moving (physics/material_fit.h) and then agrees with the
//   full model; ReductionError measures how well.
// Units: mm, s, kg. Not thread-safe (the factorisation is reused between calls).
#pragma once

#include <Eigen/Core>
#include <complex>
#include <memory>
#include <vector>

#include "core/rigid3.h"
#include "core/status.h"
#include "physics/soft_tissue.h"

namespace facedyn::physics {

// A sinusoidal skull motion at one frequency, as phasors in the skull frame.
struct HarmonicSkullMotion {
  double frequency_hz = 0.0;
  // Uniform acceleration load: gravity's change in skull coordinates minus the skull origin's
  // acceleration, mm/s^2.
  Eigen::Vector3cd uniform_acceleration_in_skull = Eigen::Vector3cd::Zero();
  // Angular acceleration of the skull, skull coordinates, rad/s^2.
  Eigen::Vector3cd angular_acceleration_in_skull = Eigen::Vector3cd::Zero();
  // The motion itself: the skull origin's displacement (world, mm) and its rotation vector
  // relative to the mean rotation (skull coordinates, rad), what the loads were made from.
  Eigen::Vector3cd translation_in_world = Eigen::Vector3cd::Zero();
  Eigen::Vector3cd rotation_in_skull = Eigen::Vector3cd::Zero();
};

// The harmonic skull motion of a sampled pose track at `frequency_hz`: each of the skull's
// translation (world) and rotation vector (relative to the mean rotation, skull coordinates) is
// fitted by least squares with a constant, a linear drift and the sinusoid, and the loads follow
// to first order in the amplitude (acceleration -w^2 X; gravity's change -Phi x g_skull).
// Requires at least 8 samples spanning at least one period. Errors name what is missing.
StatusOr<HarmonicSkullMotion> FitHarmonicSkullMotion(const std::vector<double>& time_s,
                                                     const std::vector<Rigid3>& world_from_skull,
                                                     double frequency_hz);

// Phasor (3 x n) of each column's coordinates over time: samples[f] is 3 x n at time_s[f]; the
// same constant + drift + sinusoid least squares. Requires matching sizes and >= 8 samples.
StatusOr<Eigen::Matrix3Xcd> FitHarmonicPhasors(const std::vector<double>& time_s,
                                               const std::vector<Eigen::Matrix3Xd>& samples,
                                               double frequency_hz);

class HarmonicTissueResponse {
 public:
  // `observed_vertices` are the skin vertices whose response is returned (e.g. the markers');
  // each must be a free skin vertex of `parts` (not held by bone). Errors name the vertex.
  static StatusOr<std::unique_ptr<HarmonicTissueResponse>> Create(
      TissueSystemParts parts, std::vector<int> observed_vertices);
  ~HarmonicTissueResponse();

  int group_count() const { return static_cast<int>(parts_.stiffness_by_group.size()); }
  int parameter_count() const { return group_count() + 2; }
  const std::vector<int>& observed_vertices() const { return observed_; }
  // theta of the model the parts came from: 0 per group, log alpha, log beta (a damping
  // coefficient of 0 is taken as 1e-9 of its scale so its logarithm exists).
  Eigen::VectorXd InitialParameters() const;

  // Projects the system on `blocks` blocks of load-dependent Ritz vectors (up to 6 each) for the
  // stiffness at `theta`; Evaluate then solves the small dense system. UseFullSystem undoes it.
  Status ReduceAt(const Eigen::VectorXd& theta, int blocks);
  void UseFullSystem() { reduced_ = false; }
  bool reduced() const { return reduced_; }
  int basis_size() const { return static_cast<int>(basis_.cols()); }
  // |reduced - full| / |full| of the response at theta and motion (one full factorisation).
  StatusOr<double> ReductionError(const Eigen::VectorXd& theta,
                                  const HarmonicSkullMotion& motion) const;

  // Phasors (3 x n, mm) of the observed skin vertices' displacement from their targets, and if
  // `jacobian` is given its derivative per parameter (parameter_count() matrices).
  Status Evaluate(const Eigen::VectorXd& theta, const HarmonicSkullMotion& motion,
                  Eigen::Matrix3Xcd* response,
                  std::vector<Eigen::Matrix3Xcd>* jacobian = nullptr) const;

 private:
  HarmonicTissueResponse() = default;
  struct Solver;
  TissueSystemParts parts_;
  std::vector<int> observed_;
  std::vector<int> diagonal_entry_;  // per DOF: index of (d, d) in the shared value array
  std::unique_ptr<Solver> solver_;
  Status EvaluateFull(const Eigen::VectorXd& theta, const HarmonicSkullMotion& motion,
                      Eigen::Matrix3Xcd* response, std::vector<Eigen::Matrix3Xcd>* jacobian) const;
  Status EvaluateReduced(const Eigen::VectorXd& theta, const HarmonicSkullMotion& motion,
                         Eigen::Matrix3Xcd* response,
                         std::vector<Eigen::Matrix3Xcd>* jacobian) const;
  // The reduction: basis V (DOFs x N), V^T K_g V per group, V^T diag(springs) V, V^T M V (= I),
  // V^T load_fields, and the observed DOFs' rows of V.
  bool reduced_ = false;
  Eigen::MatrixXd basis_;
  std::vector<Eigen::MatrixXd> reduced_stiffness_;
  Eigen::MatrixXd reduced_springs_, reduced_mass_, reduced_loads_, observed_basis_;
};

}  // namespace facedyn::physics
