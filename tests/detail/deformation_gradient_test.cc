#include "detail/deformation_gradient.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "detail_test_util.h"

namespace facedyn::detail {
namespace {

TEST(DeformationGradients, RigidMotionGivesRotations) {
  const Mesh mesh = testing::TestPatch();
  const Eigen::Matrix3d r = (Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, -1).normalized()) *
                             Eigen::AngleAxisd(-0.3, Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  const Eigen::Vector3d t(12.0, -5.0, 30.0);
  const Eigen::Matrix3Xd moved = (r * mesh.positions_mm).colwise() + t;
  const DeformationGradients gradients(mesh);
  Eigen::Matrix<double, 9, Eigen::Dynamic> f;
  gradients.Compute(moved, &f);
  ASSERT_EQ(f.cols(), gradients.triangle_count());
  ASSERT_GT(f.cols(), 1000);
  for (int k = 0; k < f.cols(); ++k) {
    const Eigen::Map<const Eigen::Matrix3d> fk(f.col(k).data());
    ASSERT_LT((fk - r).norm(), 1e-9) << "triangle " << k;
    ASSERT_LT((fk.transpose() * fk - Eigen::Matrix3d::Identity()).norm(), 1e-9);
    ASSERT_NEAR(fk.determinant(), 1.0, 1e-9);
  }
}

TEST(DeformationGradient, InPlaneScaleKeepsTheNormal) {
  Eigen::Matrix3d rest;
  rest << 0, 10, 2, 0, 1, 7, 0, 3, -1;  // columns a, b, c
  const Eigen::Matrix3d f = DeformationGradient(rest, 2.0 * rest);
  const Eigen::Vector3d e1 = rest.col(1) - rest.col(0), e2 = rest.col(2) - rest.col(0);
  const Eigen::Vector3d n = e1.cross(e2).normalized();
  EXPECT_LT((f * e1 - 2.0 * e1).norm(), 1e-12);
  EXPECT_LT((f * e2 - 2.0 * e2).norm(), 1e-12);
  EXPECT_LT((f * n - n).norm(), 1e-12);
}

TEST(DeformationGradient, BendingChangesIt) {
  // The property Masquerade wants over edge strain: fold a triangle about an edge without
  // stretching it and F changes (its normal column turns) although every edge length is kept.
  Eigen::Matrix3d rest;
  rest << 0, 10, 0, 0, 0, 10, 0, 0, 0;
  Eigen::Matrix3d folded = rest;
  folded.col(2) = Eigen::Vector3d(0, 10 * std::cos(0.5), 10 * std::sin(0.5));
  const Eigen::Matrix3d f = DeformationGradient(rest, folded);
  EXPECT_NEAR((folded.col(2) - folded.col(0)).norm(), 10.0, 1e-12);
  EXPECT_GT((f - Eigen::Matrix3d::Identity()).norm(), 0.4);
}

}  // namespace
}  // namespace facedyn::detail
