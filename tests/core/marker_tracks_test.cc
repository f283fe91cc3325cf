// Marker tracks files (core/marker_tracks.h): round trip, the skull-frame file, and damaged
// files named by file, line and field.
#include "core/marker_tracks.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::ReadBytes;
using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

MarkerTracks TwoMarkers() {
  MarkerTracks t;
  t.names = {"brow_l", "chin"};
  t.time_s = {0.0, 0.0078125, 0.015625};
  t.world_mm.resize(6, 3);
  t.confidence.resize(2, 3);
  t.state.assign(3, std::vector<MarkerTrackState>(2, MarkerTrackState::kObserved));
  for (int f = 0; f < 3; ++f) {
    t.world_mm.col(f) << 10 + f, 20, 30, -5, -40 - 0.5 * f, 12;
    t.confidence.col(f) << 0.9, 0.8;
  }
  t.state[1][1] = MarkerTrackState::kMissing;
  t.world_mm.block(3, 1, 3, 1).setConstant(std::nan(""));
  t.confidence(1, 1) = 0.0;
  t.state[2][1] = MarkerTrackState::kBridged;
  return t;
}

TEST(MarkerTracks, RoundTripAndSkullFrameFile) {
  TempDir dir;
  const MarkerTracks tracks = TwoMarkers();
  const std::vector<Rigid3> poses(3, Rigid3::FromTranslation(Eigen::Vector3d(10, 0, 0)));
  ASSERT_TRUE(SaveMarkerTracks(tracks, poses, dir.path()).ok());
  const auto loaded = LoadMarkerTracks(dir.path());
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->names, tracks.names);
  EXPECT_EQ(loaded->time_s, tracks.time_s);
  for (int f = 0; f < 3; ++f) {
    for (int i = 0; i < 2; ++i) {
      EXPECT_EQ(loaded->state[f][i], tracks.state[f][i]);
      EXPECT_NEAR(loaded->confidence(i, f), tracks.confidence(i, f), 1e-4);
      if (tracks.present(i, f)) {
        EXPECT_LT(
            (loaded->world_mm.block(3 * i, f, 3, 1) - tracks.world_mm.block(3 * i, f, 3, 1)).norm(),
            1e-5);
      } else {
        EXPECT_TRUE(std::isnan(loaded->world_mm(3 * i, f)));
      }
    }
  }
  // Skull frame: the pose's translation taken off; the missing marker's fields empty.
  const std::string skull = ReadBytes(dir.Join(kMarkerTracksSkullFile));
  EXPECT_THAT(skull, HasSubstr("time_s,brow_l_x,brow_l_y,brow_l_z,chin_x,chin_y,chin_z\n"));
  EXPECT_THAT(skull, HasSubstr("0.0078125,1.000000,20.000000,30.000000,,,\n"));
  EXPECT_THAT(ReadBytes(dir.Join(kMarkerTracksFile)),
              HasSubstr("1,0.0078125,chin,missing,0.0000,,,\n"));
}

TEST(MarkerTracks, AbsentIsNotFound) {
  TempDir dir;
  const auto loaded = LoadMarkerTracks(dir.path());
  ASSERT_FALSE(loaded.ok());
  EXPECT_EQ(loaded.status().code(), StatusCode::kNotFound);
}

TEST(MarkerTracks, RefusesInconsistentTracksBeforeWriting) {
  TempDir dir;
  MarkerTracks tracks = TwoMarkers();
  tracks.confidence(0, 0) = 1.5;
  EXPECT_FALSE(SaveMarkerTracks(tracks, std::vector<Rigid3>(3), dir.path()).ok());
  tracks = TwoMarkers();
  tracks.names[1] = "brow_l";
  EXPECT_THAT(SaveMarkerTracks(tracks, std::vector<Rigid3>(3), dir.path()).message(),
              HasSubstr("twice"));
  tracks = TwoMarkers();
  EXPECT_FALSE(SaveMarkerTracks(tracks, std::vector<Rigid3>(2), dir.path()).ok());
  EXPECT_FALSE(std::filesystem::exists(dir.Join(kMarkerTracksFile)));
}

TEST(MarkerTracks, DamagedFilesAreNamed) {
  const std::string header = "frame,time_s,marker,state,confidence,x_mm,y_mm,z_mm\n";
  struct Case {
    std::string body;
    std::string expected;
  };
  const Case cases[] = {
      {"0,0,a,seen,1,1,2,3\n", "not observed, bridged or missing"},
      {"0,0,a,observed,2,1,2,3\n", "confidence"},
      {"0,0,a,missing,0,1,2,3\n", "has a position"},
      {"0,0,a,observed,1,1,x,3\n", "y_mm"},
      {"0,0,a,observed,1,1,2,3\n0,0,b,observed,1,1,2,3\n1,0.1,a,observed,1,1,2,3\n"
       "2,0.2,a,observed,1,1,2,3\n",
       "frame 1 lists 1 of 2 markers"},
      {"0,0,a,observed,1,1,2,3\n0,0,b,observed,1,1,2,3\n1,0.1,a,observed,1,1,2,3\n",
       "the last frame lists 1 of 2 markers"},
      {"0,0,a,observed,1,1,2,3\n1,0,a,observed,1,1,2,3\n", "time does not increase"},
      {"0,0,a,observed,1,1,2,3\n2,0.1,a,observed,1,1,2,3\n", "out of order"},
      {"0,0,a,observed,1,1,2,3\n1,0.1,b,observed,1,1,2,3\n", "not in frame 0"},
      {"0,0,a,observed,1,1,2,3\n0,0,a,observed,1,1,2,3\n", "twice"},
      {"0,0,a b,observed,1,1,2,3\n", "bad marker name"},
      {"", "no frames"},
  };
  for (const Case& c : cases) {
    TempDir dir;
    WriteBytes(dir.Join(kMarkerTracksFile), header + c.body);
    const auto loaded = LoadMarkerTracks(dir.path());
    ASSERT_FALSE(loaded.ok()) << c.body;
    EXPECT_THAT(loaded.status().message(), HasSubstr(c.expected)) << c.body;
    EXPECT_THAT(loaded.status().message(), HasSubstr(kMarkerTracksFile)) << c.body;
  }
}

}  // namespace
}  // namespace facedyn
