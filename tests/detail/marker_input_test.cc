// MarkersFromTracks: tracked markers into the skull frame, missing ones held and counted, and
// a layout the tracks do not have named.

#include "detail/marker_input.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace facedyn::detail {
namespace {

using ::testing::HasSubstr;

Mesh ThreeVertexMesh() {
  Mesh mesh;
  mesh.positions_mm.resize(3, 3);
  mesh.positions_mm << 0, 10, 0,  //
      0, 0, 10,                   //
      0, 0, 0;
  mesh.AddFace({0, 1, 2});
  return mesh;
}

TEST(MarkersFromTracks, SkullFrameHeldAndNamed) {
  const Mesh neutral = ThreeVertexMesh();
  const std::vector<Marker> layout = {{"b", SurfacePoint::AtVertex(1), 2.0},
                                      {"a", SurfacePoint::AtVertex(0), 2.0},
                                      {"c", SurfacePoint::AtVertex(2), 2.0}};
  MarkerTracks tracks;
  tracks.names = {"a", "b", "c"};
  tracks.time_s = {0.0, 0.1, 0.2};
  tracks.world_mm = Eigen::MatrixXd::Constant(9, 3, std::numeric_limits<double>::quiet_NaN());
  tracks.confidence = Eigen::MatrixXd::Zero(3, 3);
  tracks.state.assign(3, std::vector<MarkerTrackState>(3, MarkerTrackState::kMissing));
  // World = skull shifted by +5 mm in x on every frame.
  const std::vector<Rigid3> world_from_skull(3, Rigid3::FromTranslation({5, 0, 0}));
  auto observe = [&](int marker, int frame, const Eigen::Vector3d& in_skull) {
    tracks.world_mm.block(3 * marker, frame, 3, 1) = in_skull + Eigen::Vector3d(5, 0, 0);
    tracks.confidence(marker, frame) = 1.0;
    tracks.state[frame][marker] = MarkerTrackState::kObserved;
  };
  observe(0, 0, {1, 2, 3});  // a: seen on frame 0 only
  observe(1, 1, {4, 5, 6});  // b: seen on frame 1 only
  observe(1, 2, {7, 8, 9});  //    and frame 2           (c: never)
  const auto frames = MarkersFromTracks(tracks, world_from_skull, layout, neutral);
  ASSERT_TRUE(frames.ok()) << frames.status().ToString();
  ASSERT_EQ(frames->markers_mm.size(), 3u);
  // Layout order b, a, c; skull frame (the +5 mm gone).
  EXPECT_TRUE(frames->markers_mm[1].col(0).isApprox(Eigen::Vector3d(4, 5, 6)));
  EXPECT_TRUE(frames->markers_mm[2].col(0).isApprox(Eigen::Vector3d(7, 8, 9)));
  EXPECT_TRUE(frames->markers_mm[0].col(0).isApprox(Eigen::Vector3d(4, 5, 6)));  // before: first
  EXPECT_TRUE(frames->markers_mm[0].col(1).isApprox(Eigen::Vector3d(1, 2, 3)));
  EXPECT_TRUE(frames->markers_mm[2].col(1).isApprox(Eigen::Vector3d(1, 2, 3)));   // after: last
  EXPECT_TRUE(frames->markers_mm[1].col(2).isApprox(Eigen::Vector3d(0, 10, 0)));  // neutral
  EXPECT_EQ(frames->filled, 1 + 2 + 3);
  ASSERT_EQ(frames->never_seen.size(), 1u);
  EXPECT_EQ(frames->never_seen[0], "c");

  const std::vector<Marker> other = {{"z", SurfacePoint::AtVertex(0), 2.0}};
  EXPECT_THAT(MarkersFromTracks(tracks, world_from_skull, other, neutral).status().message(),
              HasSubstr("marker 'z' of the model's layout is not in the take's marker tracks"));
  EXPECT_THAT(MarkersFromTracks(tracks, {Rigid3()}, layout, neutral).status().message(),
              HasSubstr("3 frames but the take has 1 skull poses"));
}

}  // namespace
}  // namespace facedyn::detail
