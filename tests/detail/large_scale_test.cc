#include "detail/large_scale.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "detail_test_util.h"

namespace facedyn::detail {
namespace {

std::vector<SurfacePoint> Points(const std::vector<Marker>& markers) {
  std::vector<SurfacePoint> p;
  for (const Marker& m : markers) p.push_back(m.point);
  return p;
}

Eigen::Matrix3Xd MarkersOn(const std::vector<Marker>& markers, const Eigen::Matrix3Xd& x) {
  Eigen::Matrix3Xd p(3, static_cast<int>(markers.size()));
  for (size_t m = 0; m < markers.size(); ++m)
    p.col(static_cast<int>(m)) = markers[m].point.Evaluate(x);
  return p;
}

TEST(LaplacianDeformer, NeutralMarkersGiveTheNeutral) {
  const Mesh mesh = testing::TestPatch();
  const std::vector<Marker> markers = testing::TestMarkers(mesh);
  StatusOr<LaplacianDeformer> deformer = LaplacianDeformer::Create(mesh, Points(markers), {});
  ASSERT_TRUE(deformer.ok()) << deformer.status().ToString();
  Eigen::Matrix3Xd x;
  deformer->Deform(MarkersOn(markers, mesh.positions_mm), &x);
  EXPECT_LT((x - mesh.positions_mm).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(LaplacianDeformer, TranslationIsExact) {
  const Mesh mesh = testing::TestPatch();
  const std::vector<Marker> markers = testing::TestMarkers(mesh);
  StatusOr<LaplacianDeformer> deformer = LaplacianDeformer::Create(mesh, Points(markers), {});
  ASSERT_TRUE(deformer.ok());
  const Eigen::Vector3d t(4.0, -7.5, 12.0);
  Eigen::Matrix3Xd x;
  deformer->Deform(MarkersOn(markers, mesh.positions_mm).colwise() + t, &x);
  EXPECT_LT(((x - mesh.positions_mm).colwise() - t).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(LaplacianDeformer, MarkerResidualFallsWithWeight) {
  // One marker pushed 5 mm out: the soft constraint leaves a residual ~ 1/w.
  const Mesh mesh = testing::TestPatch();
  const std::vector<Marker> markers = testing::TestMarkers(mesh);
  Eigen::Matrix3Xd p = MarkersOn(markers, mesh.positions_mm);
  p(2, 5) += 5.0;
  double residual[2];
  const double weights[2] = {10.0, 1000.0};
  for (int i = 0; i < 2; ++i) {
    LaplacianDeformerOptions options;
    options.marker_weight = weights[i];
    StatusOr<LaplacianDeformer> deformer =
        LaplacianDeformer::Create(mesh, Points(markers), options);
    ASSERT_TRUE(deformer.ok());
    Eigen::Matrix3Xd x;
    deformer->Deform(p, &x);
    residual[i] = (markers[5].point.Evaluate(x) - p.col(5)).norm();
  }
  EXPECT_LT(residual[1], 0.05 * residual[0]);
  EXPECT_LT(residual[1], 0.25);  // default weight: within 5% of the push
}

TEST(LaplacianDeformer, MarkerResponseEqualsBackSubstitution) {
  const Mesh mesh = testing::TestPatch();
  const std::vector<Marker> markers = testing::TestMarkers(mesh);
  StatusOr<LaplacianDeformer> deformer = LaplacianDeformer::Create(mesh, Points(markers), {});
  ASSERT_TRUE(deformer.ok());
  const Eigen::Matrix3Xd p = MarkersOn(markers, testing::TestFrame(mesh, 0.8, -0.4));
  Eigen::Matrix3Xd a, b;
  deformer->Deform(p, &a);
  deformer->DeformBySolve(p, &b);
  EXPECT_LT((a - b).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_GT((a - mesh.positions_mm).cwiseAbs().maxCoeff(), 1.0);
}

TEST(LaplacianDeformer, BadInputNamed) {
  const Mesh mesh = testing::TestPatch();
  std::vector<SurfacePoint> points{SurfacePoint::AtVertex(0),
                                   SurfacePoint::AtVertex(mesh.vertex_count() + 3)};
  StatusOr<LaplacianDeformer> deformer = LaplacianDeformer::Create(mesh, points, {});
  ASSERT_FALSE(deformer.ok());
  EXPECT_THAT(deformer.status().message(), ::testing::HasSubstr("marker 1 refers to vertex"));
  LaplacianDeformerOptions options;
  options.marker_weight = -1;
  EXPECT_THAT(
      LaplacianDeformer::Create(mesh, {SurfacePoint::AtVertex(0)}, options).status().message(),
      ::testing::HasSubstr("marker_weight"));
  EXPECT_FALSE(LaplacianDeformer::Create(mesh, {}, {}).ok());
}

TEST(TangentFrames, OrthonormalAndFollowARigidMotion) {
  const Mesh mesh = testing::TestPatch();
  const TangentFrames tangent(mesh);
  const Eigen::Matrix3d r =
      Eigen::AngleAxisd(1.1, Eigen::Vector3d(0.3, -1, 0.2).normalized()).toRotationMatrix();
  Eigen::Matrix<double, 9, Eigen::Dynamic> rest, moved;
  tangent.Compute(mesh.positions_mm, &rest);
  tangent.Compute((r * mesh.positions_mm).colwise() + Eigen::Vector3d(1, 2, 3), &moved);
  for (int v = 0; v < mesh.vertex_count(); ++v) {
    const Eigen::Map<const Eigen::Matrix3d> a(rest.col(v).data()), b(moved.col(v).data());
    ASSERT_LT((a.transpose() * a - Eigen::Matrix3d::Identity()).norm(), 1e-12);
    ASSERT_NEAR(a.determinant(), 1.0, 1e-12);
    ASSERT_LT((b - r * a).norm(), 1e-9) << "vertex " << v;
  }
  // Local offsets round trip.
  const Eigen::Matrix3Xd x = testing::TestFrame(mesh, 0.5, -0.5);
  Eigen::Matrix3Xd local, back;
  TangentFrames::ToLocal(moved, mesh.positions_mm, x, &local);
  TangentFrames::FromLocal(moved, mesh.positions_mm, local, &back);
  EXPECT_LT((back - x).cwiseAbs().maxCoeff(), 1e-10);
}

}  // namespace
}  // namespace facedyn::detail
