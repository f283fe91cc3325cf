#include "detail/masquerade.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <iterator>
#include <limits>
#include <vector>

#include "core/file_util.h"
#include "detail/bickel.h"
#include "detail_test_util.h"
#include "tests/support/test_support.h"

namespace facedyn::detail {
namespace {

double MaxError(const Eigen::Matrix3Xd& a, const Eigen::Matrix3Xd& b) {
  return (a - b).colwise().norm().maxCoeff();
}
double MeanError(const Eigen::Matrix3Xd& a, const Eigen::Matrix3Xd& b) {
  return (a - b).colwise().norm().mean();
}

MasqueradeOptions AllFrames() {
  MasqueradeOptions options;
  options.global_frames = 0;
  return options;
}

TEST(MasqueradeModel, ReproducesItsTrainingFrames) {
  // Each region interpolates its training offsets exactly and the blend weights sum to 1, so a
  // training frame's own markers give that frame back.
  const DetailTrainingSet set = testing::TestTrainingSet();
  MasqueradeTrainingSummary summary;
  StatusOr<MasqueradeModel> model = MasqueradeModel::Train(set, AllFrames(), &summary);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  EXPECT_DOUBLE_EQ(summary.mean_frames_per_region, 25.0);
  for (size_t f = 0; f < set.frames_mm.size(); ++f) {
    Eigen::Matrix3Xd skin, large;
    ASSERT_TRUE(model->Apply(set.MarkersOn(set.frames_mm[f]), &skin, &large).ok());
    EXPECT_LT(MaxError(skin, set.frames_mm[f]), 1e-6) << "frame " << f;
    if (f == 0) {
      EXPECT_GT(MaxError(large, set.frames_mm[f]), 0.5);  // the detail was not in the markers
    }
  }
}

TEST(MasqueradeModel, HeldOutPoseBeatsLargeScaleOnly) {
  const DetailTrainingSet set = testing::TestTrainingSet();
  StatusOr<MasqueradeModel> model = MasqueradeModel::Train(set, AllFrames());
  ASSERT_TRUE(model.ok());
  const Eigen::Matrix3Xd truth = testing::TestFrame(set.neutral, 0.3, -0.6);
  Eigen::Matrix3Xd skin, large;
  ASSERT_TRUE(model->Apply(set.MarkersOn(truth), &skin, &large).ok());
  EXPECT_LT(MeanError(skin, truth), 0.5 * MeanError(large, truth));
}

TEST(MasqueradeModel, ApplyFramesOnSeveralThreadsMatchesApplyPerFrame) {
  const DetailTrainingSet set = testing::TestTrainingSet();
  StatusOr<MasqueradeModel> model = MasqueradeModel::Train(set, AllFrames());
  ASSERT_TRUE(model.ok());
  std::vector<Eigen::Matrix3Xd> markers;
  for (int f = 0; f < 12; ++f)
    markers.push_back(set.MarkersOn(testing::TestFrame(set.neutral, 0.1 * f - 0.5, 0.6 - 0.1 * f)));
  std::vector<Eigen::Matrix3Xd> skins, large;
  Progress progress("test", static_cast<long>(markers.size()), ProgressMode::kSilent);
  ASSERT_TRUE(model->ApplyFrames(markers, &skins, &large, 3, &progress).ok());
  ASSERT_EQ(skins.size(), markers.size());
  ASSERT_EQ(large.size(), markers.size());
  for (size_t f = 0; f < markers.size(); ++f) {
    Eigen::Matrix3Xd skin, large_one;
    ASSERT_TRUE(model->Apply(markers[f], &skin, &large_one).ok());
    EXPECT_EQ(MaxError(skins[f], skin), 0.0) << "frame " << f;  // the same arithmetic
    EXPECT_EQ(MaxError(large[f], large_one), 0.0) << "frame " << f;
  }
  // A bad frame is named.
  markers[7](1, 2) = std::numeric_limits<double>::quiet_NaN();
  const Status status = model->ApplyFrames(markers, &skins, nullptr, 2);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), ::testing::HasSubstr("frame 7"));
}

TEST(MasqueradeModel, GreedyFramesPerRegion) {
  const DetailTrainingSet set = testing::TestTrainingSet();
  MasqueradeOptions options;
  options.global_frames = 12;
  options.per_region_frames = 6;
  MasqueradeTrainingSummary summary;
  StatusOr<MasqueradeModel> model = MasqueradeModel::Train(set, options, &summary);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  EXPECT_EQ(summary.global_frames.size(), 12u);
  EXPECT_LE(summary.mean_frames_per_region, 6.0);
  StatusOr<MasqueradeModel> all = MasqueradeModel::Train(set, AllFrames());
  ASSERT_TRUE(all.ok());
  EXPECT_LT(model->MemoryBytes(), all->MemoryBytes());
}

TEST(MasqueradeModel, FileRoundTrip) {
  const DetailTrainingSet set = testing::TestTrainingSet(4);
  StatusOr<MasqueradeModel> model = MasqueradeModel::Train(set, AllFrames());
  ASSERT_TRUE(model.ok());
  facedyn::testing::TempDir dir;
  const std::string path = dir.Join("detail.bin");
  ASSERT_TRUE(model->Save(path).ok());
  StatusOr<MasqueradeModel> loaded = MasqueradeModel::Load(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->subject(), "patch");
  EXPECT_EQ(loaded->MemoryBytes(), model->MemoryBytes());
  ASSERT_EQ(loaded->markers().size(), set.markers.size());
  EXPECT_EQ(loaded->markers()[3].name, set.markers[3].name);
  const Eigen::Matrix3Xd truth = testing::TestFrame(set.neutral, -0.2, 0.7);
  Eigen::Matrix3Xd a, b;
  ASSERT_TRUE(model->Apply(set.MarkersOn(truth), &a).ok());
  ASSERT_TRUE(loaded->Apply(set.MarkersOn(truth), &b).ok());
  EXPECT_EQ(MaxError(a, b), 0.0);
}

TEST(MasqueradeModel, CompressedOutputsShrinkTheModelAndSurviveARoundTrip) {
  const DetailTrainingSet set = testing::TestTrainingSet(4);
  StatusOr<MasqueradeModel> full = MasqueradeModel::Train(set, AllFrames());
  ASSERT_TRUE(full.ok());
  MasqueradeOptions options = AllFrames();
  options.output_energy = 0.999;
  StatusOr<MasqueradeModel> compressed = MasqueradeModel::Train(set, options);
  ASSERT_TRUE(compressed.ok()) << compressed.status().ToString();
  EXPECT_LT(compressed->MemoryBytes(), full->MemoryBytes());
  // Compression moves the RBFs' outputs into a basis and leaves the centres and the region
  // tables as they were.
  const MasqueradeModel::MemoryParts full_parts = full->MemoryBreakdown();
  const MasqueradeModel::MemoryParts parts = compressed->MemoryBreakdown();
  EXPECT_EQ(full_parts.rbf_output_bases, 0u);
  EXPECT_GT(parts.rbf_output_bases, 0u);
  EXPECT_LT(parts.rbf_coefficients + parts.rbf_output_bases, full_parts.rbf_coefficients);
  EXPECT_EQ(parts.rbf_centres, full_parts.rbf_centres);
  EXPECT_EQ(parts.region_vertices, full_parts.region_vertices);
  EXPECT_EQ(parts.feature_triangles, full_parts.feature_triangles);
  EXPECT_GT(parts.feature_triangles, 0u);
  // At a held-out pose it stays close to the uncompressed model (0.1% of the offsets' energy
  // dropped per region).
  const Eigen::Matrix3Xd truth = testing::TestFrame(set.neutral, 0.3, -0.6);
  Eigen::Matrix3Xd a, b, large;
  ASSERT_TRUE(full->Apply(set.MarkersOn(truth), &a, &large).ok());
  ASSERT_TRUE(compressed->Apply(set.MarkersOn(truth), &b).ok());
  EXPECT_LT(MeanError(a, b), 0.1 * MeanError(large, a));
  facedyn::testing::TempDir dir;
  ASSERT_TRUE(compressed->Save(dir.Join("c.bin")).ok());
  ASSERT_TRUE(full->Save(dir.Join("f.bin")).ok());
  // Format version (after the 8-byte magic): 2 with an output basis, 1 without.
  auto version_of = [](const std::string& path) {
    StatusOr<std::string> bytes = ReadFileToString(path);
    return bytes.ok() && bytes->size() >= 12 ? static_cast<unsigned char>((*bytes)[8]) : -1;
  };
  EXPECT_EQ(version_of(dir.Join("c.bin")), 2);
  EXPECT_EQ(version_of(dir.Join("f.bin")), 1);
  StatusOr<MasqueradeModel> loaded = MasqueradeModel::Load(dir.Join("c.bin"));
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->MemoryBytes(), compressed->MemoryBytes());
  Eigen::Matrix3Xd c;
  ASSERT_TRUE(loaded->Apply(set.MarkersOn(truth), &c).ok());
  EXPECT_EQ(MaxError(b, c), 0.0);
  options.output_energy = 1.5;
  EXPECT_THAT(MasqueradeModel::Train(set, options).status().message(),
              ::testing::HasSubstr("output_energy"));
  options.output_energy = -0.1;
  EXPECT_FALSE(MasqueradeModel::Train(set, options).ok());
}

TEST(MasqueradeModel, ChoosesTheOutputEnergyOnTheFramesSelectionLeftOut) {
  const DetailTrainingSet set = testing::TestTrainingSet(6);  // 36 frames
  MasqueradeOptions options;
  options.global_frames = 20;
  options.output_energy = kChooseOutputEnergy;
  MasqueradeTrainingSummary summary;
  StatusOr<MasqueradeModel> chosen = MasqueradeModel::Train(set, options, &summary);
  ASSERT_TRUE(chosen.ok()) << chosen.status().ToString();
  EXPECT_EQ(summary.output_energy_validation_frames, static_cast<int>(set.frames_mm.size()) - 20);
  // The choice is one of the candidates, and the model is what training with it gives.
  EXPECT_NE(std::find(std::begin(kOutputEnergyCandidates), std::end(kOutputEnergyCandidates),
                      summary.output_energy),
            std::end(kOutputEnergyCandidates));
  options.output_energy = summary.output_energy;
  StatusOr<MasqueradeModel> direct = MasqueradeModel::Train(set, options);
  ASSERT_TRUE(direct.ok());
  EXPECT_EQ(chosen->MemoryBytes(), direct->MemoryBytes());
  // The rule: within 5% of the uncompressed error on the left-out frames, and no smaller
  // candidate is.
  auto held_out_error = [&](const MasqueradeModel& model) {
    std::vector<char> in_pool(set.frames_mm.size(), 0);
    MasqueradeOptions pool_options;
    pool_options.global_frames = 20;
    MasqueradeTrainingSummary pool_summary;
    EXPECT_TRUE(MasqueradeModel::Train(set, pool_options, &pool_summary).ok());
    for (int f : pool_summary.global_frames) in_pool[f] = 1;
    double error = 0;
    for (size_t f = 0; f < set.frames_mm.size(); ++f) {
      if (in_pool[f]) continue;
      Eigen::Matrix3Xd skin;
      EXPECT_TRUE(model.Apply(set.MarkersOn(set.frames_mm[f]), &skin).ok());
      error += MeanError(skin, set.frames_mm[f]);
    }
    return error;
  };
  options.output_energy = 1.0;
  const double uncompressed = held_out_error(*MasqueradeModel::Train(set, options));
  EXPECT_LE(held_out_error(*chosen), 1.05 * uncompressed + 1e-12);
  for (double candidate : kOutputEnergyCandidates) {
    if (candidate >= summary.output_energy) continue;
    options.output_energy = candidate;
    EXPECT_GT(held_out_error(*MasqueradeModel::Train(set, options)), 1.05 * uncompressed)
        << candidate;
  }
  // With every frame selected there is nothing to choose on: uncompressed.
  options.global_frames = 0;
  options.output_energy = kChooseOutputEnergy;
  ASSERT_TRUE(MasqueradeModel::Train(set, options, &summary).ok());
  EXPECT_EQ(summary.output_energy, 1.0);
  EXPECT_EQ(summary.output_energy_validation_frames, 0);
}

TEST(MasqueradeModel, TruncatedAndCorruptedFilesAreNamedErrors) {
  const DetailTrainingSet set = testing::TestTrainingSet(3);
  StatusOr<MasqueradeModel> model = MasqueradeModel::Train(set, AllFrames());
  ASSERT_TRUE(model.ok());
  facedyn::testing::TempDir dir;
  const std::string path = dir.Join("detail.bin");
  ASSERT_TRUE(model->Save(path).ok());
  StatusOr<std::string> bytes = ReadFileToString(path);
  ASSERT_TRUE(bytes.ok());
  const std::string bad = dir.Join("bad.bin");
  // Truncated anywhere: an error naming the file, never a crash.
  for (size_t length = 0; length < bytes->size(); length += 1 + bytes->size() / 97) {
    ASSERT_TRUE(WriteFileAtomic(bad, bytes->substr(0, length)).ok());
    StatusOr<MasqueradeModel> loaded = MasqueradeModel::Load(bad);
    ASSERT_FALSE(loaded.ok()) << "length " << length;
    EXPECT_THAT(loaded.status().message(), ::testing::HasSubstr(bad));
  }
  // Bytes flipped anywhere: an error or (a flipped coefficient) a model, never a crash.
  int errors = 0;
  for (size_t at = 0; at < bytes->size(); at += 1 + bytes->size() / 211) {
    std::string corrupt = *bytes;
    corrupt[at] = static_cast<char>(corrupt[at] ^ 0x5a);
    ASSERT_TRUE(WriteFileAtomic(bad, corrupt).ok());
    errors += MasqueradeModel::Load(bad).ok() ? 0 : 1;
  }
  EXPECT_GT(errors, 0);
  std::string magic = *bytes;
  magic[0] = 'X';
  ASSERT_TRUE(WriteFileAtomic(bad, magic).ok());
  EXPECT_THAT(MasqueradeModel::Load(bad).status().message(),
              ::testing::HasSubstr("not a facedyn detail model"));
  EXPECT_EQ(MasqueradeModel::Load(dir.Join("missing.bin")).status().code(), StatusCode::kNotFound);
}

TEST(MasqueradeModel, IncompatibleInputNamed) {
  const DetailTrainingSet set = testing::TestTrainingSet(3);
  StatusOr<MasqueradeModel> model = MasqueradeModel::Train(set, AllFrames());
  ASSERT_TRUE(model.ok());
  std::vector<std::string> names = MarkerNames(set.markers);
  EXPECT_TRUE(model->CheckCompatible(names, set.neutral.vertex_count(), "take T").ok());
  names[4] = "chin";
  EXPECT_THAT(model->CheckCompatible(names, set.neutral.vertex_count(), "take T").message(),
              ::testing::HasSubstr("take T: marker #4 is 'chin', the detail model expects '" +
                                   set.markers[4].name + "'"));
  names.pop_back();
  names[4] = set.markers[4].name;
  EXPECT_THAT(model->CheckCompatible(names, set.neutral.vertex_count(), "take T").message(),
              ::testing::HasSubstr("is missing"));
  EXPECT_THAT(model->CheckCompatible(MarkerNames(set.markers), 10, "take T").message(),
              ::testing::HasSubstr("10 vertices, the detail model's rig 'patch' has"));
  Eigen::Matrix3Xd skin;
  EXPECT_THAT(model->Apply(Eigen::Matrix3Xd::Zero(3, 5), &skin).message(),
              ::testing::HasSubstr("5 marker positions"));
  Eigen::Matrix3Xd nan = set.MarkersOn(set.neutral.positions_mm);
  nan(1, 2) = std::nan("");
  EXPECT_THAT(model->Apply(nan, &skin).message(), ::testing::HasSubstr("marker 2"));
}

TEST(MasqueradeModel, CoarserPoseQuadratureShrinksTheTableAndKeepsThePoses) {
  const DetailTrainingSet set = testing::TestTrainingSet(4);
  MasqueradeOptions options = AllFrames();
  options.pose_cell_mm = 0.0;  // every triangle
  StatusOr<MasqueradeModel> fine = MasqueradeModel::Train(set, options);
  ASSERT_TRUE(fine.ok());
  options.pose_cell_mm = 10.0;
  StatusOr<MasqueradeModel> coarse = MasqueradeModel::Train(set, options);
  ASSERT_TRUE(coarse.ok()) << coarse.status().ToString();
  const MasqueradeModel::MemoryParts fine_parts = fine->MemoryBreakdown();
  const MasqueradeModel::MemoryParts coarse_parts = coarse->MemoryBreakdown();
  EXPECT_LT(coarse_parts.feature_triangles, fine_parts.feature_triangles / 3);
  EXPECT_EQ(coarse_parts.region_vertices, fine_parts.region_vertices);
  // The poses of a held-out frame's large-scale skin (smooth: F varies over the marker
  // spacing, not over a cell) agree to a small fraction of their size.
  const Eigen::Matrix3Xd truth = testing::TestFrame(set.neutral, 0.8, -0.6);
  Eigen::Matrix3Xd skin, large;
  ASSERT_TRUE(fine->Apply(set.MarkersOn(truth), &skin, &large).ok());
  Eigen::MatrixXd fine_poses, coarse_poses;
  fine->RegionPoses(large, &fine_poses);
  coarse->RegionPoses(large, &coarse_poses);
  ASSERT_EQ(coarse_poses.cols(), static_cast<int>(set.markers.size()));
  ASSERT_GT(fine_poses.norm(), 0.05);
  EXPECT_LT((coarse_poses - fine_poses).norm(), 0.05 * fine_poses.norm());
  // The table survives a round trip exactly (float weights are exact in the file's doubles).
  facedyn::testing::TempDir dir;
  ASSERT_TRUE(coarse->Save(dir.Join("coarse.bin")).ok());
  StatusOr<MasqueradeModel> loaded = MasqueradeModel::Load(dir.Join("coarse.bin"));
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->MemoryBytes(), coarse->MemoryBytes());
  Eigen::MatrixXd loaded_poses;
  loaded->RegionPoses(large, &loaded_poses);
  EXPECT_EQ((loaded_poses - coarse_poses).norm(), 0.0);
  options.pose_cell_mm = -1.0;
  EXPECT_THAT(MasqueradeModel::Train(set, options).status().message(),
              ::testing::HasSubstr("pose_cell_mm"));
}

TEST(MasqueradeModel, BadTrainingSetNamed) {
  DetailTrainingSet set = testing::TestTrainingSet(2);
  set.frames_mm[2] = Eigen::Matrix3Xd(set.frames_mm[2].leftCols(10));  // a copy: no aliasing
  EXPECT_THAT(MasqueradeModel::Train(set, {}).status().message(),
              ::testing::HasSubstr("frame 2 has 10 vertices"));
  set = testing::TestTrainingSet(2);
  set.markers[1].name = set.markers[0].name;
  EXPECT_THAT(MasqueradeModel::Train(set, {}).status().message(),
              ::testing::HasSubstr("appears twice"));
  MasqueradeOptions options;
  options.region_sigma_mm = 0;
  EXPECT_THAT(MasqueradeModel::Train(testing::TestTrainingSet(2), options).status().message(),
              ::testing::HasSubstr("region_sigma_mm"));
}

TEST(BickelModel, ReproducesTrainingFramesAndIsPerVertex) {
  const DetailTrainingSet set = testing::TestTrainingSet();
  BickelOptions options;
  options.frames = 0;
  StatusOr<BickelModel> model = BickelModel::Train(set, options);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  EXPECT_GT(model->edge_count(), 20);
  for (size_t f = 0; f < set.frames_mm.size(); f += 6) {
    Eigen::Matrix3Xd skin;
    ASSERT_TRUE(model->Apply(set.MarkersOn(set.frames_mm[f]), &skin).ok());
    EXPECT_LT(MaxError(skin, set.frames_mm[f]), 1e-6) << "frame " << f;
  }
  // Per-vertex coefficients: memory grows with the vertex count, at least 3 (N + 1) doubles each.
  EXPECT_GE(model->MemoryBytes(), sizeof(double) * 3 * 26 * set.neutral.vertex_count());
}

TEST(BickelModel, ApplyFramesOnSeveralThreadsMatchesApplyPerFrame) {
  const DetailTrainingSet set = testing::TestTrainingSet();
  StatusOr<BickelModel> model = BickelModel::Train(set, BickelOptions());
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  std::vector<Eigen::Matrix3Xd> markers;
  for (int f = 0; f < 9; ++f)
    markers.push_back(set.MarkersOn(testing::TestFrame(set.neutral, 0.5 - 0.1 * f, 0.1 * f)));
  std::vector<Eigen::Matrix3Xd> skins;
  ASSERT_TRUE(model->ApplyFrames(markers, &skins, 2).ok());
  ASSERT_EQ(skins.size(), markers.size());
  for (size_t f = 0; f < markers.size(); ++f) {
    Eigen::Matrix3Xd skin;
    ASSERT_TRUE(model->Apply(markers[f], &skin).ok());
    EXPECT_EQ(MaxError(skins[f], skin), 0.0) << "frame " << f;
  }
  markers[4].resize(3, 2);
  const Status status = model->ApplyFrames(markers, &skins, 2);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), ::testing::HasSubstr("frame 4"));
}

}  // namespace
}  // namespace facedyn::detail
