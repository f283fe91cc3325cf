// Baselines: zero-phase low-pass of stabilised positions, no removal, moving average.

#include "dynamics/baselines.h"

#include <cmath>
#include <complex>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/mesh_primitives.h"
#include "dynamics/quasistatic.h"
#include "tests/support/test_support.h"

namespace facedyn::dynamics {
namespace {

constexpr double kPi = 3.14159265358979323846;

TEST(ButterworthLowPass, UnitDcGainAndHalfPowerAtCutoff) {
  const Biquad f = ButterworthLowPass(4.0, 128.0);
  EXPECT_NEAR((f.b0 + f.b1 + f.b2) / (1 + f.a1 + f.a2), 1.0, 1e-12);
  // |H(e^{i w})| at the cutoff is 1/sqrt(2) (pre-warped bilinear transform).
  const std::complex<double> z = std::polar(1.0, 2 * kPi * 4.0 / 128.0);
  const std::complex<double> h = (f.b0 + f.b1 / z + f.b2 / (z * z)) / (1.0 + f.a1 / z + f.a2 / (z * z));
  EXPECT_NEAR(std::abs(h), 1 / std::sqrt(2.0), 1e-9);
}

TEST(ZeroPhaseLowPass, AttenuatesElevenHertzKeepsDcAndSlowMotionInPhase) {
  const double fps = 128.0;
  const int frames = 384;
  Eigen::MatrixXd signal(3, frames);
  for (int t = 0; t < frames; ++t) {
    const double s = t / fps;
    signal(0, t) = 7.0;                                          // DC
    signal(1, t) = 7.0 + 2.0 * std::sin(2 * kPi * 11.0 * s);     // DC + 11 Hz jiggle
    signal(2, t) = 3.0 * std::sin(2 * kPi * 0.5 * s + 0.3);      // slow expression change
  }
  const Eigen::MatrixXd filtered = ZeroPhaseLowPass(signal, 4.0, fps).value();
  EXPECT_LT((filtered.row(0).array() - 7.0).abs().maxCoeff(), 1e-9);  // ends included
  const int edge = 32;
  const auto interior = [&](int row) { return filtered.row(row).segment(edge, frames - 2 * edge); };
  // 11 Hz through |H|^2 of a 4 Hz Butterworth: about 0.017 of the amplitude.
  EXPECT_LT((interior(1).array() - 7.0).abs().maxCoeff(), 0.05 * 2.0);
  // 0.5 Hz: gain ~1 and no lag (zero phase).
  EXPECT_LT((interior(2) - signal.row(2).segment(edge, frames - 2 * edge)).cwiseAbs().maxCoeff(), 0.01 * 3.0);
}

TEST(ZeroPhaseLowPass, RejectsCutoffAboveNyquistAndHandlesShortSignals) {
  const Eigen::MatrixXd signal = Eigen::MatrixXd::Ones(2, 3);
  const auto bad = ZeroPhaseLowPass(signal, 70.0, 128.0);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), ::testing::HasSubstr("cutoff"));
  const auto short_signal = ZeroPhaseLowPass(signal, 4.0, 128.0);
  ASSERT_TRUE(short_signal.ok());
  EXPECT_EIGEN_NEAR(*short_signal, signal, 1e-12);
}

// A rigidly moving patch whose skin oscillates at 11 Hz along the skull's z by 1 mm.
Take JigglingTake(const Mesh& rest, int frames, double fps) {
  Take take;
  take.info.fps = fps;
  take.topology = rest;
  take.positions.vertex_count = rest.vertex_count();
  take.positions.positions.resize(3 * rest.vertex_count(), frames);
  for (int t = 0; t < frames; ++t) {
    const double s = t / fps;
    take.world_from_skull.push_back(Rigid3::FromAxisAngle(
        Eigen::Vector3d(0.2, 1, 0).normalized(), 0.4 * std::sin(2 * kPi * 0.7 * s),
        {30 * std::sin(2 * kPi * 11.0 * s), 10 * s, 0}));
    Eigen::Matrix3Xd in_skull = rest.positions_mm;
    in_skull.row(2).array() += 1.0 * std::sin(2 * kPi * 11.0 * s);
    take.positions.Frame(t) = take.world_from_skull[t].Apply(in_skull).cast<float>();
  }
  take.SetUniformTimes();
  return take;
}

double MaxInteriorErrorToRest(const PointCache& estimate, const Take& take, const Mesh& rest, int edge) {
  double worst = 0;
  for (int t = edge; t < take.frame_count() - edge; ++t) {
    const Eigen::Matrix3Xd expected = take.world_from_skull[t].Apply(rest.positions_mm);
    worst = std::max(worst, (estimate.Frame(t).cast<double>() - expected).colwise().norm().maxCoeff());
  }
  return worst;
}

TEST(ComputeBaseline, LowPassRemovesStabilisedJiggleButNotHeadMotion) {
  const Mesh rest = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 6, 6);
  const Take take = JigglingTake(rest, 256, 128.0);
  BaselineOptions options;
  const PointCache lowpass = ComputeBaseline(take, BaselineKind::kLowPass, options).value();
  const PointCache none = ComputeBaseline(take, BaselineKind::kNoRemoval, options).value();
  const PointCache average = ComputeBaseline(take, BaselineKind::kMovingAverage, options).value();
  EXPECT_NEAR(MaxInteriorErrorToRest(none, take, rest, 32), 1.0, 0.01);
  // The 30 mm, 11 Hz head motion is untouched (it is not in the stabilised signal) and the
  // 1 mm skin jiggle is attenuated to a few percent.
  EXPECT_LT(MaxInteriorErrorToRest(lowpass, take, rest, 32), 0.05);
  // 11 Hz over a 21-frame box at 128 fps: |sinc| leaves about 0.2 of the amplitude.
  EXPECT_LT(MaxInteriorErrorToRest(average, take, rest, 32), 0.3);
  EXPECT_STREQ(BaselineName(BaselineKind::kLowPass), "lowpass");
  EXPECT_STREQ(BaselineName(BaselineKind::kNoRemoval), "no_removal");
  EXPECT_STREQ(BaselineName(BaselineKind::kMovingAverage), "moving_average");
}

TEST(BaselineOptions, CheckNamesTheField) {
  BaselineOptions options;
  EXPECT_TRUE(options.Check().ok());
  options.lowpass_cutoff_hz = 0;  // the rule
  EXPECT_TRUE(options.Check().ok());
  options.lowpass_cutoff_hz = -1;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("lowpass_cutoff_hz"));
  options = BaselineOptions();
  options.window_s = 2;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("window_s"));
}

}  // namespace
}  // namespace facedyn::dynamics

namespace facedyn::dynamics {
namespace {

// A take whose skull bobs vertically at `bob_hz` (and walks forward at 1 m/s) and records no
// platform frequency; its truth channels are whatever the caller puts there.
Take BobbingTake(double bob_hz, int frames, double fps) {
  Take take;
  take.info.fps = fps;
  take.topology = MakeEllipsoidPatch(40, 50, 45, 1.0, 0.8, 4, 4);
  take.positions.vertex_count = take.topology.vertex_count();
  take.positions.positions.resize(3 * take.positions.vertex_count, frames);
  for (int t = 0; t < frames; ++t) {
    const double s = t / fps;
    const Rigid3 pose = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitY(), 0.0,
                                              {0.0, 20 * std::sin(2 * kPi * bob_hz * s), 1000 * s});
    take.world_from_skull.push_back(pose);
    take.positions.Frame(t) = pose.Apply(take.topology.positions_mm).cast<float>();
  }
  take.SetUniformTimes();
  return take;
}

// The tuned low-pass needs no truth: its cutoff comes from the recorded platform frequency, or
// from the estimated skull motion's spectrum, and the truth channels do not change it.
TEST(LowPassCutoffByRule, FromThePlatformFrequencyOrTheSkullMotionNeverTheTruth) {
  Take take = BobbingTake(1.9, 384, 128.0);
  EXPECT_NEAR(DominantHeadMotionHz(take), 1.9, 0.1);
  EXPECT_NEAR(LowPassCutoffByRule(take), 1.9 / 3, 0.05);
  take.info.platform_hz = 9.0;  // a platform take: its recorded frequency decides
  EXPECT_DOUBLE_EQ(LowPassCutoffByRule(take), 3.0);
  take.info.platform_hz.reset();
  const PointCache without_truth =
      ComputeBaseline(take, BaselineKind::kLowPass, BaselineOptions()).value();
  take.channels["quasistatic"] = take.positions;
  take.channels["quasistatic"].positions.setRandom();
  take.channels["dynamic_offset"] = take.channels["quasistatic"];
  const PointCache with_truth =
      ComputeBaseline(take, BaselineKind::kLowPass, BaselineOptions()).value();
  EXPECT_EQ(with_truth.positions, without_truth.positions);
  // A head that does not move: nothing to remove, the cutoff sits at 0.45 fps.
  Take still = BobbingTake(1.9, 384, 128.0);
  for (Rigid3& pose : still.world_from_skull) pose = Rigid3();
  EXPECT_DOUBLE_EQ(LowPassCutoffByRule(still), 0.45 * 128.0);
  // An explicit cutoff overrides the rule.
  BaselineOptions fixed;
  fixed.lowpass_cutoff_hz = 4.0;
  EXPECT_NE(ComputeBaseline(take, BaselineKind::kLowPass, fixed).value().positions,
            without_truth.positions);
}

}  // namespace
}  // namespace facedyn::dynamics
