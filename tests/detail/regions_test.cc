#include "detail/regions.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/mesh_primitives.h"
#include "detail_test_util.h"

namespace facedyn::detail {
namespace {

std::vector<SurfacePoint> Points(const std::vector<Marker>& markers) {
  std::vector<SurfacePoint> p;
  for (const Marker& m : markers) p.push_back(m.point);
  return p;
}

TEST(MarkerRegions, WeightsSumToOneAndLeadAtTheirMarker) {
  const Mesh mesh = testing::TestPatch();
  const std::vector<Marker> markers = testing::TestMarkers(mesh);
  StatusOr<MarkerRegions> regions = ComputeMarkerRegions(mesh, Points(markers), 10.0);
  ASSERT_TRUE(regions.ok()) << regions.status().ToString();
  ASSERT_EQ(regions->region_count(), static_cast<int>(markers.size()));
  const Eigen::VectorXd sums = regions->WeightSums(mesh.vertex_count());
  EXPECT_LT((sums.array() - 1.0).abs().maxCoeff(), 1e-12);
  // Dense weights (regions x vertices) to compare regions at one vertex.
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(regions->region_count(), mesh.vertex_count());
  int overlapping = 0;
  for (int r = 0; r < regions->region_count(); ++r) {
    for (size_t k = 0; k < regions->vertices[r].size(); ++k) {
      const double w = regions->weights[r][k];
      EXPECT_GT(w, 0.0);
      EXPECT_LE(w, 1.0);
      dense(r, regions->vertices[r][k]) = w;
      if (w < 0.9) ++overlapping;
    }
  }
  // At its marker's vertex, a region outweighs every other region.
  for (int r = 0; r < regions->region_count(); ++r) {
    Eigen::Index best = -1;
    dense.col(markers[r].point.vertices[0]).maxCoeff(&best);
    EXPECT_EQ(best, r);
  }
  EXPECT_GT(overlapping, 0);  // soft boundaries: some vertices are shared
}

TEST(MeshGraphDistances, ExactAlongAGridLineOfAPlane) {
  // A flat grid (huge radii make the ellipsoid patch nearly flat: compare with the path along
  // its vertices, which is what an edge path follows).
  const Mesh mesh = MakeEllipsoidPatch(1e6, 1e6, 1e6, 1e-5, 1e-5, 10, 10);
  const Eigen::VectorXd d = MeshGraphDistances(mesh, {{0, 0.0}});
  double along = 0;
  for (int c = 1; c <= 10; ++c) {
    along += (mesh.positions_mm.col(c) - mesh.positions_mm.col(c - 1)).norm();
    EXPECT_NEAR(d[c], along, 1e-9 * along);
  }
}

TEST(MarkerRegions, BadInputNamed) {
  const Mesh mesh = testing::TestPatch();
  EXPECT_THAT(ComputeMarkerRegions(mesh, {SurfacePoint::AtVertex(0)}, 0.0).status().message(),
              ::testing::HasSubstr("sigma_mm"));
  EXPECT_THAT(ComputeMarkerRegions(mesh, {SurfacePoint::AtVertex(-2)}, 5.0).status().message(),
              ::testing::HasSubstr("marker 0 refers to vertex -2"));
}

}  // namespace
}  // namespace facedyn::detail
