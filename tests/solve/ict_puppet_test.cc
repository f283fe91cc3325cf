// The realistic puppet: an ICT-FaceKit rig (55 ARKit channels) with config/solve/ict.yaml.
// Skipped when ../shared/assets/ict-facekit is absent (a failure under CI=true).
#include <gtest/gtest.h>

#include "sim/ict_import.h"
#include "solve/marker_fit.h"
#include "solve/puppet.h"
#include "solve/solve_config.h"
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
