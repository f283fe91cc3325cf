// Shape alignment with anchor poses (FDLS section 4.4.2, Eq. 5).
//
// A shot's markers can differ from the puppet's by a constant offset per marker (a mask placed
// a little differently, a face that changed slightly). With an anchor frame a whose weights
// w_a the artist sets (the neutral, w_a = 0, for a neutral-ish frame), the offsets
//   o = x_a - (x_0 + B w_a)
// are subtracted from every frame, weighted per frame by alpha_t (Eq. 5); for the first anchor
// every alpha_t is 1. The trained solver is then re-run on the aligned markers, no retraining.
#pragma once

#include <Eigen/Core>

#include "core/status.h"
#include "solve/puppet.h"

namespace facedyn::solve {

// Offsets o (3M, stacked) of anchor frame `anchor_frame` of `markers` (3M x N) against the
// puppet posed at `anchor_weights` (C). Errors: sizes, a frame out of range.
StatusOr<Eigen::VectorXd> AnchorOffsets(const Puppet& puppet, const Eigen::MatrixXd& markers,
                                        int anchor_frame, const Eigen::VectorXd& anchor_weights);

// markers_t - alpha_t o for every frame (alpha: N, or empty for all ones).
StatusOr<Eigen::MatrixXd> AlignToAnchor(const Eigen::MatrixXd& markers,
                                        const Eigen::VectorXd& offsets,
                                        const Eigen::VectorXd& alpha = Eigen::VectorXd());

}  // namespace facedyn::solve
