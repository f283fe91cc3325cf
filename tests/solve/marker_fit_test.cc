// The matching approach (FDLS Eq. 2): the QP baseline and bounded fine-tuning on the procedural
// face's puppet.
#include "solve/marker_fit.h"

#include <gtest/gtest.h>

#include <random>

#include "tests/solve/solve_test_rig.h"
#include "tests/support/test_support.h"

namespace facedyn::solve {
namespace {

using testing::ProceduralPuppet;

// Weights within [0, 1], a few frames, some at the bounds.
Eigen::MatrixXd SomeWeights(const Puppet& puppet, int frames, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  Eigen::MatrixXd w(puppet.channel_count(), frames);
  for (int f = 0; f < frames; ++f) {
    for (int c = 0; c < puppet.channel_count(); ++c) {
      const double u = unit(rng);
      w(c, f) = u < 0.3 ? 0.0 : (u > 0.9 ? 1.0 : unit(rng));
    }
  }
  return w;
}

Eigen::MatrixXd MarkersOf(const Puppet& puppet, const Eigen::MatrixXd& weights) {
  return (puppet.marker_basis_mm * weights).colwise() + puppet.StackedNeutral();
}

TEST(MakePuppet, ProceduralFaceHasItsChannelsAndMarkers) {
  const Puppet& puppet = ProceduralPuppet();
  EXPECT_EQ(puppet.channel_count(), 10);
  EXPECT_EQ(puppet.marker_count(), 150);
  EXPECT_GE(puppet.ChannelIndex("jaw_open"), 0);
  EXPECT_TRUE(puppet.symmetric_pairs.empty());  // no split channels on the procedural face
  // Every channel moves some marker by at least a millimetre at weight 1.
  for (int c = 0; c < puppet.channel_count(); ++c) {
    double peak = 0.0;
    for (int m = 0; m < puppet.marker_count(); ++m) {
      peak = std::max(peak, puppet.marker_basis_mm.block<3, 1>(3 * m, c).norm());
    }
    EXPECT_GT(peak, 1.0) << puppet.channel_names[c];
  }
}

TEST(SolveMarkersQp, RecoversExactWeightsFromCleanPuppetMarkers) {
  const Puppet& puppet = ProceduralPuppet();
  const Eigen::MatrixXd truth = SomeWeights(puppet, 20, 7);
  MarkerFitSummary summary;
  const StatusOr<Eigen::MatrixXd> solved =
      SolveMarkersQp(puppet, MarkersOf(puppet, truth), nullptr, &summary);
  ASSERT_TRUE(solved.ok()) << solved.status().ToString();
  EXPECT_EIGEN_NEAR(solved.value(), truth, 1e-6);
  EXPECT_LT(summary.final_rmse_mm, 1e-6);
  EXPECT_GT(summary.initial_rmse_mm, 0.5);
  EXPECT_EQ(summary.problems, 20);
}

TEST(SolveMarkersQp, IgnoresMissingMarkers) {
  const Puppet& puppet = ProceduralPuppet();
  const Eigen::MatrixXd truth = SomeWeights(puppet, 5, 8);
  Eigen::MatrixXd markers = MarkersOf(puppet, truth);
  MarkerPresence present = MarkerPresence::Constant(puppet.marker_count(), 5, true);
  for (int m = 0; m < puppet.marker_count(); m += 3) {
    present(m, 2) = false;
    markers.block<3, 1>(3 * m, 2).setConstant(1e3);  // garbage where missing
  }
  const StatusOr<Eigen::MatrixXd> solved = SolveMarkersQp(puppet, markers, &present, nullptr);
  ASSERT_TRUE(solved.ok()) << solved.status().ToString();
  EXPECT_EIGEN_NEAR(solved.value(), truth, 1e-6);
}

TEST(FitWeightsToMarkers, FinetuneStaysInBoundsAndLeavesFrozenChannels) {
  const Puppet& puppet = ProceduralPuppet();
  // Targets beyond the bounds: the puppet at weights in [-0.5, 1.5], plus noise.
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> wide(-0.5, 1.5);
  std::normal_distribution<double> noise(0.0, 0.3);
  Eigen::MatrixXd beyond(puppet.channel_count(), 12);
  for (Eigen::Index i = 0; i < beyond.size(); ++i) beyond.data()[i] = wide(rng);
  Eigen::MatrixXd markers = MarkersOf(puppet, beyond);
  for (Eigen::Index i = 0; i < markers.size(); ++i) markers.data()[i] += noise(rng);
  const Eigen::MatrixXd start = SomeWeights(puppet, 12, 4);
  for (const double smoothness : {0.0, 50.0}) {
    MarkerFitOptions options;
    options.free_channels = {puppet.ChannelIndex("smile"), puppet.ChannelIndex("jaw_open"),
                             puppet.ChannelIndex("brow_raise")};
    options.smoothness = smoothness;
    MarkerFitSummary summary;
    const StatusOr<Eigen::MatrixXd> tuned =
        FitWeightsToMarkers(puppet, markers, start, nullptr, options, &summary);
    ASSERT_TRUE(tuned.ok()) << tuned.status().ToString();
    EXPECT_GE(tuned.value().minCoeff(), 0.0);
    EXPECT_LE(tuned.value().maxCoeff(), 1.0);
    for (int c = 0; c < puppet.channel_count(); ++c) {
      if (std::count(options.free_channels.begin(), options.free_channels.end(), c)) continue;
      EXPECT_EQ(tuned.value().row(c), start.row(c)) << "frozen channel " << puppet.channel_names[c];
    }
    // Some free weight was pushed against a bound, and the fit improved.
    EXPECT_TRUE((tuned.value().array() == 0.0).any() || (tuned.value().array() == 1.0).any());
    EXPECT_LT(summary.final_rmse_mm, summary.initial_rmse_mm);
  }
}

TEST(FitWeightsToMarkers, SmoothnessReducesFrameToFrameChange) {
  const Puppet& puppet = ProceduralPuppet();
  Eigen::MatrixXd truth = Eigen::MatrixXd::Constant(puppet.channel_count(), 30, 0.4);
  Eigen::MatrixXd markers = MarkersOf(puppet, truth);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, 0.5);
  for (Eigen::Index i = 0; i < markers.size(); ++i) markers.data()[i] += noise(rng);
  auto roughness = [](const Eigen::MatrixXd& w) {
    return (w.rightCols(w.cols() - 1) - w.leftCols(w.cols() - 1)).squaredNorm();
  };
  MarkerFitOptions rough, smooth;
  smooth.smoothness = 2000.0;
  const Eigen::MatrixXd start = Eigen::MatrixXd::Zero(puppet.channel_count(), 30);
  const Eigen::MatrixXd a =
      FitWeightsToMarkers(puppet, markers, start, nullptr, rough, nullptr).value();
  const Eigen::MatrixXd b =
      FitWeightsToMarkers(puppet, markers, start, nullptr, smooth, nullptr).value();
  EXPECT_LT(roughness(b), 0.2 * roughness(a));
  EXPECT_LT((b - truth).norm(), (a - truth).norm());
}

TEST(FitWeightsToMarkers, BadInputIsNamed) {
  const Puppet& puppet = ProceduralPuppet();
  const Eigen::MatrixXd markers =
      MarkersOf(puppet, Eigen::MatrixXd::Zero(puppet.channel_count(), 2));
  const Eigen::MatrixXd start = Eigen::MatrixXd::Zero(puppet.channel_count(), 2);
  MarkerFitOptions options;
  options.free_channels = {99};
  StatusOr<Eigen::MatrixXd> result =
      FitWeightsToMarkers(puppet, markers, start, nullptr, options, nullptr);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find("free_channels"), std::string::npos)
      << result.status().message();
  result =
      FitWeightsToMarkers(puppet, markers.topRows(30), start, nullptr, MarkerFitOptions{}, nullptr);
  ASSERT_FALSE(result.ok());
  MarkerPresence none = MarkerPresence::Constant(puppet.marker_count(), 2, false);
  result = FitWeightsToMarkers(puppet, markers, start, &none, MarkerFitOptions{}, nullptr);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find("frame 0 has no marker"), std::string::npos);
}

}  // namespace
}  // namespace facedyn::solve
