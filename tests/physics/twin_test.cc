// The pieces of the twin fit that need no simulation (physics/twin.h): the held expression's
// blendshape fit, the mandible angle from the rig's geometry, and the stiffness groups.

#include "physics/twin.h"

#include <gtest/gtest.h>

#include "sim/procedural_face.h"

namespace facedyn::physics {
namespace {

const FaceRig& Face() {
  static const FaceRig* rig =
      new FaceRig(sim::MakeProceduralFace(sim::ProceduralFaceOptions()).value());
  return *rig;
}

std::vector<int> SomeVertices(const FaceRig& rig) {
  std::vector<int> vertices;
  for (const Marker& marker : rig.markers) vertices.push_back(marker.point.vertices[0]);
  return vertices;
}

Eigen::Matrix3Xd SkinAt(const FaceRig& rig, const Eigen::VectorXd& weights,
                        const std::vector<int>& vertices) {
  Eigen::Matrix3Xd points(3, vertices.size());
  for (size_t i = 0; i < vertices.size(); ++i) {
    Eigen::Vector3d p = rig.neutral.positions_mm.col(vertices[i]);
    for (int k = 0; k < weights.size(); ++k)
      p += weights[k] * rig.blendshape_deltas_mm[k].col(vertices[i]);
    points.col(i) = p;
  }
  return points;
}

TEST(FitBlendshapeWeights, RecoversAHeldExpressionAndRespectsTheBounds) {
  const FaceRig& rig = Face();
  const std::vector<int> vertices = SomeVertices(rig);
  Eigen::VectorXd truth =
      Eigen::VectorXd::Zero(static_cast<Eigen::Index>(rig.blendshape_names.size()));
  truth[rig.BlendshapeIndex("smile")] = 0.3;
  truth[rig.BlendshapeIndex("jaw_open")] = 0.6;
  auto fit = FitBlendshapeWeights(rig, vertices, SkinAt(rig, truth, vertices));
  ASSERT_TRUE(fit.ok()) << fit.status().message();
  EXPECT_LT((fit->weights - truth).cwiseAbs().maxCoeff(), 1e-4);
  EXPECT_LT(fit->rms_mm, 1e-3);

  // Over-driven past 1: the weight stops at its bound and the rest is residual.
  Eigen::VectorXd over = truth;
  over[rig.BlendshapeIndex("smile")] = 1.4;
  fit = FitBlendshapeWeights(rig, vertices, SkinAt(rig, over, vertices));
  ASSERT_TRUE(fit.ok());
  EXPECT_LE(fit->weights.maxCoeff(), 1.0 + 1e-9);
  EXPECT_GE(fit->weights.minCoeff(), -1e-9);
  EXPECT_GT(fit->rms_mm, 0.01);

  EXPECT_FALSE(FitBlendshapeWeights(rig, {0, 1}, Eigen::Matrix3Xd::Zero(3, 3)).ok());
  auto bad = FitBlendshapeWeights(rig, {-4}, Eigen::Matrix3Xd::Zero(3, 1));
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("vertex -4"), std::string::npos) << bad.status().message();
}

// The hinge fitted to the procedural jaw-opening shape: the generator rotates the jaw region by
// kProceduralJawOpenRad, blended toward the lips, so the fit over the rigid part comes close.
TEST(FittedJawOpenAngleRad, ComesCloseToTheProceduralRotation) {
  const double fitted = FittedJawOpenAngleRad(Face());
  EXPECT_NEAR(fitted, sim::kProceduralJawOpenRad, 0.2 * sim::kProceduralJawOpenRad);
  Eigen::VectorXd weights =
      Eigen::VectorXd::Zero(static_cast<Eigen::Index>(Face().blendshape_names.size()));
  weights[Face().BlendshapeIndex("jaw_open")] = 0.5;
  EXPECT_DOUBLE_EQ(FittedJawAngleRad(Face(), weights), 0.5 * fitted);
}

TEST(TetStiffnessGroups, DefaultGroupsCoverTheTissueAndBadGroupsAreNamed) {
  auto model = SoftTissueModel::Create(Face(), TissueOptions());
  ASSERT_TRUE(model.ok());
  const TetShell& shell = (*model)->shell();
  auto groups = TetStiffnessGroups(Face(), shell, DefaultStiffnessGroups());
  ASSERT_TRUE(groups.ok()) << groups.status().message();
  ASSERT_EQ(groups->size(), shell.tets.cols());
  for (int g = 0; g < 3; ++g) EXPECT_GT((groups->array() == g).count(), 100) << g;

  auto error = TetStiffnessGroups(Face(), shell, {{"a", {"nosuch"}}, {"rest", {}}});
  ASSERT_FALSE(error.ok());
  EXPECT_NE(error.status().message().find("no region 'nosuch'"), std::string::npos);
  error = TetStiffnessGroups(Face(), shell, {{"a", {}}, {"b", {}}});
  ASSERT_FALSE(error.ok());
  EXPECT_NE(error.status().message().find("both have no regions"), std::string::npos);
  error = TetStiffnessGroups(Face(), shell, {{"a", {"cheeks"}}, {"b", {"cheeks"}}, {"rest", {}}});
  ASSERT_FALSE(error.ok());
  EXPECT_NE(error.status().message().find("share region vertices"), std::string::npos);
  error = TetStiffnessGroups(Face(), shell, {{"cheeks", {"cheeks"}}});
  ASSERT_FALSE(error.ok());
  EXPECT_NE(error.status().message().find("in no group"), std::string::npos);
}

TEST(FitTwin, RefusesTakesThatCannotIdentifyTheMaterial) {
  Take still;
  still.info.fps = 64;
  auto refused = FitTwin(Face(), {{"still-take", &still}}, TwinFitOptions());
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("still-take has no platform frequency"),
            std::string::npos)
      << refused.status().message();
  EXPECT_FALSE(FitTwin(Face(), {}, TwinFitOptions()).ok());
  TwinFitOptions bad;
  bad.prior.damping_ratio = -1;
  EXPECT_FALSE(FitTwin(Face(), {{"x", &still}}, bad).ok());
}

}  // namespace
}  // namespace facedyn::physics
