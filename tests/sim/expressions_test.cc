#include "sim/expressions.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "sim/ict_import.h"
#include "sim/procedural_face.h"
#include "tests/support/test_support.h"

namespace facedyn::sim {
namespace {

const FaceRig& Procedural() {
  static const FaceRig rig = [] {
    StatusOr<FaceRig> made = MakeProceduralFace(ProceduralFaceOptions{});
    FACEDYN_CHECK(made.ok(), made.status().ToString());
    return std::move(made).value();
  }();
  return rig;
}

double MeanRegionDelta(const FaceRig& rig, const Eigen::Matrix3Xd& delta, const std::string& region,
                       int axis) {
  double sum = 0;
  for (int v : rig.regions.at(region)) sum += delta(axis, v);
  return sum / rig.regions.at(region).size();
}

TEST(ExpressionNames, NeutralThenThePapersTen) {
  const auto names = ExpressionNames();
  ASSERT_EQ(names.size(), 11u);
  EXPECT_EQ(names[0], "neutral");
  for (size_t k = 0; k < 10; ++k) EXPECT_EQ(names[k + 1], kProceduralExpressions[k]);
}

TEST(ExpressionWeights, ProceduralNamesAreItsOwnShapes) {
  const FaceRig& rig = Procedural();
  auto neutral = ExpressionWeights(rig, "neutral");
  ASSERT_TRUE(neutral.ok());
  EXPECT_EQ(neutral->size(), 10);
  EXPECT_EQ(neutral->squaredNorm(), 0.0);
  for (const auto& name : ExpressionNames()) {
    if (name == "neutral") continue;
    auto w = ExpressionWeights(rig, name);
    ASSERT_TRUE(w.ok()) << name;
    EXPECT_EQ(w->sum(), 1.0) << name;
    EXPECT_EQ((*w)[rig.BlendshapeIndex(name)], 1.0) << name;
  }
}

TEST(ExpressionWeights, UnknownNameListsTheValidOnes) {
  auto w = ExpressionWeights(Procedural(), "frown");
  ASSERT_FALSE(w.ok());
  EXPECT_EQ(w.status().code(), StatusCode::kNotFound);
  for (const char* expected : {"frown", "neutral", "smile", "lips_parted"}) {
    EXPECT_NE(w.status().message().find(expected), std::string::npos) << w.status().message();
  }
}

TEST(ExpressionWeights, MissingArkitShapeIsNamed) {
  FaceRig rig;
  rig.name = "partial";
  rig.neutral.positions_mm = Eigen::Matrix3Xd::Zero(3, 3);
  rig.blendshape_names = {"jawOpen"};
  rig.blendshape_deltas_mm = {Eigen::Matrix3Xd::Zero(3, 3)};
  auto jaw = ExpressionWeights(rig, "jaw_open");
  ASSERT_TRUE(jaw.ok());
  EXPECT_EQ((*jaw)[0], 1.0);
  auto smile = ExpressionWeights(rig, "smile");
  ASSERT_FALSE(smile.ok());
  EXPECT_NE(smile.status().message().find("mouthSmile_L"), std::string::npos);
}

TEST(JawAngleRad, ProceduralIsJawOpenWeightTimesItsAngle) {
  const FaceRig& rig = Procedural();
  Eigen::VectorXd w = Eigen::VectorXd::Zero(10);
  EXPECT_EQ(JawAngleRad(rig, w), 0.0);
  w[rig.BlendshapeIndex("jaw_open")] = 0.5;
  w[rig.BlendshapeIndex("smile")] = 1.0;
  EXPECT_DOUBLE_EQ(JawAngleRad(rig, w), 0.5 * kProceduralJawOpenRad);
  EXPECT_DOUBLE_EQ(JawOpenAngleRad(rig), kProceduralJawOpenRad);
}

TEST(ExpressionWeights, IctCombinationsFormThePapersExpressions) {
  FACEDYN_REQUIRE_SHARED_ASSET(neutral, "ict-facekit/generic_neutral_mesh.obj");
  IctImportOptions options;
  options.dir = std::filesystem::path(neutral).parent_path().string();
  auto imported = ImportIctFaceKit(options);
  ASSERT_TRUE(imported.ok()) << imported.status().ToString();
  const FaceRig& rig = *imported;
  for (const auto& name : ExpressionNames()) {
    auto w = ExpressionWeights(rig, name);
    ASSERT_TRUE(w.ok()) << name << ": " << w.status().ToString();
    ASSERT_EQ(w->size(), 55);
    EXPECT_GE(w->minCoeff(), 0.0) << name;
    EXPECT_LE(w->maxCoeff(), 1.0) << name;
    const Eigen::Matrix3Xd delta = rig.Evaluate(*w) - rig.neutral.positions_mm;
    const double peak = delta.colwise().norm().maxCoeff();
    if (name == "neutral") {
      EXPECT_EQ(peak, 0.0);
    } else {
      EXPECT_GT(peak, 2.0) << name;
      EXPECT_LT(peak, 60.0) << name;
    }
  }
  const auto delta = [&](const std::string& name) {
    return Eigen::Matrix3Xd(rig.Evaluate(*ExpressionWeights(rig, name)) - rig.neutral.positions_mm);
  };
  EXPECT_GT(MeanRegionDelta(rig, delta("smile"), "mouth_corners", 1), 2.0);  // corners up
  EXPECT_LT(MeanRegionDelta(rig, delta("jaw_open"), "chin", 1), -10.0);      // chin down
  EXPECT_GT(MeanRegionDelta(rig, delta("pucker"), "lips", 2), 2.0);          // lips forward
  EXPECT_GT(MeanRegionDelta(rig, delta("brow_raise"), "brows", 1), 2.0);     // brows up
  EXPECT_LT(MeanRegionDelta(rig, delta("squeeze"), "brows", 1), -1.0);       // brows down
  EXPECT_LT(std::abs(MeanRegionDelta(rig, delta("jaw_open"), "forehead", 1)), 0.2);

  const double open = JawAngleRad(rig, *ExpressionWeights(rig, "jaw_open"));
  const double parted = JawAngleRad(rig, *ExpressionWeights(rig, "lips_parted"));
  EXPECT_GT(open, 0.2);
  EXPECT_LT(open, 0.45);
  EXPECT_GT(parted, 0.0);
  EXPECT_LT(parted, 0.1);
  EXPECT_EQ(JawAngleRad(rig, *ExpressionWeights(rig, "smile")), 0.0);

  auto blink = ExpressionWeights(rig, "eyeBlink_L");  // any blendshape by name
  ASSERT_TRUE(blink.ok());
  EXPECT_EQ((*blink)[rig.BlendshapeIndex("eyeBlink_L")], 1.0);
  auto unknown = ExpressionWeights(rig, "grin");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("mouthSmile_L"), std::string::npos);
}

}  // namespace
}  // namespace facedyn::sim
