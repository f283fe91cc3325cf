#include "reconstruct/tracking.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

#include "reconstruct/assignment.h"
#include "sim/performance.h"
#include "tests/reconstruct/reconstruct_test_util.h"
#include "tests/support/test_support.h"

namespace facedyn::reconstruct {
namespace {

TEST(SolveAssignment, MatchesBruteForce) {
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> uniform(0.0, 10.0);
  for (int trial = 0; trial < 30; ++trial) {
    const int rows = 2 + trial % 4, cols = rows + trial % 3;
    Eigen::MatrixXd cost(rows, cols);
    for (int i = 0; i < rows; ++i) {
      for (int j = 0; j < cols; ++j) cost(i, j) = uniform(rng);
    }
    const std::vector<int> assignment = SolveAssignment(cost);
    double total = 0.0;
    std::vector<int> taken;
    for (int i = 0; i < rows; ++i) {
      total += cost(i, assignment[i]);
      taken.push_back(assignment[i]);
    }
    std::sort(taken.begin(), taken.end());
    EXPECT_EQ(std::unique(taken.begin(), taken.end()), taken.end());
    std::vector<int> columns(cols);
    std::iota(columns.begin(), columns.end(), 0);
    double best = 1e18;
    do {
      double sum = 0.0;
      for (int i = 0; i < rows; ++i) sum += cost(i, columns[i]);
      best = std::min(best, sum);
    } while (std::next_permutation(columns.begin(), columns.end()));
    EXPECT_NEAR(total, best, 1e-9) << "trial " << trial;
  }
}

TEST(SolveGatedAssignment, LeavesFarItemsUnassigned) {
  Eigen::MatrixXd cost(3, 2);
  cost << 1.0, 9.0, 9.0, 2.0, 50.0, 60.0;
  const std::vector<int> assignment = SolveGatedAssignment(cost, 4.0);
  EXPECT_EQ(assignment, (std::vector<int>{0, 1, -1}));
}

Eigen::Matrix3Xd Shuffle(const Eigen::Matrix3Xd& points, std::mt19937* rng,
                         std::vector<int>* marker_of_point) {
  std::vector<int> order(points.cols());
  std::iota(order.begin(), order.end(), 0);
  std::shuffle(order.begin(), order.end(), *rng);
  Eigen::Matrix3Xd shuffled(3, points.cols());
  marker_of_point->assign(points.cols(), -1);
  for (size_t k = 0; k < order.size(); ++k) shuffled.col(k) = points.col(order[k]);
  *marker_of_point = order;
  return shuffled;
}

TEST(FitRigToPoints, LabelsARotatedExpressiveFaceWithoutPrior) {
  const FaceRig& rig = testing::ProceduralFace();
  Eigen::VectorXd weights = Eigen::VectorXd::Zero(rig.blendshape_names.size());
  weights[rig.BlendshapeIndex("jaw_open")] = 0.6;
  weights[rig.BlendshapeIndex("smile")] = 0.4;
  const Rigid3 world_from_skull = Rigid3::FromAxisAngle(Eigen::Vector3d(0.3, 1.0, 0.2).normalized(),
                                                        1.1, Eigen::Vector3d(40, 1500, -300));
  const Eigen::Matrix3Xd markers =
      world_from_skull.Apply(testing::MarkerPositions(rig, rig.Evaluate(weights)));
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.07);
  // 10% of the markers unseen, 6 clutter points.
  std::vector<int> kept;
  for (int m = 0; m < markers.cols(); ++m) {
    if (m % 10 != 3) kept.push_back(m);
  }
  Eigen::Matrix3Xd points(3, kept.size() + 6);
  for (size_t k = 0; k < kept.size(); ++k) {
    points.col(k) = markers.col(kept[k]) + Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
  }
  for (int k = 0; k < 6; ++k) {
    points.col(kept.size() + k) = world_from_skull * Eigen::Vector3d(30.0 * k - 75, 120, 40);
  }
  std::vector<int> order;
  const Eigen::Matrix3Xd shuffled = Shuffle(points, &rng, &order);
  const auto fit = FitRigToPoints(rig, shuffled, TrackingOptions());
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  int correct = 0, wrong = 0;
  for (int m = 0; m < markers.cols(); ++m) {
    const int j = fit->point_of_marker[m];
    if (j < 0) continue;
    const int source = order[j];
    if (source < static_cast<int>(kept.size()) && kept[source] == m) {
      ++correct;
    } else {
      ++wrong;
    }
  }
  std::printf(
      "labelled %d correctly, %d wrongly of %zu seen; rms %.3f mm; jaw_open %.2f smile %.2f\n",
      correct, wrong, kept.size(), fit->rms_mm,
      fit->blendshape_weights[rig.BlendshapeIndex("jaw_open")],
      fit->blendshape_weights[rig.BlendshapeIndex("smile")]);
  EXPECT_EQ(wrong, 0);
  EXPECT_GE(correct, static_cast<int>(0.97 * kept.size()));
  EXPECT_NEAR(fit->blendshape_weights[rig.BlendshapeIndex("jaw_open")], 0.6, 0.1);
  EXPECT_LT((fit->world_from_skull.translation() - world_from_skull.translation()).norm(), 1.0);
}

TEST(FitRigToPoints, TooFewPointsIsAnError) {
  const auto fit =
      FitRigToPoints(testing::ProceduralFace(), Eigen::Matrix3Xd::Zero(3, 4), TrackingOptions());
  ASSERT_FALSE(fit.ok());
  EXPECT_NE(fit.status().message().find("only 4 points"), std::string::npos);
}

// A simulated performance on the 11 Hz platform: per frame the true marker positions plus
// triangulation-level noise, a few markers dropped at random, one hidden for 10 frames, clutter
// points, and a frame with no points at all.
TEST(MarkerTracker, SimulatedPlatformTakeWithoutSwaps) {
  const FaceRig& rig = testing::ProceduralFace();
  sim::PerformanceOptions performance;
  performance.expression = "speech";
  performance.motion.kind = sim::MotionKind::kPlatform;
  performance.motion.platform_hz = 11.0;
  performance.motion.amplitude_mm = 2.0;
  performance.seconds = 1.0;
  performance.fps = 128.0;
  const auto take = sim::SimulatePerformance(rig, performance);
  ASSERT_TRUE(take.ok()) << take.status().ToString();
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 0.07);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  MarkerTracker tracker(rig, TrackingOptions());
  std::vector<std::vector<int>> truth;  // per frame, marker of each point (-1 clutter)
  const int hidden = 17;
  for (int f = 0; f < take->frame_count(); ++f) {
    const Eigen::Matrix3Xd markers = testing::MarkerPositions(rig, take->FramePositions(f));
    std::vector<TriangulatedPoint> points;
    std::vector<int> marker_of_point;
    if (f != 40) {
      for (int m = 0; m < markers.cols(); ++m) {
        if (uniform(rng) < 0.05 || (m == hidden && f >= 60 && f < 70)) continue;
        TriangulatedPoint p;
        p.position_in_world = markers.col(m) + Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
        p.confidence = 0.9;
        points.push_back(p);
        marker_of_point.push_back(m);
      }
      for (int k = 0; k < 3; ++k) {
        TriangulatedPoint p;
        p.position_in_world = take->world_from_skull[f] *
                              Eigen::Vector3d(100 * uniform(rng) - 50, 80 + 40 * uniform(rng), 60);
        p.confidence = 0.5;
        points.push_back(p);
        marker_of_point.push_back(-1);
      }
    }
    std::vector<int> order(points.size());
    std::iota(order.begin(), order.end(), 0);
    std::shuffle(order.begin(), order.end(), rng);
    std::vector<TriangulatedPoint> shuffled;
    std::vector<int> shuffled_truth;
    for (int k : order) {
      shuffled.push_back(points[k]);
      shuffled_truth.push_back(marker_of_point[k]);
    }
    truth.push_back(shuffled_truth);
    ASSERT_TRUE(tracker.AddFrame(shuffled).ok()) << "frame " << f;
  }
  const std::vector<TrackedFrame> frames = tracker.Finish();
  ASSERT_EQ(static_cast<int>(frames.size()), take->frame_count());
  int wrong = 0, observed = 0, offered = 0, bridged = 0;
  double bridged_worst_mm = 0.0;
  for (int f = 0; f < take->frame_count(); ++f) {
    const Eigen::Matrix3Xd markers = testing::MarkerPositions(rig, take->FramePositions(f));
    for (int t : truth[f]) offered += t >= 0 ? 1 : 0;
    for (int m = 0; m < tracker.marker_count(); ++m) {
      if (frames[f].states[m] == MarkerState::kObserved) {
        ++observed;
        if (truth[f][frames[f].point_of_marker[m]] != m) ++wrong;
      } else if (frames[f].states[m] == MarkerState::kBridged) {
        ++bridged;
        const double e = (frames[f].positions_in_world.col(m) - markers.col(m)).norm();
        bridged_worst_mm = std::max(bridged_worst_mm, e);
      }
    }
  }
  std::printf("%d of %d offered labelled, %d wrong, %d bridged (worst %.3f mm)\n", observed,
              offered, wrong, bridged, bridged_worst_mm);
  EXPECT_EQ(wrong, 0);
  EXPECT_GE(observed, 0.995 * offered);
  EXPECT_EQ(frames[65].states[hidden], MarkerState::kBridged);
  EXPECT_EQ(frames[40].observed(), 0);
  EXPECT_EQ(frames[40].states[0], MarkerState::kBridged);
  EXPECT_LT(bridged_worst_mm, 1.0);
  EXPECT_GT(frames[70].confidence[hidden], 0.5);  // re-acquired after the gap
}

}  // namespace
}  // namespace facedyn::reconstruct
