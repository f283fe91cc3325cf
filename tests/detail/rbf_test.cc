#include "detail/rbf.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace facedyn::detail {
namespace {

Eigen::MatrixXd RandomMatrix(int rows, int cols, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::MatrixXd m(rows, cols);
  for (int j = 0; j < cols; ++j) {
    for (int i = 0; i < rows; ++i) m(i, j) = u(rng);
  }
  return m;
}

TEST(BiharmonicRbf, InterpolatesCentresExactly) {
  const Eigen::MatrixXd centres = RandomMatrix(4, 30, 1);
  const Eigen::MatrixXd values = RandomMatrix(30, 5, 2);
  for (RbfPolynomial poly : {RbfPolynomial::kConstant, RbfPolynomial::kLinear}) {
    StatusOr<BiharmonicRbf> rbf = BiharmonicRbf::Fit(centres, values, poly);
    ASSERT_TRUE(rbf.ok()) << rbf.status().ToString();
    EXPECT_EQ(rbf->linear(), poly == RbfPolynomial::kLinear);
    Eigen::VectorXd out(5);
    for (int j = 0; j < 30; ++j) {
      rbf->Evaluate(centres.col(j), out);
      EXPECT_LT((out - values.row(j).transpose()).norm(), 1e-10) << "centre " << j;
    }
  }
}

TEST(BiharmonicRbf, LinearPartReproducesAffineFunctionsEverywhere) {
  // With the linear part, an affine function is interpolated by the polynomial alone (kernel
  // coefficients zero), so it is exact away from the centres too.
  const Eigen::MatrixXd centres = RandomMatrix(3, 20, 3);
  const Eigen::Matrix<double, 2, 3> a = RandomMatrix(2, 3, 4);
  const Eigen::Vector2d b(0.5, -2.0);
  Eigen::MatrixXd values(20, 2);
  for (int j = 0; j < 20; ++j) values.row(j) = (a * centres.col(j) + b).transpose();
  StatusOr<BiharmonicRbf> rbf = BiharmonicRbf::Fit(centres, values, RbfPolynomial::kLinear);
  ASSERT_TRUE(rbf.ok()) << rbf.status().ToString();
  const Eigen::MatrixXd queries = RandomMatrix(3, 10, 5);
  Eigen::VectorXd out(2);
  for (int q = 0; q < 10; ++q) {
    rbf->Evaluate(queries.col(q), out);
    EXPECT_LT((out - (a * queries.col(q) + b)).norm(), 1e-9);
  }
  // The constant part alone does not: the same data away from the centres is off.
  StatusOr<BiharmonicRbf> constant = BiharmonicRbf::Fit(centres, values, RbfPolynomial::kConstant);
  ASSERT_TRUE(constant.ok());
  constant->Evaluate(Eigen::Vector3d(3.0, 3.0, 3.0), out);
  EXPECT_GT((out - (a * Eigen::Vector3d(3.0, 3.0, 3.0) + b)).norm(), 1e-3);
}

TEST(BiharmonicRbf, CompressedOutputsAreExactOnLowRankValues) {
  // Values of rank 2 spread over 60 outputs: two directions hold all their energy, so the
  // compressed interpolant stores 2 coefficient columns plus a 2 x 60 basis and still
  // interpolates the centres, and agrees with the uncompressed one away from them.
  const Eigen::MatrixXd centres = RandomMatrix(9, 40, 11);
  const Eigen::MatrixXd values = RandomMatrix(40, 2, 12) * RandomMatrix(2, 60, 13);
  StatusOr<BiharmonicRbf> full = BiharmonicRbf::Fit(centres, values);
  ASSERT_TRUE(full.ok()) << full.status().ToString();
  BiharmonicRbf compressed = *full;
  ASSERT_TRUE(compressed.CompressOutputs(values, 0.999).ok());
  EXPECT_EQ(compressed.output_basis().rows(), 2);
  EXPECT_EQ(compressed.outputs(), 60);
  EXPECT_EQ(compressed.coefficients().cols(), 2);
  const Eigen::MatrixXd gram = compressed.output_basis() * compressed.output_basis().transpose();
  EXPECT_LT((gram - Eigen::MatrixXd::Identity(2, 2)).norm(), 1e-10);  // orthonormal rows
  EXPECT_LT(compressed.MemoryBytes(), full->MemoryBytes());
  EXPECT_LT(compressed.coefficients().size() + compressed.output_basis().size(),
            full->coefficients().size() / 10);
  Eigen::VectorXd out(60), reference(60);
  for (int j = 0; j < 40; ++j) {
    compressed.Evaluate(centres.col(j), out);
    EXPECT_LT((out - values.row(j).transpose()).norm(), 1e-9) << "centre " << j;
  }
  const Eigen::MatrixXd probes = RandomMatrix(9, 5, 14);
  for (int j = 0; j < 5; ++j) {
    compressed.Evaluate(probes.col(j), out);
    full->Evaluate(probes.col(j), reference);
    EXPECT_LT((out - reference).norm(), 1e-9 * (1.0 + reference.norm())) << "probe " << j;
  }
  // A stored compressed RBF comes back the same.
  StatusOr<BiharmonicRbf> loaded =
      BiharmonicRbf::FromParts(compressed.centres(), compressed.coefficients(), compressed.linear(),
                               compressed.output_basis());
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  loaded->Evaluate(probes.col(0), reference);
  compressed.Evaluate(probes.col(0), out);
  EXPECT_EQ((out - reference).norm(), 0.0);
}

TEST(BiharmonicRbf, CompressionKeepsTheAskedEnergy) {
  // Full-rank values: the kept directions hold at least the asked fraction of the squared
  // singular values, so the error at the centres is at most sqrt(1 - energy) of the values'
  // norm, and fewer are kept for less energy.
  const Eigen::MatrixXd centres = RandomMatrix(9, 30, 21);
  Eigen::MatrixXd values = RandomMatrix(30, 45, 22);
  for (int c = 0; c < 45; ++c) values.col(c) *= std::pow(0.8, c);  // a decaying spectrum
  StatusOr<BiharmonicRbf> full = BiharmonicRbf::Fit(centres, values);
  ASSERT_TRUE(full.ok());
  int previous_k = 1000;
  for (double energy : {0.9999, 0.99, 0.9}) {
    BiharmonicRbf rbf = *full;
    ASSERT_TRUE(rbf.CompressOutputs(values, energy).ok());
    const int k = static_cast<int>(rbf.output_basis().rows());
    EXPECT_LT(k, previous_k) << energy;
    previous_k = k;
    Eigen::MatrixXd at_centres(30, 45);
    Eigen::VectorXd out(45);
    for (int j = 0; j < 30; ++j) {
      rbf.Evaluate(centres.col(j), out);
      at_centres.row(j) = out.transpose();
    }
    EXPECT_LE((at_centres - values).norm(), std::sqrt(1.0 - energy) * values.norm() * (1 + 1e-9))
        << energy;
  }
  BiharmonicRbf rbf = *full;
  EXPECT_FALSE(rbf.CompressOutputs(values, 0.0).ok());
  EXPECT_FALSE(rbf.CompressOutputs(values, 1.5).ok());
  EXPECT_FALSE(rbf.CompressOutputs(values.leftCols(3), 0.9).ok());
  EXPECT_FALSE(BiharmonicRbf::FromParts(full->centres(), full->coefficients(), full->linear(),
                                        Eigen::MatrixXd::Zero(3, 45))
                   .ok());
}

TEST(BiharmonicRbf, RepeatedCentreIsDroppedNotSingular) {
  Eigen::MatrixXd centres = RandomMatrix(2, 6, 6);
  centres.col(5) = centres.col(1);
  const Eigen::MatrixXd values = RandomMatrix(6, 1, 7);
  StatusOr<BiharmonicRbf> rbf = BiharmonicRbf::Fit(centres, values, RbfPolynomial::kConstant);
  ASSERT_TRUE(rbf.ok()) << rbf.status().ToString();
  EXPECT_EQ(rbf->centre_count(), 5);
}

TEST(BiharmonicRbf, BadInputNamed) {
  StatusOr<BiharmonicRbf> rbf = BiharmonicRbf::Fit(RandomMatrix(2, 6, 1), RandomMatrix(5, 1, 2));
  ASSERT_FALSE(rbf.ok());
  EXPECT_EQ(rbf.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(rbf.status().message(), ::testing::HasSubstr("6 centres but 5 value rows"));
  Eigen::MatrixXd nan = RandomMatrix(2, 3, 3);
  nan(1, 1) = std::nan("");
  EXPECT_FALSE(BiharmonicRbf::Fit(nan, RandomMatrix(3, 1, 2)).ok());
  EXPECT_EQ(
      BiharmonicRbf::FromParts(RandomMatrix(2, 3, 1), RandomMatrix(5, 1, 1), true).status().code(),
      StatusCode::kDataLoss);
}

TEST(GreedySelectFrames, StartsWithLargestAndSkipsRepeatedFrames) {
  // Frames 5..9 repeat 0..4 (same pose, same values): once 0..4 are in, nothing is left to fix.
  Eigen::MatrixXd features = RandomMatrix(3, 10, 8);
  Eigen::MatrixXd y = RandomMatrix(10, 40, 9);
  features.rightCols(5) = features.leftCols(5);
  y.bottomRows(5) = y.topRows(5);
  y.row(3) *= 10.0;
  y.row(8) = y.row(3);
  const std::vector<int> chosen = GreedySelectFrames(features, y * y.transpose(), 10);
  ASSERT_EQ(chosen.size(), 5u);
  EXPECT_TRUE(chosen[0] == 3 || chosen[0] == 8);
  std::vector<int> poses;
  for (int c : chosen) poses.push_back(c % 5);
  std::sort(poses.begin(), poses.end());
  EXPECT_EQ(poses, (std::vector<int>{0, 1, 2, 3, 4}));
}

TEST(GreedySelectFrames, PicksWorstReconstructedFrame) {
  // 1-D pose on a line, values = a spike at 0.5 on a shallow ramp: the spike is the largest
  // frame; with it alone the interpolant is its constant value, worst at the ramp's low end.
  const int n = 11;
  Eigen::MatrixXd features(1, n), y(n, 1);
  for (int j = 0; j < n; ++j) {
    features(0, j) = j / 10.0;
    y(j, 0) = (j == 5 ? 1.0 : 0.0) + 0.01 * j;
  }
  const std::vector<int> chosen = GreedySelectFrames(features, y * y.transpose(), 2);
  ASSERT_EQ(chosen.size(), 2u);
  EXPECT_EQ(chosen[0], 5);
  EXPECT_EQ(chosen[1], 0);
}

TEST(GreedySelectFrames, MatchesExplicitRefitting) {
  // The Gram-matrix shortcut must pick what refitting the interpolant and measuring every
  // frame's error directly would pick.
  const int n = 25;
  const Eigen::MatrixXd features = RandomMatrix(3, n, 11);
  Eigen::MatrixXd y(n, 12);
  for (int j = 0; j < n; ++j) {
    for (int c = 0; c < 12; ++c)
      y(j, c) = std::sin((c + 1) * features(0, j)) + features(1, j) * features(2, j) * c;
  }
  const std::vector<int> chosen = GreedySelectFrames(features, y * y.transpose(), 8);
  ASSERT_EQ(chosen.size(), 8u);
  for (int step = 1; step < 8; ++step) {
    Eigen::MatrixXd c(3, step), v(step, 12);
    for (int i = 0; i < step; ++i) {
      c.col(i) = features.col(chosen[i]);
      v.row(i) = y.row(chosen[i]);
    }
    StatusOr<BiharmonicRbf> rbf = BiharmonicRbf::Fit(c, v, RbfPolynomial::kConstant);
    ASSERT_TRUE(rbf.ok());
    int worst = -1;
    double worst_error = -1;
    Eigen::VectorXd out(12);
    for (int j = 0; j < n; ++j) {
      if (std::find(chosen.begin(), chosen.begin() + step, j) != chosen.begin() + step) continue;
      rbf->Evaluate(features.col(j), out);
      const double e = (out - y.row(j).transpose()).squaredNorm();
      if (e > worst_error) {
        worst_error = e;
        worst = j;
      }
    }
    EXPECT_EQ(chosen[step], worst) << "step " << step;
  }
}

}  // namespace
}  // namespace facedyn::detail
