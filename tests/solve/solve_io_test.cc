// Weights and labelled-markers CSV files of the solve stage: round trips, and bad input named.
#include "solve/solve_io.h"

#include <gtest/gtest.h>

#include "tests/solve/solve_test_rig.h"
#include "tests/support/test_support.h"

namespace facedyn::solve {
namespace {

using facedyn::testing::ReadBytes;
using facedyn::testing::TempDir;
using facedyn::testing::WriteBytes;
using testing::ProceduralPuppet;

bool Contains(const Status& status, const std::string& text) {
  return status.message().find(text) != std::string::npos;
}

TEST(WeightsCsv, RoundTrip) {
  const Puppet& puppet = ProceduralPuppet();
  TempDir dir;
  const std::vector<double> time_s{0.0, 1.0 / 60, 2.0 / 60};
  Eigen::MatrixXd weights = Eigen::MatrixXd::Random(puppet.channel_count(), 3).cwiseAbs();
  weights(2, 1) = 1.0;
  ASSERT_TRUE(WriteWeightsCsv(dir.Join("w.csv"), puppet, time_s, weights).ok());
  EXPECT_EQ(ReadBytes(dir.Join("w.csv")).substr(0, 16), "time_s,smile,jaw");
  std::vector<double> read_time;
  const StatusOr<Eigen::MatrixXd> read = ReadWeightsCsv(dir.Join("w.csv"), puppet, &read_time);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EIGEN_NEAR(read.value(), weights, 1e-9);
  ASSERT_EQ(read_time.size(), 3u);
  EXPECT_NEAR(read_time[2], 2.0 / 60, 1e-9);
}

TEST(WeightsCsv, UnknownChannelIsNamedWithFileAndColumn) {
  TempDir dir;
  WriteBytes(dir.Join("w.csv"), "time_s,smile,mouthSmile_L\n0,0.5,0.25\n");
  const StatusOr<Eigen::MatrixXd> read =
      ReadWeightsCsv(dir.Join("w.csv"), ProceduralPuppet(), nullptr);
  ASSERT_FALSE(read.ok());
  EXPECT_TRUE(Contains(read.status(), dir.Join("w.csv"))) << read.status().message();
  EXPECT_TRUE(
      Contains(read.status(), "column 3 'mouthSmile_L' is not a channel of rig 'procedural'"))
      << read.status().message();
}

TEST(WeightsCsv, ChannelsWithoutAColumnAreZero) {
  TempDir dir;
  WriteBytes(dir.Join("w.csv"), "time_s,pucker\n0,0.5\n0.1,0.25\n");
  const Eigen::MatrixXd read =
      ReadWeightsCsv(dir.Join("w.csv"), ProceduralPuppet(), nullptr).value();
  EXPECT_EQ(read.row(ProceduralPuppet().ChannelIndex("pucker")).sum(), 0.75);
  EXPECT_EQ(read.cwiseAbs().sum(), 0.75);
}

TEST(WeightsCsv, TruncatedAndCorruptedInputsAreErrors) {
  TempDir dir;
  WriteBytes(dir.Join("t.csv"), "time_s,smile\n0,0.5\n0.1");
  const StatusOr<Eigen::MatrixXd> truncated =
      ReadWeightsCsv(dir.Join("t.csv"), ProceduralPuppet(), nullptr);
  ASSERT_FALSE(truncated.ok());
  EXPECT_TRUE(Contains(truncated.status(), ":3")) << truncated.status().message();
  WriteBytes(dir.Join("c.csv"), "time_s,smile\n0,0.5\n0.1,abc\n");
  const StatusOr<Eigen::MatrixXd> corrupted =
      ReadWeightsCsv(dir.Join("c.csv"), ProceduralPuppet(), nullptr);
  ASSERT_FALSE(corrupted.ok());
  EXPECT_TRUE(Contains(corrupted.status(), "abc")) << corrupted.status().message();
}

MarkerFrames SomeFrames(const Puppet& puppet) {
  MarkerFrames frames;
  frames.time_s = {0.0, 0.5};
  frames.markers_in_skull.resize(3 * puppet.marker_count(), 2);
  frames.markers_in_skull.col(0) = puppet.StackedNeutral();
  frames.markers_in_skull.col(1) =
      puppet.StackedMarkers(Eigen::VectorXd::Constant(puppet.channel_count(), 0.3));
  frames.present = MarkerPresence::Constant(puppet.marker_count(), 2, true);
  frames.present(5, 1) = false;
  frames.markers_in_skull.col(1).segment<3>(15).setZero();
  return frames;
}

TEST(MarkersCsv, RoundTripWithAMissingMarker) {
  const Puppet& puppet = ProceduralPuppet();
  TempDir dir;
  const MarkerFrames frames = SomeFrames(puppet);
  ASSERT_TRUE(WriteMarkersCsv(dir.Join("m.csv"), puppet, frames).ok());
  const StatusOr<MarkerFrames> read = ReadMarkersCsv(dir.Join("m.csv"), puppet);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EIGEN_NEAR(read.value().markers_in_skull, frames.markers_in_skull, 1e-6);
  EXPECT_TRUE((read.value().present == frames.present).all());
}

TEST(MarkersCsv, MissingMarkerColumnsAreNamed) {
  const Puppet& puppet = ProceduralPuppet();
  TempDir dir;
  ASSERT_TRUE(WriteMarkersCsv(dir.Join("m.csv"), puppet, SomeFrames(puppet)).ok());
  // Drop the columns of marker m007 (header and every row).
  std::string text = ReadBytes(dir.Join("m.csv"));
  const std::string header = text.substr(0, text.find('\n'));
  const size_t at = header.find(",m007_x,m007_y,m007_z");
  ASSERT_NE(at, std::string::npos);
  WriteBytes(dir.Join("short.csv"), header.substr(0, at) + header.substr(at + 21) + "\n");
  const StatusOr<MarkerFrames> read = ReadMarkersCsv(dir.Join("short.csv"), puppet);
  ASSERT_FALSE(read.ok());
  EXPECT_TRUE(Contains(read.status(),
                       "3 marker columns of rig 'procedural' are missing: m007_x, m007_y, m007_z"))
      << read.status().message();
}

TEST(MarkersCsv, HalfMissingMarkerAndBadTimesAreNamed) {
  const Puppet& puppet = ProceduralPuppet();
  TempDir dir;
  ASSERT_TRUE(WriteMarkersCsv(dir.Join("m.csv"), puppet, SomeFrames(puppet)).ok());
  std::string text = ReadBytes(dir.Join("m.csv"));
  // Second data row (line 3): time 0.5 -> 0 (not increasing).
  const size_t line3 = text.find('\n', text.find('\n') + 1) + 1;
  std::string bad_time = text;
  bad_time.replace(line3, 3, "0");
  WriteBytes(dir.Join("t.csv"), bad_time);
  StatusOr<MarkerFrames> read = ReadMarkersCsv(dir.Join("t.csv"), puppet);
  ASSERT_FALSE(read.ok());
  EXPECT_TRUE(Contains(read.status(), "t.csv:3")) << read.status().message();
  // Line 2: blank out marker m000's x only.
  const size_t line2 = text.find('\n') + 1;
  const size_t first_comma = text.find(',', line2);
  const size_t second_comma = text.find(',', first_comma + 1);
  std::string half = text;
  half.erase(first_comma + 1, second_comma - first_comma - 1);
  WriteBytes(dir.Join("h.csv"), half);
  read = ReadMarkersCsv(dir.Join("h.csv"), puppet);
  ASSERT_FALSE(read.ok());
  EXPECT_TRUE(Contains(read.status(), "h.csv:2")) << read.status().message();
  EXPECT_TRUE(Contains(read.status(), "marker 'm000' has 1 of its 3 coordinates empty"))
      << read.status().message();
}

// Markers read off a take: the puppet's own pose, seen through a moving head, comes back in the
// skull frame exactly; truth channels and a foreign topology are refused by name.
TEST(MarkersFromTake, SkullFrameMarkersOfAPosedMovingHead) {
  const FaceRig& rig = testing::ProceduralRig();
  const Puppet& puppet = testing::ProceduralPuppet();
  Eigen::VectorXd weights = Eigen::VectorXd::Zero(puppet.channel_count());
  weights[0] = 0.7;
  weights[puppet.channel_count() - 1] = 0.3;
  Take take;
  take.info.fps = 10.0;
  take.info.subject = rig.name;
  take.topology = rig.neutral;
  take.positions.vertex_count = rig.vertex_count();
  take.positions.positions.resize(3 * rig.vertex_count(), 2);
  const Eigen::Matrix3Xd skin_in_skull = rig.Evaluate(weights);
  for (int f = 0; f < 2; ++f) {
    const Rigid3 world_from_skull(Eigen::Quaterniond(Eigen::AngleAxisd(
                                      0.2 + 0.1 * f, Eigen::Vector3d(0.3, 1, 0.2).normalized())),
                                  Eigen::Vector3d(10.0 * f, -4.0, 30.0));
    take.world_from_skull.push_back(world_from_skull);
    take.time_s.push_back(0.1 * f);
    Eigen::Matrix3Xd skin_in_world(3, skin_in_skull.cols());
    for (int v = 0; v < skin_in_skull.cols(); ++v) {
      skin_in_world.col(v) = world_from_skull * Eigen::Vector3d(skin_in_skull.col(v));
    }
    take.positions.Frame(f) = skin_in_world.cast<float>();
  }
  take.channels["quasistatic"] = take.positions;
  const auto frames = MarkersFromTake(puppet, rig, take);
  ASSERT_TRUE(frames.ok()) << frames.status().message();
  ASSERT_EQ(frames->markers_in_skull.cols(), 2);
  EXPECT_TRUE(frames->present.all());
  const Eigen::VectorXd expected = puppet.StackedMarkers(weights);
  for (int f = 0; f < 2; ++f) {
    // float storage of world positions: about 1e-5 mm at these magnitudes.
    EXPECT_LT((frames->markers_in_skull.col(f) - expected).cwiseAbs().maxCoeff(), 1e-3)
        << "frame " << f;
  }
  const auto truth = MarkersFromTake(puppet, rig, take, "quasistatic");
  ASSERT_FALSE(truth.ok());
  EXPECT_NE(truth.status().message().find("simulator truth"), std::string::npos);
  const auto missing = MarkersFromTake(puppet, rig, take, "removed");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.status().message().find("'removed'"), std::string::npos);
  Take other = take;
  other.topology.positions_mm = other.topology.positions_mm.leftCols(10);
  const auto foreign = MarkersFromTake(puppet, rig, other);
  ASSERT_FALSE(foreign.ok());
  EXPECT_NE(foreign.status().message().find("topology"), std::string::npos);
}

TEST(MarkersFromTracks, SkullFrameMarkersFromTheTracksFileWithMissingAndBridged) {
  const Puppet& puppet = testing::ProceduralPuppet();
  Eigen::VectorXd weights = Eigen::VectorXd::Zero(puppet.channel_count());
  weights[0] = 0.5;
  const Eigen::VectorXd in_skull = puppet.StackedMarkers(weights);
  const int m = puppet.marker_count();
  // Tracks with one extra marker the puppet does not know, in reversed order.
  MarkerTracks tracks;
  tracks.names.push_back("extra_dot");
  for (int i = m - 1; i >= 0; --i) tracks.names.push_back(puppet.marker_names[i]);
  tracks.time_s = {0.0, 0.1};
  tracks.world_mm.setConstant(3 * (m + 1), 2, std::nan(""));
  tracks.confidence.setZero(m + 1, 2);
  tracks.state.assign(2, std::vector<MarkerTrackState>(m + 1, MarkerTrackState::kObserved));
  std::vector<Rigid3> world_from_skull;
  for (int f = 0; f < 2; ++f) {
    world_from_skull.push_back(
        Rigid3(Eigen::Quaterniond(Eigen::AngleAxisd(0.3 * f + 0.1, Eigen::Vector3d::UnitY())),
               Eigen::Vector3d(5.0 * f, 1.0, -2.0)));
    tracks.world_mm.block(0, f, 3, 1) = Eigen::Vector3d(1, 2, 3);
    for (int i = 0; i < m; ++i) {
      const int t = 1 + (m - 1 - i);
      tracks.world_mm.block(3 * t, f, 3, 1) =
          world_from_skull[f] * Eigen::Vector3d(in_skull.segment<3>(3 * i));
      tracks.confidence(t, f) = 0.9;
    }
  }
  tracks.state[1][1] = MarkerTrackState::kMissing;  // puppet marker m - 1, frame 1
  tracks.world_mm.block(3, 1, 3, 1).setConstant(std::nan(""));
  tracks.state[1][2] = MarkerTrackState::kBridged;  // puppet marker m - 2, frame 1
  TempDir dir;
  ASSERT_TRUE(SaveMarkerTracks(tracks, world_from_skull, dir.path()).ok());
  const auto loaded = LoadMarkerTracks(dir.path());
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  const auto frames = MarkersFromTracks(puppet, *loaded, world_from_skull);
  ASSERT_TRUE(frames.ok()) << frames.status().message();
  EXPECT_FALSE(frames->present(m - 1, 1));
  EXPECT_TRUE(frames->present(m - 2, 1));
  EXPECT_EQ(frames->present.count(), 2 * m - 1);
  for (int f = 0; f < 2; ++f) {
    for (int i = 0; i < m; ++i) {
      if (!frames->present(i, f)) continue;
      EXPECT_LT((frames->markers_in_skull.block(3 * i, f, 3, 1) - in_skull.segment<3>(3 * i))
                    .cwiseAbs()
                    .maxCoeff(),
                1e-5);
    }
  }
  // The skull-frame file is the labelled-markers CSV a solver reads: the same markers.
  const auto csv = ReadMarkersCsv(dir.Join(kMarkerTracksSkullFile), puppet);
  ASSERT_TRUE(csv.ok()) << csv.status().message();
  EXPECT_TRUE((csv->present.array() == frames->present.array()).all());
  EXPECT_LT((csv->markers_in_skull - frames->markers_in_skull).cwiseAbs().maxCoeff(), 1e-5);

  // A puppet marker the tracks lack is named; frame counts must agree.
  MarkerTracks fewer = *loaded;
  fewer.names[1] = "renamed";
  const auto lacking = MarkersFromTracks(puppet, fewer, world_from_skull);
  ASSERT_FALSE(lacking.ok());
  EXPECT_TRUE(Contains(lacking.status(), puppet.marker_names[m - 1]));
  EXPECT_FALSE(MarkersFromTracks(puppet, *loaded, {world_from_skull[0]}).ok());
}

TEST(DriveRig, EvaluatesTheRigAtTheTrackAndNamesAForeignColumn) {
  const FaceRig& rig = testing::ProceduralRig();
  BlendshapeWeightsTrack track;
  track.names = {"smile", "jaw_open"};
  track.time_s = {1.0, 1.5, 2.0};
  track.weights.resize(3, 2);
  track.weights << 0.0, 0.0, 0.5, 0.2, 1.0, 0.0;
  const auto take = DriveRig(rig, track, "w.csv");
  ASSERT_TRUE(take.ok()) << take.status().message();
  ASSERT_EQ(take->frame_count(), 3);
  EXPECT_DOUBLE_EQ(take->time_s.front(), 0.0);
  EXPECT_DOUBLE_EQ(take->info.fps, 2.0);
  Eigen::VectorXd w = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(rig.blendshape_names.size()));
  w[rig.BlendshapeIndex("smile")] = 0.5;
  w[rig.BlendshapeIndex("jaw_open")] = 0.2;
  const Eigen::Matrix3Xd expected = rig.Evaluate(w);
  EXPECT_LT((take->positions.Frame(1).cast<double>() - expected).cwiseAbs().maxCoeff(), 1e-3);
  EXPECT_LT((take->positions.Frame(0).cast<double>() - rig.neutral.positions_mm)
                .cwiseAbs()
                .maxCoeff(),
            1e-3);

  track.names[1] = "eyeBlinkLeft";
  const auto foreign = DriveRig(rig, track, "w.csv");
  ASSERT_FALSE(foreign.ok());
  EXPECT_TRUE(Contains(foreign.status(), "w.csv: column 3 'eyeBlinkLeft'"));
  track.names[1] = "jaw_open";
  track.time_s.resize(1);
  track.weights.conservativeResize(1, 2);
  EXPECT_FALSE(DriveRig(rig, track, "w.csv").ok());
}

}  // namespace
}  // namespace facedyn::solve
