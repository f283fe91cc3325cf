// ExpressionCurve: held expressions reach and hold their target, speech visits its key poses;
// both stay in [0, 1], are smooth and deterministic for a seed.
#include "sim/expression_curve.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <vector>

#include "tests/support/test_support.h"

namespace facedyn::sim {
namespace {

Eigen::VectorXd Target() {
  Eigen::VectorXd target(5);
  target << 1.0, 0.6, 0.0, 0.25, 0.98;
  return target;
}

std::vector<Eigen::VectorXd> KeyPoses() {
  std::vector<Eigen::VectorXd> poses;
  for (int i = 0; i < 5; ++i) {
    Eigen::VectorXd pose = Eigen::VectorXd::Zero(6);
    pose[i] = 0.8;
    pose[5] = 0.1 * i;  // a shared jaw-like channel
    poses.push_back(pose);
  }
  return poses;
}

// Largest |w(t + h) - 2 w(t) + w(t - h)| / h^2 over [t0, t1].
double MaxSecondDerivative(const ExpressionCurve& curve, double t0, double t1, double h) {
  double max_value = 0.0;
  for (double t = t0; t < t1; t += h) {
    const Eigen::VectorXd d2 =
        (curve.Weights(t + h) - 2.0 * curve.Weights(t) + curve.Weights(t - h)) / (h * h);
    max_value = std::max(max_value, d2.cwiseAbs().maxCoeff());
  }
  return max_value;
}

TEST(MakeHeldExpression, ReachesTargetWithinDriftAndStaysInUnitInterval) {
  const Eigen::VectorXd target = Target();
  const double drift = 0.03;
  const auto curve = MakeHeldExpression(target, 0.3, drift, 7);
  ASSERT_EQ(curve->size(), 5);
  EXPECT_EIGEN_NEAR(curve->Weights(0.0), Eigen::VectorXd::Zero(5), 0.0);
  EXPECT_EIGEN_NEAR(curve->Weights(-1.0), Eigen::VectorXd::Zero(5), 0.0);
  Eigen::VectorXd max_deviation = Eigen::VectorXd::Zero(5);
  for (double t = 0.0; t < 20.0; t += 0.005) {
    const Eigen::VectorXd w = curve->Weights(t);
    EXPECT_GE(w.minCoeff(), 0.0) << "t = " << t;
    EXPECT_LE(w.maxCoeff(), 1.0) << "t = " << t;
    if (t >= 0.3) max_deviation = max_deviation.cwiseMax((w - target).cwiseAbs());
  }
  // Within twice the peak drift (a weight at 1 drifts downward only), and it does drift.
  for (int i = 0; i < 5; ++i) {
    EXPECT_LE(max_deviation[i], 2.0 * drift * target[i] + 1e-12) << "weight " << i;
  }
  EXPECT_GT(max_deviation[1], 0.2 * drift * target[1]);
  EXPECT_EQ(max_deviation[2], 0.0);  // a zero target stays zero
}

TEST(MakeHeldExpression, IsSmoothAndSlow) {
  const auto curve = MakeHeldExpression(Target(), 0.3, 0.03, 7);
  // The ramp's second derivative peaks at 2 pi / ramp^2 ~ 70 per s^2; the drift (< 1 Hz,
  // amplitude 0.03) adds < (2 pi 0.8)^2 0.03 ~ 0.8.
  EXPECT_LT(MaxSecondDerivative(*curve, -0.1, 0.5, 1e-3), 75.0);
  EXPECT_LT(MaxSecondDerivative(*curve, 0.5, 10.0, 1e-3), 0.8);
}

TEST(MakeHeldExpression, DeterministicForSeed) {
  const auto a = MakeHeldExpression(Target(), 0.3, 0.03, 7);
  const auto b = MakeHeldExpression(Target(), 0.3, 0.03, 7);
  const auto c = MakeHeldExpression(Target(), 0.3, 0.03, 8);
  double same = 0.0, different = 0.0;
  for (double t = 0.0; t < 5.0; t += 0.05) {
    same = std::max(same, (a->Weights(t) - b->Weights(t)).cwiseAbs().maxCoeff());
    different = std::max(different, (a->Weights(t) - c->Weights(t)).cwiseAbs().maxCoeff());
  }
  EXPECT_EQ(same, 0.0);
  EXPECT_GT(different, 1e-3);
}

TEST(MakeSpeechSequence, VisitsSeveralKeyPosesAtSyllableRate) {
  const std::vector<Eigen::VectorXd> poses = KeyPoses();
  const double rate = 4.5;
  const auto curve = MakeSpeechSequence(poses, rate, 3);
  ASSERT_EQ(curve->size(), 6);
  std::set<int> visited;
  int arrivals = 0;
  bool at_pose = false;
  for (double t = 0.0; t < 10.0; t += 1e-3) {
    const Eigen::VectorXd w = curve->Weights(t);
    ASSERT_GE(w.minCoeff(), 0.0);
    ASSERT_LE(w.maxCoeff(), 1.0);
    int nearest = -1;
    for (size_t k = 0; k < poses.size(); ++k) {
      if ((w - poses[k]).cwiseAbs().maxCoeff() < 1e-3) nearest = static_cast<int>(k);
    }
    if (nearest >= 0) visited.insert(nearest);
    // Count arrivals at a new pose (consecutive repeats of one pose count once).
    if (nearest >= 0 && !at_pose) ++arrivals;
    at_pose = nearest >= 0;
  }
  EXPECT_GE(visited.size(), 4u);
  // ~45 syllables in 10 s, fewer arrivals when a pose repeats.
  EXPECT_GT(arrivals, 25);
  EXPECT_LE(arrivals, 50);
}

TEST(MakeSpeechSequence, IsSmoothAndDeterministic) {
  const auto a = MakeSpeechSequence(KeyPoses(), 4.5, 3);
  const auto b = MakeSpeechSequence(KeyPoses(), 4.5, 3);
  const auto c = MakeSpeechSequence(KeyPoses(), 4.5, 4);
  // Shortest knot interval 0.5 / 4.5 s; quintic smootherstep's second derivative peaks at
  // 10 / sqrt(3) / interval^2 per unit of pose difference (0.8): ~370 per s^2.
  EXPECT_LT(MaxSecondDerivative(*a, -0.1, 5.0, 2e-4), 400.0);
  double same = 0.0, different = 0.0;
  for (double t = 0.0; t < 5.0; t += 0.01) {
    same = std::max(same, (a->Weights(t) - b->Weights(t)).cwiseAbs().maxCoeff());
    different = std::max(different, (a->Weights(t) - c->Weights(t)).cwiseAbs().maxCoeff());
  }
  EXPECT_EQ(same, 0.0);
  EXPECT_GT(different, 0.1);
  EXPECT_EIGEN_NEAR(a->Weights(0.0), Eigen::VectorXd::Zero(6), 0.0);
}

// A scripted range of motion: every key pose once per cycle (the knot times are the speech
// sequence's, k / rate with +-0.25 jitter, so knot k is reached by (k + 0.25) / rate), each
// cycle in its own seeded order.
TEST(MakeScriptedSequence, VisitsEveryPoseOncePerCycle) {
  const std::vector<Eigen::VectorXd> poses = KeyPoses();
  const double rate = 3.0;
  const auto curve = MakeScriptedSequence(poses, rate, 5);
  const int n = static_cast<int>(poses.size());
  std::vector<std::vector<int>> cycles(3);
  for (int k = 1; k <= 3 * n; ++k) {
    // The weights at knot k's time are pose(k); find it between the jittered bounds by the
    // sample closest to a key pose.
    int found = -1;
    for (double t = (k - 0.26) / rate; t <= (k + 0.26) / rate && found < 0; t += 1e-4) {
      const Eigen::VectorXd w = curve->Weights(t);
      for (int p = 0; p < n; ++p) {
        if ((w - poses[p]).cwiseAbs().maxCoeff() < 1e-6) found = p;
      }
    }
    ASSERT_GE(found, 0) << "knot " << k;
    cycles[(k - 1) / n].push_back(found);
  }
  for (std::vector<int>& cycle : cycles) {
    std::vector<int> sorted = cycle;
    std::sort(sorted.begin(), sorted.end());
    for (int p = 0; p < n; ++p) EXPECT_EQ(sorted[p], p);  // a permutation
  }
  EXPECT_NE(cycles[0], cycles[1]);  // seeded per cycle (this seed; 5! = 120 possible orders)
  const auto other = MakeScriptedSequence(poses, rate, 6);
  double different = 0.0;
  for (double t = 0.0; t < 2.0 * n / rate; t += 0.01) {
    different = std::max(different, (curve->Weights(t) - other->Weights(t)).cwiseAbs().maxCoeff());
  }
  EXPECT_GT(different, 0.1);
}

TEST(MakeHeldExpression, AcceptsARigWithoutBlendshapes) {
  const auto curve = MakeHeldExpression(Eigen::VectorXd(0), 0.3, 0.02, 1);
  EXPECT_EQ(curve->size(), 0);
  EXPECT_EQ(curve->Weights(1.0).size(), 0);
}

}  // namespace
}  // namespace facedyn::sim
