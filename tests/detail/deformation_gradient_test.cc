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

TEST(DeformationGradients, ASubsetIsTheSameColumnsOfTheWhole) {
  const Mesh mesh = testing::TestPatch();
  Eigen::Matrix3Xd bent = mesh.positions_mm;
  for (int v = 0; v < bent.cols(); ++v) bent(2, v) += 0.002 * bent(0, v) * bent(1, v);
  const DeformationGradients gradients(mesh);
  Eigen::Matrix<double, 9, Eigen::Dynamic> all, some;
  gradients.Compute(bent, &all);
  const std::vector<int> subset = {gradients.triangle_count() - 1, 0, 17, 17, 400};
  gradients.Compute(bent, subset, &some);
  ASSERT_EQ(some.cols(), static_cast<int>(subset.size()));
  for (size_t k = 0; k < subset.size(); ++k)
    EXPECT_EQ(some.col(static_cast<int>(k)), all.col(subset[k])) << "triangle " << subset[k];
  gradients.Compute(bent, {}, &some);
  EXPECT_EQ(some.cols(), 0);
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

TEST(PatchRepresentatives, GroupsConnectedTrianglesOfACellAndNeverTwoSheets) {
  const Mesh mesh = testing::TestPatch();
  const Eigen::Matrix3Xi one = mesh.Triangles();
  const int t_one = static_cast<int>(one.cols()), v_one = mesh.vertex_count();
  // Two copies of the patch 0.5 mm apart (like closed lips): one cell holds both, no edge joins.
  Eigen::Matrix3Xd rest(3, 2 * v_one);
  rest << mesh.positions_mm, (mesh.positions_mm.colwise() + Eigen::Vector3d(0, 0, 0.5));
  Eigen::Matrix3Xi tris(3, 2 * t_one);
  tris << one, (one.array() + v_one).matrix();

  const std::vector<int> identity = PatchRepresentatives(rest, tris, 0.0);
  for (int t = 0; t < tris.cols(); ++t) ASSERT_EQ(identity[t], t);

  auto centroid = [&](int t) {
    return Eigen::Vector3d((rest.col(tris(0, t)) + rest.col(tris(1, t)) + rest.col(tris(2, t))) /
                           3.0);
  };
  const double cell = 10.0;
  const std::vector<int> rep = PatchRepresentatives(rest, tris, cell);
  ASSERT_EQ(rep.size(), static_cast<size_t>(tris.cols()));
  std::vector<int> patches;
  for (int t = 0; t < tris.cols(); ++t) {
    const int r = rep[t];
    ASSERT_GE(r, 0);
    ASSERT_LT(r, tris.cols());
    ASSERT_EQ(rep[r], r) << "a representative represents itself";
    ASSERT_EQ(t < t_one, r < t_one)
        << "triangle " << t << " of one sheet, " << r << " of the other";
    const Eigen::Vector3d a = (centroid(t) / cell).array().floor(),
                          b = (centroid(r) / cell).array().floor();
    ASSERT_EQ(a, b) << "triangle " << t << " and its representative share a cell";
    if (r == t) patches.push_back(t);
  }
  // The patch's triangles are about 4 mm across: a 10 mm cell holds several of them.
  EXPECT_LT(patches.size(), tris.cols() / 3);
  EXPECT_GT(patches.size(), 2u * static_cast<size_t>(80.0 * 100.0 / (cell * cell)) / 4);
  // A coarser cell makes fewer patches.
  const std::vector<int> coarse = PatchRepresentatives(rest, tris, 2 * cell);
  size_t coarse_patches = 0;
  for (int t = 0; t < tris.cols(); ++t) coarse_patches += coarse[t] == t ? 1 : 0;
  EXPECT_LT(coarse_patches, patches.size());
}

}  // namespace
}  // namespace facedyn::detail
