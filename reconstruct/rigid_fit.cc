#include "reconstruct/rigid_fit.h"

#include <Eigen/SVD>

#include "core/check.h"

namespace facedyn::reconstruct {

Rigid3 FitRigid(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst,
                const Eigen::VectorXd& weights) {
  FACEDYN_CHECK(src.cols() == dst.cols() && src.cols() == weights.size(), "FitRigid: sizes");
  const double total = weights.sum();
  FACEDYN_CHECK(total > 0, "FitRigid: weights must have a positive sum");
  const Eigen::Vector3d src_mean = (src * weights) / total;
  const Eigen::Vector3d dst_mean = (dst * weights) / total;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (int i = 0; i < src.cols(); ++i) {
    covariance += weights[i] * (dst.col(i) - dst_mean) * (src.col(i) - src_mean).transpose();
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance,
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) d(2, 2) = -1.0;
  const Eigen::Matrix3d rotation = svd.matrixU() * d * svd.matrixV().transpose();
  return Rigid3(Eigen::Quaterniond(rotation), dst_mean - rotation * src_mean);
}

}  // namespace facedyn::reconstruct
