// The realistic puppet: an ICT-FaceKit rig (55 ARKit channels) with config/solve/ict.yaml.
// Skipped when ../shared/assets/ict-facekit is absent (a failure under CI=true).
#include <gtest/gtest.h>

#include "sim/ict_import.h"
#include "solve/marker_fit.h"
#include "solve/puppet.h"
#include "solve/solve_config.h"
#include "solve/training_data.h"
#include "tests/support/test_support.h"

namespace facedyn::solve {
namespace {

TEST(IctPuppet, TablesResolveAndPairsAreFoundByName) {
  FACEDYN_REQUIRE_SHARED_ASSET(neutral, "ict-facekit/generic_neutral_mesh.obj");
  sim::IctImportOptions options;
  options.dir = neutral.substr(0, neutral.rfind('/'));
  const StatusOr<FaceRig> rig = sim::ImportIctFaceKit(options);
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  const Puppet puppet = MakePuppet(rig.value()).value();
  EXPECT_EQ(puppet.channel_count(), 55);
  // Every _L with its _R (21 pairs); jawLeft/jawRight and mouthLeft/mouthRight are sideways
  // motions, not split shapes.
  EXPECT_EQ(puppet.symmetric_pairs.size(), 21u);
  for (const auto& [left, right] : puppet.symmetric_pairs) {
    const std::string& l = puppet.channel_names[left];
    const std::string& r = puppet.channel_names[right];
    EXPECT_EQ(l.substr(0, l.size() - 2), r.substr(0, r.size() - 2));
  }
  const StatusOr<SolveConfig> config =
      ReadSolveConfig(std::string(FACEDYN_SOURCE_DIR) + "/config/solve/ict.yaml");
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  const StatusOr<ResolvedConfig> resolved = ResolveSolveConfig(config.value(), rig.value(), puppet);
  ASSERT_TRUE(resolved.ok()) << resolved.status().ToString();
  EXPECT_EQ(resolved.value().jaw.channels.size(), 4u);

  // The procedural tables on this rig name the first channel the rig lacks.
  const StatusOr<ResolvedConfig> wrong =
      ResolveSolveConfig(ProceduralSolveConfig().value(), rig.value(), puppet);
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.status().message().find("'jaw_open', which the rig does not have"),
            std::string::npos)
      << wrong.status().message();

  // Training poses: the sweeps, then each pair symmetric and asymmetric (both sides at a, one
  // side at a and the other at a/2), FDLS 4.1.
  TrainingDataOptions data_options;
  data_options.sweep_steps = 4;
  data_options.rom_clips = 0;
  data_options.random_combos = 0;
  const Eigen::MatrixXd poses = MakeTrainingWeights(puppet, data_options).value();
  ASSERT_EQ(poses.cols(), 1 + 55 * 4 + 21 * 4 * 3);
  const auto [left, right] = puppet.symmetric_pairs.front();
  const Eigen::Index first_pair = 1 + 55 * 4;
  EXPECT_EQ(poses(left, first_pair), 0.25);
  EXPECT_EQ(poses(right, first_pair), 0.25);
  EXPECT_EQ(poses(right, first_pair + 1), 0.125);
  EXPECT_EQ(poses.col(first_pair).cwiseAbs().sum(), 0.5);

  // QP on clean puppet markers: the marker residual vanishes whatever the rank of B.
  Eigen::MatrixXd truth = Eigen::MatrixXd::Zero(puppet.channel_count(), 3);
  truth(puppet.ChannelIndex("jawOpen"), 0) = 0.6;
  truth(puppet.ChannelIndex("mouthSmile_L"), 1) = 0.8;
  truth(puppet.ChannelIndex("browInnerUp_R"), 2) = 0.5;
  const Eigen::MatrixXd markers =
      (puppet.marker_basis_mm * truth).colwise() + puppet.StackedNeutral();
  MarkerFitSummary summary;
  const Eigen::MatrixXd solved = SolveMarkersQp(puppet, markers, nullptr, &summary).value();
  EXPECT_LT(summary.final_rmse_mm, 0.01);
  EXPECT_NEAR(solved(puppet.ChannelIndex("jawOpen"), 0), 0.6, 0.05);
}

}  // namespace
}  // namespace facedyn::solve
