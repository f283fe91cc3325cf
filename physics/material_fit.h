// Material identification: the twin's regional stiffness and Rayleigh damping fitted to the
// steady-state skin motion of platform takes (held expressions on the vibrating platform), by
// bounded nonlinear least squares on the harmonic response (physics/harmonic_response.h).
//
// Why it is shaped this way:
// - A capture session already has what identifies the material: each platform take holds an
//   expression at one frequency, and its markers' phasors in the skull frame (amplitude and
//   phase against the measured skull motion) sample the face's frequency response. Takes at
//   6-10 Hz below an 11 Hz resonance fix both the resonance (from the amplitude's rise) and the
//   damping (from the phase lag).
// - Only what a capture has enters: the markers' phasors, the skull motion's phasor, the held
//   expression's blendshape weights (each observation's model is linearised about them). A
//   method never sees the simulator's true tissue parameters; tests score against them.
// - Ceres' Levenberg-Marquardt on log parameters with bounds (a scale of 1/20..20 per group,
//   damping within four decades), with the analytic forward-sensitivity Jacobian. The
//   uncertainty is the Gauss-Newton covariance scaled by the residual variance (Ceres'
//   Covariance), one standard deviation per parameter.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/status.h"
#include "physics/harmonic_response.h"

namespace facedyn::physics {

// One platform take's steady state.
struct PlatformObservation {
  std::string name;                         // for messages, e.g. the take folder
  HarmonicTissueResponse* model = nullptr;  // linearised about the take's held expression
  HarmonicSkullMotion motion;
  Eigen::Matrix3Xcd skin_phasors_mm;  // per observed vertex of `model`, skull frame
};

struct MaterialFitOptions {
  int max_iterations = 40;
  double max_scale = 20.0;  // stiffness groups within [1/max_scale, max_scale] x initial
  double damping_decades = 2.0;
  // Load-dependent Ritz blocks per reduction (HarmonicTissueResponse::ReduceAt); 0 fits on the
  // full system (one complex sparse LU per observation and evaluation: slow on a face).
  int reduction_blocks = 12;
  int max_reductions = 4;             // refreshes of the basis at the current parameters
  double reduction_tolerance = 1e-3;  // stop refreshing when no parameter moved more (log)
  bool check_reduction = true;  // compare with the full system at the result (one LU each)  //
                                // alpha and beta within 10^(+-decades) x initial
  Status Check() const;
};

struct MaterialFitResult {
  Eigen::VectorXd theta;         // HarmonicTissueResponse's parameters
  Eigen::VectorXd theta_stddev;  // one standard deviation each (NaN when not estimable)
  Eigen::MatrixXd covariance;    // of theta (NaN when not estimable)
  double rms_initial_mm = 0.0;   // RMS of the phasor residual (per coordinate, complex modulus)
  double rms_final_mm = 0.0;
  int iterations = 0;            // over every reduction round
  int reductions = 0;            // bases built (0: the full system)
  double reduction_error = 0.0;  // max |reduced - full| / |full| at the result (if checked)
  bool converged = false;
  std::string message;  // Ceres' one-line summary
};

// Fits the parameters shared by every observation's model (all must have the same parameter
// count), starting from the first model's InitialParameters(). Errors name the observation.
StatusOr<MaterialFitResult> FitTissueMaterial(const std::vector<PlatformObservation>& observations,
                                              const MaterialFitOptions& options);

}  // namespace facedyn::physics
