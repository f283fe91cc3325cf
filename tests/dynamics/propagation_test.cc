// Propagation of sample offsets to every vertex (dynamics/propagation.h).

#include "dynamics/propagation.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "sim/procedural_face.h"
#include "tests/support/test_support.h"

namespace facedyn::dynamics {
namespace {

const FaceRig& Face() {
  static const FaceRig* rig = [] {
    sim::ProceduralFaceOptions options;
    options.target_vertex_count = 4000;
    return new FaceRig(sim::MakeProceduralFace(options).value());
  }();
  return *rig;
}

TEST(PropagationOptions, CheckNamesTheField) {
  PropagationOptions options;
  EXPECT_TRUE(options.Check().ok());
  options.constraint_weight = 0;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("constraint_weight"));
}

TEST(SamplePropagation, ReproducesAConstantOffsetEverywhere) {
  const FaceRig& rig = Face();
  const auto propagation = SamplePropagation::Build(rig);
  ASSERT_TRUE(propagation.ok()) << propagation.status().message();
  ASSERT_EQ(propagation->vertex_count(), rig.vertex_count());
  Eigen::Matrix3Xf samples(3, propagation->sample_count());
  samples.colwise() = Eigen::Vector3f(1.0f, -2.0f, 0.5f);
  Eigen::Matrix3Xf vertices(3, rig.vertex_count());
  propagation->Apply(samples, vertices);
  // Constants have zero Laplacian energy: only epsilon pulls them, by ~epsilon / lambda.
  for (int v = 0; v < rig.vertex_count(); ++v) {
    ASSERT_NEAR(vertices(0, v), 1.0f, 2e-3) << "vertex " << v;
    ASSERT_NEAR(vertices(1, v), -2.0f, 4e-3) << "vertex " << v;
  }
}

TEST(SamplePropagation, NearlyInterpolatesTheSamplesAndStaysBounded) {
  const FaceRig& rig = Face();
  const auto propagation = SamplePropagation::Build(rig).value();
  // A smooth field over the face: offsets = 0.01 * position in skull (mm -> mm).
  const Eigen::Matrix3Xd sample_positions = rig.SamplePositions(rig.neutral.positions_mm);
  const Eigen::Matrix3Xf samples = (0.01 * sample_positions).cast<float>();
  Eigen::Matrix3Xf vertices(3, rig.vertex_count());
  propagation.Apply(samples, vertices);
  double worst_at_samples = 0;
  for (int i = 0; i < propagation.sample_count(); ++i) {
    const Eigen::Vector3d at_sample = rig.skin_samples[i].Evaluate(vertices);
    worst_at_samples =
        std::max(worst_at_samples, (at_sample - samples.col(i).cast<double>()).norm());
  }
  // Offsets at the samples are up to ~1.5 mm; the soft constraints hold them to a few percent.
  EXPECT_LT(worst_at_samples, 0.05);
  // No overshoot: every vertex stays within the range of the sample values (+10%).
  const float lo = samples.row(1).minCoeff(), hi = samples.row(1).maxCoeff();
  const float margin = 0.1f * (hi - lo);
  EXPECT_GE(vertices.row(1).minCoeff(), lo - margin);
  EXPECT_LE(vertices.row(1).maxCoeff(), hi + margin);
}

TEST(SamplePropagation, DoesNotLeakAcrossTheMouth) {
  const FaceRig& rig = Face();
  const auto propagation = SamplePropagation::Build(rig).value();
  ASSERT_TRUE(rig.regions.count("upper_lip") && rig.regions.count("lower_lip"));
  const std::vector<int>& upper = rig.regions.at("upper_lip");
  std::vector<bool> is_upper(rig.vertex_count(), false);
  for (int v : upper) is_upper[v] = true;
  // Upper-lip samples move 1 mm, every other sample stays.
  Eigen::Matrix3Xf samples = Eigen::Matrix3Xf::Zero(3, propagation.sample_count());
  int moved = 0;
  for (int i = 0; i < propagation.sample_count(); ++i) {
    if (is_upper[rig.skin_samples[i].vertices[0]]) {
      samples(1, i) = 1.0f;
      ++moved;
    }
  }
  ASSERT_GT(moved, 0);
  Eigen::Matrix3Xf vertices(3, rig.vertex_count());
  propagation.Apply(samples, vertices);
  double upper_mean = 0, lower_mean = 0;
  for (int v : upper) upper_mean += vertices(1, v);
  for (int v : rig.regions.at("lower_lip")) lower_mean += std::abs(vertices(1, v));
  upper_mean /= upper.size();
  lower_mean /= rig.regions.at("lower_lip").size();
  EXPECT_GT(upper_mean, 0.5);
  EXPECT_LT(lower_mean, 0.25 * upper_mean) << "upper " << upper_mean << " lower " << lower_mean;
}

TEST(SamplePropagation, RefusesARigWithoutSamples) {
  FaceRig rig = Face();
  rig.skin_samples.clear();
  EXPECT_EQ(SamplePropagation::Build(rig).status().code(), StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace facedyn::dynamics
