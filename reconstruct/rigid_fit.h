// Weighted least-squares rigid alignment (Kabsch/Umeyama without scale).
#pragma once

#include <Eigen/Core>

#include "core/rigid3.h"

namespace facedyn::reconstruct {

// dst_from_src minimising sum_i w_i |dst_i - (R src_i + t)|^2 over rotations R (det +1).
// Preconditions: same column count, non-negative weights with a positive sum; at least three
// non-collinear points with positive weight for a unique answer.
Rigid3 FitRigid(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst,
                const Eigen::VectorXd& weights);
inline Rigid3 FitRigid(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst) {
  return FitRigid(src, dst, Eigen::VectorXd::Ones(src.cols()));
}

}  // namespace facedyn::reconstruct
