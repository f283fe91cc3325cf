// Graph features (FDLS 4.3) against values worked out by hand.
#include "solve/features.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace facedyn::solve {
namespace {

TEST(FeatureSize, CountsPairsAndMarkers) {
  EXPECT_EQ(FeatureSize(4, FeatureSet{true, false, false}), 6);
  EXPECT_EQ(FeatureSize(4, FeatureSet{false, true, false}), 18);
  EXPECT_EQ(FeatureSize(4, FeatureSet{false, false, true}), 12);
  EXPECT_EQ(FeatureSize(4, FeatureSet{}), 36);
}

// Three markers: a 3-4-5 right triangle in the XY plane, neutral one millimetre lower.
TEST(ComputeGraphFeatures, RightTriangleByHand) {
  Eigen::Matrix3Xd x(3, 3), neutral(3, 3);
  x << 0, 3, 0,  //
      0, 0, 4,   //
      1, 1, 1;
  neutral = x;
  neutral.row(1).array() -= 1.0;
  std::vector<float> f(FeatureSize(3, FeatureSet{}));
  ComputeGraphFeatures(x, neutral, FeatureSet{}, f.data());
  // Distances (0,1) = 3, (0,2) = 4, (1,2) = 5.
  EXPECT_FLOAT_EQ(f[0], 3.0f);
  EXPECT_FLOAT_EQ(f[1], 4.0f);
  EXPECT_FLOAT_EQ(f[2], 5.0f);
  // Directions x_j - x_i normalised: (1,0,0), (0,1,0), (-3/5, 4/5, 0).
  const float directions[9] = {1, 0, 0, 0, 1, 0, -0.6f, 0.8f, 0};
  for (int i = 0; i < 9; ++i) EXPECT_FLOAT_EQ(f[3 + i], directions[i]) << "direction " << i;
  // Delta pose: +1 in y for every marker.
  const float deltas[9] = {0, 1, 0, 0, 1, 0, 0, 1, 0};
  for (int i = 0; i < 9; ++i) EXPECT_FLOAT_EQ(f[12 + i], deltas[i]) << "delta " << i;
}

TEST(ComputeGraphFeatures, SubsetsKeepTheOrderDistanceDirectionDelta) {
  Eigen::Matrix3Xd x(3, 2), neutral = Eigen::Matrix3Xd::Zero(3, 2);
  x << 1, 1,  //
      2, 2,   //
      0, 2;
  std::vector<float> f(FeatureSize(2, FeatureSet{true, false, true}));
  ASSERT_EQ(f.size(), 7u);
  ComputeGraphFeatures(x, neutral, FeatureSet{true, false, true}, f.data());
  EXPECT_FLOAT_EQ(f[0], 2.0f);
  const float deltas[6] = {1, 2, 0, 1, 2, 2};
  for (int i = 0; i < 6; ++i) EXPECT_FLOAT_EQ(f[1 + i], deltas[i]);
  std::vector<float> g(FeatureSize(2, FeatureSet{false, true, false}));
  ComputeGraphFeatures(x, neutral, FeatureSet{false, true, false}, g.data());
  EXPECT_FLOAT_EQ(g[0], 0.0f);
  EXPECT_FLOAT_EQ(g[1], 0.0f);
  EXPECT_FLOAT_EQ(g[2], 1.0f);
}

TEST(ComputeGraphFeatures, DistancesAndDirectionsIgnoreAMaskShiftDeltasDoNot) {
  Eigen::Matrix3Xd x(3, 4);
  x << 0, 10, 3, -7,  //
      1, 2, 8, -4,    //
      5, 6, 9, 2;
  const Eigen::Matrix3Xd neutral = x * 0.9;
  Eigen::Matrix3Xd shifted = x;
  shifted.colwise() += Eigen::Vector3d(0.5, -2.0, 1.0);
  const int size = FeatureSize(4, FeatureSet{});
  std::vector<float> a(size), b(size);
  ComputeGraphFeatures(x, neutral, FeatureSet{}, a.data());
  ComputeGraphFeatures(shifted, neutral, FeatureSet{}, b.data());
  for (int i = 0; i < 6 + 18; ++i) EXPECT_NEAR(a[i], b[i], 1e-5) << i;
  EXPECT_NEAR(b[24] - a[24], 0.5, 1e-5);
  EXPECT_NEAR(b[25] - a[25], -2.0, 1e-5);
}

TEST(ComputeGraphFeatures, CoincidentMarkersGiveZeroDirectionNotNan) {
  const Eigen::Matrix3Xd x = Eigen::Matrix3Xd::Ones(3, 2);
  std::vector<float> f(FeatureSize(2, FeatureSet{}));
  ComputeGraphFeatures(x, x, FeatureSet{}, f.data());
  for (float value : f) EXPECT_EQ(value, 0.0f);
}

TEST(FeatureSet, ParsesAndNamesBadParts) {
  const StatusOr<FeatureSet> set = FeatureSet::Parse("distance+delta");
  ASSERT_TRUE(set.ok()) << set.status().ToString();
  EXPECT_TRUE(set.value().distance);
  EXPECT_FALSE(set.value().direction);
  EXPECT_TRUE(set.value().delta);
  EXPECT_EQ(set.value().ToString(), "distance+delta");
  const StatusOr<FeatureSet> bad = FeatureSet::Parse("distance+angle");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("'angle'"), std::string::npos) << bad.status().message();
}

}  // namespace
}  // namespace facedyn::solve
