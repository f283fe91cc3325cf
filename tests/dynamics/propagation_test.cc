// Propagation of sample offsets to every vertex (dynamics/propagation.h).

#include "dynamics/propagation.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

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

// Vertex offsets (3 x V) of a few fixed spatial patterns the Laplacian interpolant cannot
// reproduce from the samples (fine ripples of ~6 mm wavelength between ~10 mm-spaced samples, and
// a step across the face's midline), mixed with per-frame coefficients.
struct Patterns {
  std::vector<Eigen::Matrix3Xf> fields;
  PointCache Mix(int frames, uint64_t seed) const {
    std::mt19937_64 rng(seed);
    std::normal_distribution<float> normal(0.0f, 1.0f);
    PointCache cache;
    cache.vertex_count = static_cast<int>(fields[0].cols());
    cache.positions = Eigen::MatrixXf::Zero(3 * cache.vertex_count, frames);
    for (int t = 0; t < frames; ++t) {
      Eigen::Map<Eigen::Matrix3Xf> frame = cache.Frame(t);
      for (const Eigen::Matrix3Xf& field : fields) frame += normal(rng) * field;
    }
    return cache;
  }
};

Patterns RipplePatterns(const FaceRig& rig) {
  const Eigen::Matrix3Xd& p = rig.neutral.positions_mm;
  Patterns patterns;
  for (int k = 0; k < 4; ++k) {
    Eigen::Matrix3Xf field(3, rig.vertex_count());
    for (int v = 0; v < rig.vertex_count(); ++v) {
      const double ripple = std::sin(p(0, v) * (1.0 + 0.1 * k) + p(1, v) * 0.7 * k);
      const double step = p(0, v) > 0 ? 1.0 : -1.0;
      field.col(v) = Eigen::Vector3f(0.3f * step, static_cast<float>(ripple), 0.2f * k);
    }
    patterns.fields.push_back(field);
  }
  return patterns;
}

double MeanDistance(const Eigen::Matrix3Xf& a, const Eigen::Matrix3Xf& b) {
  return (a - b).colwise().norm().mean();
}

TEST(PropagationLearner, RecoversPatternsTheLaplacianCannotAndGeneralisesToNewMixtures) {
  const FaceRig& rig = Face();
  const auto laplacian = SamplePropagation::Build(rig).value();
  const Patterns patterns = RipplePatterns(rig);
  PropagationLearner learner(laplacian, rig.skin_samples);
  ASSERT_TRUE(learner.Add(patterns.Mix(60, 1), 0, 60).ok());
  EXPECT_EQ(learner.frame_count(), 60);
  const auto learned = learner.Fit();
  ASSERT_TRUE(learned.ok()) << learned.status().message();
  EXPECT_EQ(learned->method(), "learned");
  ASSERT_EQ(learned->vertex_count(), rig.vertex_count());

  // New mixtures (another seed), never seen in training.
  const PointCache test = patterns.Mix(20, 2);
  double laplacian_error = 0, learned_error = 0, magnitude = 0;
  Eigen::Matrix3Xf samples(3, laplacian.sample_count()), a(3, rig.vertex_count()),
      b(3, rig.vertex_count());
  for (int t = 0; t < test.frame_count(); ++t) {
    const auto truth = test.Frame(t);
    for (int i = 0; i < laplacian.sample_count(); ++i) {
      samples.col(i) = rig.skin_samples[i].Evaluate(truth).cast<float>();
    }
    laplacian.Apply(samples, a);
    learned->Apply(samples, b);
    laplacian_error += MeanDistance(a, truth);
    learned_error += MeanDistance(b, truth);
    magnitude += truth.colwise().norm().mean();
  }
  std::printf("ripples: Laplacian %.4f, learned %.4f, magnitude %.4f (mean per frame, mm)\n",
              laplacian_error / 20, learned_error / 20, magnitude / 20);
  EXPECT_GT(laplacian_error, 0.2 * magnitude);  // the case is hard for the Laplacian
  EXPECT_LT(learned_error, 0.01 * magnitude);
}

TEST(PropagationLearner, ReproducesLaplacianInterpolantsFromTheirSamples) {
  // Training fields that are the prior's own interpolants of random sample offsets: a data set
  // the prior already explains, so the learned map must reproduce the fields from their sample
  // values (the prior alone would not exactly, as its soft constraints do not interpolate).
  const FaceRig& rig = Face();
  const auto laplacian = SamplePropagation::Build(rig).value();
  std::mt19937_64 rng(3);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  PointCache cache;
  cache.vertex_count = rig.vertex_count();
  cache.positions.resize(3 * rig.vertex_count(), 30);
  for (int t = 0; t < 30; ++t) {
    Eigen::Matrix3Xf samples(3, laplacian.sample_count());
    for (int i = 0; i < samples.size(); ++i) samples.data()[i] = normal(rng);
    Eigen::Map<Eigen::Matrix3Xf> frame = cache.Frame(t);
    Eigen::Matrix3Xf vertices(3, rig.vertex_count());
    laplacian.Apply(samples, vertices);
    frame = vertices;
  }
  PropagationLearner learner(laplacian, rig.skin_samples);
  ASSERT_TRUE(learner.Add(cache, 0, 30).ok());
  const auto learned = learner.Fit().value();
  double worst = 0;
  for (int t = 0; t < 5; ++t) {
    const auto frame = cache.Frame(t);
    Eigen::Matrix3Xf samples(3, laplacian.sample_count());
    for (int i = 0; i < laplacian.sample_count(); ++i) {
      samples.col(i) = rig.skin_samples[i].Evaluate(frame).cast<float>();
    }
    Eigen::Matrix3Xf vertices(3, rig.vertex_count());
    learned.Apply(samples, vertices);
    worst = std::max(worst, static_cast<double>((vertices - frame).cwiseAbs().maxCoeff()));
  }
  EXPECT_LT(worst, 0.05);
}

TEST(PropagationLearner, BadInputIsAnErrorNamingIt) {
  const FaceRig& rig = Face();
  const auto laplacian = SamplePropagation::Build(rig).value();
  PropagationLearner learner(laplacian, rig.skin_samples);
  EXPECT_EQ(learner.Fit().status().code(), StatusCode::kFailedPrecondition);
  PointCache wrong;
  wrong.vertex_count = 10;
  wrong.positions = Eigen::MatrixXf::Zero(30, 4);
  EXPECT_THAT(learner.Add(wrong, 0, 4).message(), ::testing::HasSubstr("vertices"));
  PointCache right;
  right.vertex_count = rig.vertex_count();
  right.positions = Eigen::MatrixXf::Zero(3 * rig.vertex_count(), 4);
  EXPECT_THAT(learner.Add(right, 2, 9).message(), ::testing::HasSubstr("frame range"));
  PropagationLearnOptions options;
  options.prior_weight = 0;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("prior_weight"));
  EXPECT_FALSE(SamplePropagation::FromWeights(Eigen::MatrixXf(), "x").ok());
  Eigen::MatrixXf nan = Eigen::MatrixXf::Zero(4, 3);
  nan(1, 1) = std::nanf("");
  EXPECT_EQ(SamplePropagation::FromWeights(nan, "x").status().code(), StatusCode::kDataLoss);
}

TEST(SamplePropagation, RefusesARigWithoutSamples) {
  FaceRig rig = Face();
  rig.skin_samples.clear();
  EXPECT_EQ(SamplePropagation::Build(rig).status().code(), StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace facedyn::dynamics
