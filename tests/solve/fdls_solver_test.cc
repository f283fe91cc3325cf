// The learned solver (FDLS 4.1-4.4) on the procedural face: region tables, training data,
// salient selection, and a small trained solver that reproduces the puppet's own frames.
#include "solve/fdls_solver.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <sstream>

#include "core/config_node.h"
#include "solve/marker_fit.h"
#include "solve/solve_config.h"
#include "solve/training_data.h"
#include "tests/solve/solve_test_rig.h"
#include "tests/support/test_support.h"

namespace facedyn::solve {
namespace {

using testing::ProceduralPuppet;
using testing::ProceduralRig;

ResolvedConfig ProceduralResolved() {
  const SolveConfig config = ProceduralSolveConfig().value();
  return ResolveSolveConfig(config, ProceduralRig(), ProceduralPuppet()).value();
}

TEST(SolveConfig, ShippedFileMatchesTheEmbeddedDefault) {
  std::ifstream file(std::string(FACEDYN_SOURCE_DIR) + "/config/solve/procedural.yaml");
  ASSERT_TRUE(file) << "config/solve/procedural.yaml";
  std::stringstream text;
  text << file.rdbuf();
  EXPECT_EQ(text.str(), std::string(ProceduralSolveConfigYaml()));
}

TEST(SolveConfig, ProceduralTablesCoverEveryChannelOnce) {
  const ResolvedConfig resolved = ProceduralResolved();
  std::vector<int> count(ProceduralPuppet().channel_count(), 0);
  for (int c : resolved.jaw.channels) ++count[c];
  for (const ResolvedRegion& region : resolved.regions) {
    for (int c : region.channels) ++count[c];
    EXPECT_GE(region.markers.size(), 4u) << region.spec.name;
    EXPECT_LE(region.markers.size(), 17u) << region.spec.name;  // 16 + the nose bridge
  }
  for (int c = 0; c < ProceduralPuppet().channel_count(); ++c) EXPECT_EQ(count[c], 1) << c;
  EXPECT_EQ(resolved.jaw.channels, std::vector<int>{ProceduralPuppet().ChannelIndex("jaw_open")});
}

TEST(SolveConfig, ErrorsNameTheChannelTheRegionAndTheField) {
  SolveConfig config = ProceduralSolveConfig().value();
  config.regions[0].channels.push_back("mouthSmile_L");
  StatusOr<ResolvedConfig> resolved =
      ResolveSolveConfig(config, ProceduralRig(), ProceduralPuppet());
  ASSERT_FALSE(resolved.ok());
  EXPECT_NE(resolved.status().message().find("'mouthSmile_L', which the rig does not have"),
            std::string::npos)
      << resolved.status().message();

  config = ProceduralSolveConfig().value();
  config.regions[0].channels.pop_back();  // squeeze in no region
  resolved = ResolveSolveConfig(config, ProceduralRig(), ProceduralPuppet());
  ASSERT_FALSE(resolved.ok());
  EXPECT_NE(resolved.status().message().find("'squeeze' is in no region"), std::string::npos)
      << resolved.status().message();

  config = ProceduralSolveConfig().value();
  config.regions[1].rig_regions = {"ears"};
  resolved = ResolveSolveConfig(config, ProceduralRig(), ProceduralPuppet());
  ASSERT_FALSE(resolved.ok());
  EXPECT_NE(resolved.status().message().find("'ears'"), std::string::npos)
      << resolved.status().message();

  const StatusOr<ConfigNode> node = ConfigNode::Parse(
      "jaw: {rig_regions: [jaw], channels: [jaw_open], features: distance+wobble}\nregions: []\n",
      "bad.yaml");
  ASSERT_TRUE(node.ok());
  const StatusOr<SolveConfig> parsed = ParseSolveConfig(node.value());
  ASSERT_FALSE(parsed.ok());
  EXPECT_NE(parsed.status().message().find("bad.yaml:1"), std::string::npos)
      << parsed.status().message();
  EXPECT_NE(parsed.status().message().find("wobble"), std::string::npos)
      << parsed.status().message();
}

TEST(MakeTrainingWeights, HasSweepsWithinBoundsAndIsSeeded) {
  const Puppet& puppet = ProceduralPuppet();
  TrainingDataOptions options;
  options.random_combos = 100;
  options.rom_clips = 5;
  options.jaw_channels = {puppet.ChannelIndex("jaw_open")};
  const Eigen::MatrixXd w = MakeTrainingWeights(puppet, options).value();
  EXPECT_EQ(w.cols(), 1 + 10 * 10 + 5 * 12 + 100);
  EXPECT_GE(w.minCoeff(), 0.0);
  EXPECT_LE(w.maxCoeff(), 1.0);
  // Single-channel sweep of channel 0 at weight 1 (column 10: after the neutral, steps 1..10).
  EXPECT_EQ(w(0, 10), 1.0);
  EXPECT_EQ(w.col(10).cwiseAbs().sum(), 1.0);
  EXPECT_EQ(MakeTrainingWeights(puppet, options).value(), w);
  options.seed = 2;
  EXPECT_NE(MakeTrainingWeights(puppet, options).value(), w);
  options.sweep_steps = 0;
  EXPECT_FALSE(MakeTrainingWeights(puppet, options).ok());
}

TEST(MakeTrainingSet, CopiesCarryNoiseShiftAndRefilledDropout) {
  const Puppet& puppet = ProceduralPuppet();
  Eigen::MatrixXd w = Eigen::MatrixXd::Zero(puppet.channel_count(), 50);
  TrainingDataOptions options;
  options.augment_copies = 1;
  options.noise_mm = 0.0;
  options.mask_shift_mm = 0.5;
  options.dropout = 0.0;
  const TrainingSet shifted = MakeTrainingSet(puppet, w, options).value();
  ASSERT_EQ(shifted.sample_count(), 100);
  EXPECT_EIGEN_NEAR(shifted.markers.col(0), puppet.StackedNeutral(), 1e-12);
  for (int i = 50; i < 100; ++i) {
    const Eigen::VectorXd d = shifted.markers.col(i) - puppet.StackedNeutral();
    const Eigen::Vector3d shift = d.head<3>();
    EXPECT_LE(shift.norm(), 0.5 + 1e-12);
    for (int m = 0; m < puppet.marker_count(); ++m)
      EXPECT_EIGEN_NEAR(d.segment<3>(3 * m), shift, 1e-9);
  }
  // Dropout at neutral refills from the neighbours' deltas: exactly neutral again.
  options.mask_shift_mm = 0.0;
  options.dropout = 0.3;
  const TrainingSet dropped = MakeTrainingSet(puppet, w, options).value();
  EXPECT_EIGEN_NEAR(dropped.markers.col(70), puppet.StackedNeutral(), 1e-9);
}

TEST(SelectSalientSamples, DropsNearDuplicatesKeepsDistinctPoses) {
  Eigen::MatrixXd markers(3, 6);
  markers << 0, 0.01, 5, 5.02, 10, 0,  //
      0, 0, 0, 0, 0, 0,                //
      0, 0, 0, 0, 0, 0;
  // s = exp(-d / 1 mm); threshold 0.5 keeps samples farther than ln 2 = 0.69 mm from every kept.
  EXPECT_EQ(SelectSalientSamples(markers, 0.5, 1.0), (std::vector<int>{0, 2, 4}));
  // Threshold 1 keeps all but exact duplicates (the last column repeats the first).
  EXPECT_EQ(SelectSalientSamples(markers, 1.0, 1.0), (std::vector<int>{0, 1, 2, 3, 4}));
}

// The networks trained two at a time are bitwise the ones trained one after the other (each
// region's input sees the true jaw, so no network waits for another), and a count below 1 is
// refused by name.
TEST(FdlsSolver, NetworksTrainedSideBySideAreTheSequentialOnes) {
  const Puppet& puppet = ProceduralPuppet();
  ResolvedConfig config = ProceduralResolved();
  config.network.hidden_units = 16;
  config.network.epochs = 2;
  config.network.batch_size = 64;
  TrainingDataOptions data_options;
  data_options.random_combos = 200;
  data_options.rom_clips = 4;
  data_options.augment_copies = 0;
  data_options.jaw_channels = config.jaw.channels;
  const Eigen::MatrixXd weights = MakeTrainingWeights(puppet, data_options).value();
  const TrainingSet data = MakeTrainingSet(puppet, weights, data_options).value();
  FdlsTrainOptions train;
  train.num_threads = 1;
  std::vector<RegionTrainSummary> one_summaries, two_summaries;
  const StatusOr<FdlsSolver> one = FdlsSolver::Train(puppet, config, data, train, &one_summaries);
  ASSERT_TRUE(one.ok()) << one.status().ToString();
  train.concurrent_networks = 2;
  const StatusOr<FdlsSolver> two = FdlsSolver::Train(puppet, config, data, train, &two_summaries);
  ASSERT_TRUE(two.ok()) << two.status().ToString();
  ASSERT_EQ(one_summaries.size(), 1 + config.regions.size());
  ASSERT_EQ(two_summaries.size(), one_summaries.size());
  EXPECT_EQ(two_summaries.front().region, one_summaries.front().region);  // the jaw first
  for (size_t k = 0; k < one_summaries.size(); ++k) {
    EXPECT_EQ(two_summaries[k].region, one_summaries[k].region);
    EXPECT_EQ(two_summaries[k].validation_rmse, one_summaries[k].validation_rmse);
  }
  const Eigen::MatrixXd markers = data.markers.leftCols(50);
  EXPECT_EQ(two->Solve(markers).value(), one->Solve(markers).value());

  train.concurrent_networks = 0;
  const StatusOr<FdlsSolver> refused = FdlsSolver::Train(puppet, config, data, train, nullptr);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("concurrent_networks"), std::string::npos)
      << refused.status().message();
}

// A small solver trained on the puppet reproduces the puppet's frames it never saw.
TEST(FdlsSolver, TrainedSolverReproducesThePuppetsOwnFrames) {
  const Puppet& puppet = ProceduralPuppet();
  ResolvedConfig config = ProceduralResolved();
  config.network.hidden_units = 64;
  config.network.epochs = 20;
  config.network.batch_size = 128;
  config.network.learning_rate = 2e-3;
  TrainingDataOptions data_options;
  data_options.random_combos = 1000;
  data_options.rom_clips = 40;
  data_options.augment_copies = 1;
  data_options.jaw_channels = config.jaw.channels;
  data_options.dropout =
      0.1;  // the copies lose a tenth of their markers, refilled as a solve refills them
  const Eigen::MatrixXd weights = MakeTrainingWeights(puppet, data_options).value();
  const TrainingSet data = MakeTrainingSet(puppet, weights, data_options).value();
  FdlsTrainOptions train;
  train.num_threads = 1;  // the machine is shared; one thread avoids OpenMP spin-waits
  std::vector<RegionTrainSummary> summaries;
  const auto start = std::chrono::steady_clock::now();
  StatusOr<FdlsSolver> solver = FdlsSolver::Train(puppet, config, data, train, &summaries);
  ASSERT_TRUE(solver.ok()) << solver.status().ToString();
  for (const RegionTrainSummary& s : summaries) {
    std::printf(
        "region %-10s markers %2d inputs %4d outputs %d train rmse %.4f validation rmse %.4f %.1f "
        "s\n",
        s.region.c_str(), s.markers, s.inputs, s.outputs, s.train_rmse, s.validation_rmse,
        s.train_s);
  }
  std::printf("training took %.1f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());

  // Held-out frames: other random sparse poses (another seed), clean markers.
  TrainingDataOptions test_options = data_options;
  test_options.seed = 99;
  test_options.sweep_steps = 1;
  test_options.rom_clips = 0;
  test_options.random_combos = 200;
  const Eigen::MatrixXd truth = MakeTrainingWeights(puppet, test_options).value();
  const Eigen::MatrixXd markers =
      (puppet.marker_basis_mm * truth).colwise() + puppet.StackedNeutral();
  const Eigen::MatrixXd solved = solver.value().Solve(markers).value();
  const double weight_rmse = std::sqrt((solved - truth).squaredNorm() / truth.size());
  const double marker_rmse = MarkerRmseMm(puppet, solved, markers);
  std::printf("held-out weight RMSE %.4f, marker RMSE %.3f mm\n", weight_rmse, marker_rmse);
  EXPECT_LT(weight_rmse, 0.03);  // issue 21's clean-marker bar
  EXPECT_LT(marker_rmse, 0.2);
  EXPECT_GE(solved.minCoeff(), 0.0);
  EXPECT_LE(solved.maxCoeff(), 1.0);

  // A tenth of the markers lost in every frame (refilled from neighbours): still close.
  Eigen::Array<bool, Eigen::Dynamic, Eigen::Dynamic> present =
      Eigen::Array<bool, Eigen::Dynamic, Eigen::Dynamic>::Constant(puppet.marker_count(),
                                                                   truth.cols(), true);
  for (Eigen::Index f = 0; f < truth.cols(); ++f) {
    for (int m = static_cast<int>(f % 10); m < puppet.marker_count(); m += 10)
      present(m, f) = false;
  }
  Eigen::MatrixXd holes = markers;
  for (Eigen::Index f = 0; f < truth.cols(); ++f) {
    for (int m = 0; m < puppet.marker_count(); ++m) {
      if (!present(m, f)) holes.block<3, 1>(3 * m, f).setConstant(-1e4);
    }
  }
  const Eigen::MatrixXd solved_holes = solver.value().Solve(holes, present).value();
  const double holes_rmse = std::sqrt((solved_holes - truth).squaredNorm() / truth.size());
  std::printf("held-out weight RMSE with 10%% of the markers missing %.4f\n", holes_rmse);
  EXPECT_LT(holes_rmse, 0.05);
  present.col(3).setConstant(false);
  EXPECT_FALSE(solver.value().Solve(holes, present).ok());

  // A wrong marker count is named, not a crash.
  EXPECT_FALSE(solver.value().Solve(markers.topRows(9)).ok());

  // Save / Load gives the same solve; truncated or missing files are named.
  facedyn::testing::TempDir dir;
  ASSERT_TRUE(solver.value().Save(dir.Join("s")).ok());
  StatusOr<FdlsSolver> loaded = FdlsSolver::Load(dir.Join("s"));
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded.value().Solve(markers).value(), solved);
  EXPECT_EQ(loaded.value().puppet().marker_basis_mm, puppet.marker_basis_mm);
  const std::string json = facedyn::testing::ReadBytes(dir.Join("s/solver.json"));
  facedyn::testing::WriteBytes(dir.Join("s/solver.json"), json.substr(0, json.size() / 2));
  loaded = FdlsSolver::Load(dir.Join("s"));
  ASSERT_FALSE(loaded.ok());
  EXPECT_NE(loaded.status().message().find("solver.json"), std::string::npos)
      << loaded.status().message();
  facedyn::testing::WriteBytes(dir.Join("s/solver.json"), json);
  facedyn::testing::WriteBytes(dir.Join("s/mouth.pt"), "not an archive");
  loaded = FdlsSolver::Load(dir.Join("s"));
  ASSERT_FALSE(loaded.ok());
  EXPECT_NE(loaded.status().message().find("mouth.pt"), std::string::npos)
      << loaded.status().message();
}

}  // namespace
}  // namespace facedyn::solve
