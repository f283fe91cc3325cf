// Shape alignment with an anchor pose (FDLS 4.4.2, Eq. 5).
#include "solve/anchor.h"

#include <gtest/gtest.h>

#include <random>

#include "solve/marker_fit.h"
#include "tests/solve/solve_test_rig.h"
#include "tests/support/test_support.h"

namespace facedyn::solve {
namespace {

using testing::ProceduralPuppet;

// A shot whose mask sits 2 mm off and whose markers each carry a fixed offset (a slightly
// different face): the QP's weights are off; aligned on the neutral first frame they come back.
TEST(AlignToAnchor, NeutralAnchorRemovesAConstantMarkerOffset) {
  const Puppet& puppet = ProceduralPuppet();
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> normal(0.0, 0.4);
  Eigen::MatrixXd truth(puppet.channel_count(), 8);
  for (Eigen::Index i = 0; i < truth.size(); ++i) truth.data()[i] = unit(rng);
  truth.col(0).setZero();  // the neutral-ish anchor frame
  Eigen::VectorXd offset(3 * puppet.marker_count());
  for (int m = 0; m < puppet.marker_count(); ++m) {
    offset.segment<3>(3 * m) =
        Eigen::Vector3d(2.0, 0.0, 0.0) + Eigen::Vector3d(normal(rng), normal(rng), normal(rng));
  }
  const Eigen::MatrixXd markers =
      ((puppet.marker_basis_mm * truth).colwise() + puppet.StackedNeutral()).colwise() + offset;

  const Eigen::MatrixXd before = SolveMarkersQp(puppet, markers, nullptr, nullptr).value();
  EXPECT_GT((before - truth).cwiseAbs().maxCoeff(), 0.05);

  const Eigen::VectorXd offsets =
      AnchorOffsets(puppet, markers, 0, Eigen::VectorXd::Zero(puppet.channel_count())).value();
  EXPECT_EIGEN_NEAR(offsets, offset, 1e-9);
  const Eigen::MatrixXd aligned = AlignToAnchor(markers, offsets).value();
  const Eigen::MatrixXd after = SolveMarkersQp(puppet, aligned, nullptr, nullptr).value();
  EXPECT_EIGEN_NEAR(after, truth, 1e-6);
}

TEST(AlignToAnchor, AlphaWeightsTheOffsetPerFrame) {
  const Eigen::MatrixXd markers = Eigen::MatrixXd::Zero(3, 3);
  const Eigen::Vector3d offsets(1.0, 2.0, 3.0);
  const Eigen::MatrixXd aligned =
      AlignToAnchor(markers, offsets, Eigen::Vector3d(1.0, 0.5, 0.0)).value();
  EXPECT_EIGEN_NEAR(aligned.col(0), -offsets, 0.0);
  EXPECT_EIGEN_NEAR(aligned.col(1), -0.5 * offsets, 0.0);
  EXPECT_EIGEN_NEAR(aligned.col(2), Eigen::Vector3d::Zero(), 0.0);
}

TEST(AnchorOffsets, BadFrameAndSizesAreErrors) {
  const Puppet& puppet = ProceduralPuppet();
  const Eigen::MatrixXd markers = Eigen::MatrixXd::Zero(3 * puppet.marker_count(), 4);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(puppet.channel_count());
  StatusOr<Eigen::VectorXd> result = AnchorOffsets(puppet, markers, 4, zero);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find("frame 4 is outside 0..3"), std::string::npos);
  EXPECT_FALSE(AnchorOffsets(puppet, markers, 0, Eigen::VectorXd::Zero(3)).ok());
  EXPECT_FALSE(AlignToAnchor(markers, Eigen::VectorXd::Zero(5)).ok());
}

}  // namespace
}  // namespace facedyn::solve
