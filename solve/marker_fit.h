// The matching approach of FDLS (Eq. 2): bounded least squares of the puppet's markers against
// observed ones,
//
//   min_w  sum_t |x_0 + B w_t - x_t|^2  +  lambda sum_t |w_t - w_{t-1}|^2   s.t.  l <= w_t <= u,
//
// over a chosen subset of channels (the rest frozen at their starting value). Two uses:
//   - the QP baseline: every channel free, started from zero, lambda = 0 (one problem a frame);
//   - fine-tuning (section 4.5): started from the network's solve, the artist's channels free,
//     optional temporal smoothness lambda (then one problem over the whole range, since the
//     smoothness term couples the frames).
// Solved with Ceres' trust-region minimiser, whose bounds constraints keep every iterate within
// [l, u]; the problem is linear least squares, so a few iterations converge. (Ceres' L-BFGS
// line search, the paper's optimiser, does not take bounds.) Missing markers contribute no
// residual.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/status.h"
#include "solve/puppet.h"

namespace facedyn::solve {

// M x N flags, true where a marker was observed in a frame.
using MarkerPresence = Eigen::Array<bool, Eigen::Dynamic, Eigen::Dynamic>;

struct MarkerFitOptions {
  std::vector<int> free_channels;  // puppet channel indices; empty: every channel
  double smoothness = 0.0;         // lambda, mm^2 per unit weight^2 per frame step
  int max_iterations = 50;
  int num_threads = 1;
  // Channels in range and unique, smoothness >= 0, iterations >= 1. Names the field.
  Status Check(int channel_count) const;
};

struct MarkerFitSummary {
  bool converged = true;  // every Ceres problem ended on a convergence criterion
  int problems = 0;
  int iterations = 0;            // summed over problems
  double initial_rmse_mm = 0.0;  // marker RMSE of the start
  double final_rmse_mm = 0.0;
  double solve_s = 0.0;
};

// Weights (C x N) that minimise the energy above, starting from `initial` (C x N, clamped into
// the bounds first). markers: 3M x N skull frame, mm. present: M x N or null (all present).
// Frozen channels keep their (clamped) initial value exactly. Errors: sizes, options, a frame
// without any marker, a Ceres failure.
StatusOr<Eigen::MatrixXd> FitWeightsToMarkers(const Puppet& puppet, const Eigen::MatrixXd& markers,
                                              const Eigen::MatrixXd& initial,
                                              const MarkerPresence* present,
                                              const MarkerFitOptions& options,
                                              MarkerFitSummary* summary);

// The QP baseline: every channel free from zero, per frame.
StatusOr<Eigen::MatrixXd> SolveMarkersQp(const Puppet& puppet, const Eigen::MatrixXd& markers,
                                         const MarkerPresence* present, MarkerFitSummary* summary);

// RMS over frames and present markers of the distance (mm) between the puppet's markers for
// `weights` (C x N) and `markers` (3M x N).
double MarkerRmseMm(const Puppet& puppet, const Eigen::MatrixXd& weights,
                    const Eigen::MatrixXd& markers, const MarkerPresence* present = nullptr);

}  // namespace facedyn::solve
