#include "physics/twin_targeting.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "physics/skull_kinematics.h"
#include "tests/physics/shell_rig.h"

namespace facedyn::physics {
namespace {

// The shell with a second, sideways expression, so the fit has two weights to tell apart.
FaceRig TwoShapeShell() {
  FaceRig rig = MakeShellRig(10);
  Eigen::Matrix3Xd shear = Eigen::Matrix3Xd::Zero(3, rig.vertex_count());
  for (int v = 0; v < rig.vertex_count(); ++v) {
    const Eigen::Vector3d p = rig.neutral.positions_mm.col(v);
    shear(0, v) = 2.0 * std::exp(-((p.x() - 15) * (p.x() - 15) + p.y() * p.y()) / (25.0 * 25.0));
  }
  rig.blendshape_names.push_back("shear");
  rig.blendshape_deltas_mm.push_back(shear);
  return rig;
}

Eigen::Vector3d GravityChangeLyingBack(double degrees) {
  SkullKinematics kinematics;
  kinematics.world_from_skull =
      Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), -degrees * M_PI / 180);
  return kinematics.GravityInSkull() - kGravityInWorld;
}

// Plain least squares without the skull alignment (the defaults have both).
TargetingOptions LeastSquares() {
  TargetingOptions options;
  options.align_skull = false;
  options.robust_scale_mm = 0.0;
  return options;
}

struct Frame {
  std::vector<int> vertices;
  Eigen::Matrix3Xd positions;
};

// The held expression's equilibrium in `model` at every other vertex, with Gaussian noise.
Frame HeldFrame(SoftTissueModel& model, const Eigen::VectorXd& weights, const Eigen::Vector3d& dg,
                double noise_mm, int vertex_count) {
  Frame frame;
  for (int v = 0; v < vertex_count; v += 2) frame.vertices.push_back(v);
  EXPECT_TRUE(model.SetReference(weights, 0.0, model.options().max_step_s).ok());
  auto held = model.HeldSkinWithJacobian(dg, frame.vertices);
  EXPECT_TRUE(held.ok());
  frame.positions =
      Eigen::Map<const Eigen::Matrix3Xd>(held->skin_mm.data(), 3, frame.vertices.size());
  std::mt19937 rng(11);
  std::normal_distribution<double> normal(0.0, noise_mm);
  for (Eigen::Index i = 0; i < frame.positions.size(); ++i)
    frame.positions.data()[i] += normal(rng);
  return frame;
}

// Lying back by 50 degrees the flesh sags by millimetres; the blendshape fit can only explain that
// with wrong weights, the twin's fit (the same material here: the machinery, not the
// identification, is under test) finds the expression and leaves the noise.
TEST(TwinTargeting, TiltedHeldExpressionRecoversTheWeightsTheBlendshapeFitMisses) {
  const FaceRig rig = TwoShapeShell();
  auto created = SoftTissueModel::Create(rig, TissueOptions());
  ASSERT_TRUE(created.ok()) << created.status().message();
  SoftTissueModel& model = **created;
  const Eigen::VectorXd truth = (Eigen::VectorXd(2) << 0.55, 0.3).finished();
  const Eigen::Vector3d dg = GravityChangeLyingBack(50);
  const Frame frame = HeldFrame(model, truth, dg, 0.02, rig.vertex_count());

  auto fit = TargetHeldExpression(model, rig, frame.vertices, frame.positions, dg, LeastSquares());
  ASSERT_TRUE(fit.ok()) << fit.status().message();
  EXPECT_LT((fit->twin.weights - truth).cwiseAbs().maxCoeff(), 0.01);
  EXPECT_LT(fit->twin.rms_mm, 0.02 * std::sqrt(3.0) * 1.2);  // the noise's 3D RMS, and a margin
  EXPECT_GT(fit->blendshape.rms_mm, 5 * fit->twin.rms_mm);
  EXPECT_GT((fit->blendshape.weights - truth).cwiseAbs().maxCoeff(), 0.05);
  EXPECT_GE(fit->twin.iterations, 1);
  // The flesh: the blendshape fit's is its targets' (no sag); the twin's includes the sag.
  EXPECT_NE(fit->twin.flesh_volume_change, fit->blendshape.flesh_volume_change);
  EXPECT_LT(std::abs(fit->twin.flesh_volume_change), 0.05);
  // The defaults (robust loss, skull alignment) find the same expression on this clean frame.
  auto by_default = TargetHeldExpression(model, rig, frame.vertices, frame.positions, dg);
  ASSERT_TRUE(by_default.ok()) << by_default.status().message();
  EXPECT_LT((by_default->twin.weights - truth).cwiseAbs().maxCoeff(), 0.01);
  EXPECT_LT(by_default->twin.rms_mm, 0.02 * std::sqrt(3.0) * 1.2);
  EXPECT_LT(by_default->twin.skull_rotation_deg, 0.05);
  EXPECT_EQ(by_default->twin.outlier_markers, 0);
}

// The estimated skull pose of a tilted frame is off by a small rigid motion (its stable
// markers sag too). With align_skull both fits also fit that motion: the twin's then recovers
// the expression and leaves the noise; without, the misalignment stays in its residual.
TEST(TwinTargeting, AlignmentAbsorbsARigidErrorOfTheSkullPose) {
  const FaceRig rig = TwoShapeShell();
  auto created = SoftTissueModel::Create(rig, TissueOptions());
  ASSERT_TRUE(created.ok());
  SoftTissueModel& model = **created;
  const Eigen::VectorXd truth = (Eigen::VectorXd(2) << 0.55, 0.3).finished();
  const Eigen::Vector3d dg = GravityChangeLyingBack(50);
  Frame frame = HeldFrame(model, truth, dg, 0.02, rig.vertex_count());
  const Eigen::Vector3d pivot = frame.positions.rowwise().mean();
  const Eigen::Matrix3d tilt =
      Eigen::AngleAxisd(0.6 * M_PI / 180, Eigen::Vector3d(1, 2, 0).normalized()).toRotationMatrix();
  for (Eigen::Index i = 0; i < frame.positions.cols(); ++i)
    frame.positions.col(i) =
        tilt * (frame.positions.col(i) - pivot) + pivot + Eigen::Vector3d(0.2, -0.3, 0.1);

  TargetingOptions aligned = LeastSquares();
  aligned.align_skull = true;
  auto with = TargetHeldExpression(model, rig, frame.vertices, frame.positions, dg, aligned);
  auto without =
      TargetHeldExpression(model, rig, frame.vertices, frame.positions, dg, LeastSquares());
  ASSERT_TRUE(with.ok() && without.ok());
  EXPECT_LT((with->twin.weights - truth).cwiseAbs().maxCoeff(), 0.01);
  EXPECT_LT(with->twin.rms_mm, 0.02 * std::sqrt(3.0) * 1.2);
  EXPECT_NEAR(with->twin.skull_rotation_deg, 0.6, 0.05);
  EXPECT_NEAR(with->twin.skull_translation_mm, Eigen::Vector3d(0.2, -0.3, 0.1).norm(), 0.05);
  EXPECT_GT(without->twin.rms_mm, 3 * with->twin.rms_mm);
  EXPECT_EQ(without->twin.skull_rotation_deg, 0.0);
  // The blendshape fit aligned too is still short of the sag.
  EXPECT_GT(with->blendshape.rms_mm, 5 * with->twin.rms_mm);
  for (int i = 1; i < static_cast<int>(with->twin.cost_history.size()); ++i)
    EXPECT_LT(with->twin.cost_history[i], with->twin.cost_history[i - 1]);
}

// Gross marker errors (a mislabelled dot) pull a least-squares fit off the expression; with
// the Cauchy loss the twin's fit keeps it and counts them.
TEST(TwinTargeting, RobustLossIgnoresGrossMarkerErrors) {
  const FaceRig rig = TwoShapeShell();
  auto created = SoftTissueModel::Create(rig, TissueOptions());
  ASSERT_TRUE(created.ok());
  SoftTissueModel& model = **created;
  const Eigen::VectorXd truth = (Eigen::VectorXd(2) << 0.55, 0.3).finished();
  const Eigen::Vector3d dg = GravityChangeLyingBack(50);
  Frame frame = HeldFrame(model, truth, dg, 0.02, rig.vertex_count());
  // Four markers near the bulge's centre moved by 6 mm.
  int corrupted = 0;
  for (size_t i = 0; i < frame.vertices.size() && corrupted < 4; ++i) {
    const Eigen::Vector3d p = rig.neutral.positions_mm.col(frame.vertices[i]);
    if (std::hypot(p.x(), p.y()) < 20) {
      frame.positions.col(i) += Eigen::Vector3d(0, 4, -4.5);
      ++corrupted;
    }
  }
  ASSERT_EQ(corrupted, 4);
  TargetingOptions robust = LeastSquares();
  robust.robust_scale_mm = 0.5;
  auto with = TargetHeldExpression(model, rig, frame.vertices, frame.positions, dg, robust);
  auto without =
      TargetHeldExpression(model, rig, frame.vertices, frame.positions, dg, LeastSquares());
  ASSERT_TRUE(with.ok() && without.ok());
  const double robust_error = (with->twin.weights - truth).cwiseAbs().maxCoeff();
  EXPECT_LT(robust_error, 0.01);
  EXPECT_GT((without->twin.weights - truth).cwiseAbs().maxCoeff(), 3 * robust_error);
  EXPECT_EQ(with->twin.outlier_markers, 4);
  // The markers both fits hold: not the four, nor those where the blendshape fit misses the
  // sag by more than 3 scales (measured 10 of 61 dropped in all). On them the twin's residual is
  // the noise's; least squares compares every marker.
  const int markers = static_cast<int>(frame.vertices.size());
  EXPECT_LE(with->twin.common_inlier_markers, markers - with->twin.outlier_markers);
  EXPECT_GE(with->twin.common_inlier_markers,
            markers - with->twin.outlier_markers - with->blendshape.outlier_markers);
  EXPECT_GT(with->twin.common_inlier_markers, markers / 2);
  EXPECT_EQ(with->blendshape.common_inlier_markers, with->twin.common_inlier_markers);
  EXPECT_LT(with->twin.common_inlier_rms_mm, 0.02 * std::sqrt(3.0) * 1.2);
  EXPECT_GT(with->twin.rms_mm, 3 * with->twin.common_inlier_rms_mm);
  EXPECT_GT(with->blendshape.common_inlier_rms_mm, 5 * with->twin.common_inlier_rms_mm);
  EXPECT_EQ(without->twin.common_inlier_markers, markers);
  EXPECT_DOUBLE_EQ(without->twin.common_inlier_rms_mm, without->twin.rms_mm);
  EXPECT_DOUBLE_EQ(without->blendshape.common_inlier_rms_mm, without->blendshape.rms_mm);
  EXPECT_EQ(without->twin.outlier_markers, 0);  // not counted without a robust loss
  robust.robust_scale_mm = -1;
  auto refused = TargetHeldExpression(model, rig, frame.vertices, frame.positions, dg, robust);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("robust_scale_mm"), std::string::npos);
}

// Upright, the held equilibrium is the blendshape skin exactly: the two fits agree.
TEST(TwinTargeting, UprightTheTwinFitIsTheBlendshapeFit) {
  const FaceRig rig = TwoShapeShell();
  auto created = SoftTissueModel::Create(rig, TissueOptions());
  ASSERT_TRUE(created.ok());
  SoftTissueModel& model = **created;
  const Eigen::VectorXd truth = (Eigen::VectorXd(2) << 0.4, 0.7).finished();
  const Frame frame = HeldFrame(model, truth, Eigen::Vector3d::Zero(), 0.05, rig.vertex_count());
  // Least squares: both start from the same closed-form fit, which is already the optimum.
  auto fit = TargetHeldExpression(model, rig, frame.vertices, frame.positions,
                                  Eigen::Vector3d::Zero(), LeastSquares());
  ASSERT_TRUE(fit.ok()) << fit.status().message();
  EXPECT_LT((fit->twin.weights - fit->blendshape.weights).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_NEAR(fit->twin.rms_mm, fit->blendshape.rms_mm, 1e-6);
  EXPECT_NEAR(fit->twin.flesh_volume_change, fit->blendshape.flesh_volume_change, 1e-9);
  // The defaults iterate both fits (robust weights, alignment) to the solver's tolerance
  // (parameter_tolerance 1e-5 per step): they agree to that.
  fit = TargetHeldExpression(model, rig, frame.vertices, frame.positions, Eigen::Vector3d::Zero());
  ASSERT_TRUE(fit.ok()) << fit.status().message();
  EXPECT_LT((fit->twin.weights - fit->blendshape.weights).cwiseAbs().maxCoeff(), 1e-4);
  EXPECT_NEAR(fit->twin.rms_mm, fit->blendshape.rms_mm, 1e-4);
  EXPECT_NEAR(fit->twin.flesh_volume_change, fit->blendshape.flesh_volume_change, 1e-5);
  EXPECT_LT((fit->twin.weights - truth).cwiseAbs().maxCoeff(), 0.02);
}

TEST(TwinTargeting, RefusesBadInputByName) {
  const FaceRig rig = TwoShapeShell();
  auto created = SoftTissueModel::Create(rig, TissueOptions());
  ASSERT_TRUE(created.ok());
  SoftTissueModel& model = **created;
  const std::vector<int> vertices = {0, 1, 2};
  const Eigen::Matrix3Xd positions = rig.neutral.positions_mm.leftCols(3);
  const Eigen::Vector3d nan(std::nan(""), 0, 0);
  auto refused = TargetHeldExpression(model, rig, vertices, positions, nan);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("gravity"), std::string::npos);
  refused =
      TargetHeldExpression(model, rig, vertices, positions.leftCols(2), Eigen::Vector3d::Zero());
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("3 vertices"), std::string::npos)
      << refused.status().message();
  refused = TargetHeldExpression(model, rig, {0, 1, rig.vertex_count()}, positions,
                                 Eigen::Vector3d::Zero());
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("vertex"), std::string::npos);
  // A model of another face.
  const FaceRig other = MakeShellRig(10);
  refused = TargetHeldExpression(model, other, vertices, positions, Eigen::Vector3d::Zero());
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("blendshapes"), std::string::npos);
  TargetingOptions options;
  options.max_iterations = 0;
  refused = TargetHeldExpression(model, rig, vertices, positions, Eigen::Vector3d::Zero(), options);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("max_iterations"), std::string::npos);
}

}  // namespace
}  // namespace facedyn::physics
