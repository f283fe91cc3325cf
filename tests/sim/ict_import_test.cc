#include "sim/ict_import.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "physics/face_anatomy.h"
#include "sim/expressions.h"
#include "tests/support/test_support.h"

namespace facedyn::sim {
namespace {

std::string IctDir(const std::string& neutral_path) {
  return std::filesystem::path(neutral_path).parent_path().string();
}

TEST(ParseIdentitySpec, ParsesNamesAndWeights) {
  auto parsed = ParseIdentitySpec("identity000:1.5, identity002:-0.5");
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  ASSERT_EQ(parsed->size(), 2u);
  EXPECT_EQ((*parsed)[0].first, "identity000");
  EXPECT_DOUBLE_EQ((*parsed)[0].second, 1.5);
  EXPECT_EQ((*parsed)[1].first, "identity002");
  EXPECT_DOUBLE_EQ((*parsed)[1].second, -0.5);
  auto empty = ParseIdentitySpec("");
  ASSERT_TRUE(empty.ok());
  EXPECT_TRUE(empty->empty());
}

TEST(ParseIdentitySpec, RejectsMalformedSpecs) {
  for (const char* spec :
       {"identity009:1", "identity000:abc", "foo", "identity000:1,identity000:2", "identity000:1,",
        "identity000:", "identity0:1", "identity000:1e9", "identity000:nan"}) {
    auto parsed = ParseIdentitySpec(spec);
    ASSERT_FALSE(parsed.ok()) << spec;
    EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidArgument) << spec;
    EXPECT_NE(parsed.status().message().find(spec), std::string::npos) << parsed.status().message();
  }
}

TEST(ImportIctFaceKit, MissingFolderIsNamed) {
  IctImportOptions options;
  options.dir = "/nonexistent/ict-facekit-here";
  auto rig = ImportIctFaceKit(options);
  ASSERT_FALSE(rig.ok());
  EXPECT_EQ(rig.status().code(), StatusCode::kNotFound);
  EXPECT_NE(rig.status().message().find("/nonexistent/ict-facekit-here"), std::string::npos);
  EXPECT_FALSE(ImportIctFaceKit(IctImportOptions{}).ok());  // no dir at all
}

TEST(ImportIctFaceKit, MissingNeutralMeshIsNamed) {
  testing::TempDir dir;
  IctImportOptions options;
  options.dir = dir.path();
  auto rig = ImportIctFaceKit(options);
  ASSERT_FALSE(rig.ok());
  EXPECT_NE(rig.status().message().find("generic_neutral_mesh.obj"), std::string::npos);
}

TEST(ImportIctFaceKit, TruncatedAndCorruptExpressionFilesAreNamed) {
  FACEDYN_REQUIRE_SHARED_ASSET(neutral, "ict-facekit/generic_neutral_mesh.obj");
  testing::TempDir dir;
  std::filesystem::copy_file(neutral, dir.Join("generic_neutral_mesh.obj"));
  const std::string jaw = testing::ReadBytes(IctDir(neutral) + "/jawOpen.obj");
  testing::WriteBytes(dir.Join("jawOpen.obj"), jaw.substr(0, jaw.size() / 5));
  IctImportOptions options;
  options.dir = dir.path();
  auto rig = ImportIctFaceKit(options);
  ASSERT_FALSE(rig.ok());
  EXPECT_NE(rig.status().message().find("jawOpen.obj"), std::string::npos)
      << rig.status().message();

  std::string corrupt = jaw;
  const size_t v = corrupt.find("\nv ");
  ASSERT_NE(v, std::string::npos);
  corrupt.replace(v + 3, 4, "abcd");
  testing::WriteBytes(dir.Join("jawOpen.obj"), corrupt);
  rig = ImportIctFaceKit(options);
  ASSERT_FALSE(rig.ok());
  EXPECT_EQ(rig.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(rig.status().message().find("jawOpen.obj:"), std::string::npos)
      << rig.status().message();

  options.identity_weights = {{"identity001", 1.0}};
  testing::WriteBytes(dir.Join("jawOpen.obj"), jaw);
  rig = ImportIctFaceKit(options);
  ASSERT_FALSE(rig.ok());
  EXPECT_NE(rig.status().message().find("identity001.obj"), std::string::npos)
      << rig.status().message();
}

TEST(ImportIctFaceKit, ImportsTheFaceRegionInMillimetres) {
  FACEDYN_REQUIRE_SHARED_ASSET(neutral, "ict-facekit/generic_neutral_mesh.obj");
  IctImportOptions options;
  options.dir = IctDir(neutral);
  const auto start = std::chrono::steady_clock::now();
  auto imported = ImportIctFaceKit(options);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(imported.ok()) << imported.status().ToString();
  const FaceRig& rig = *imported;
  std::printf("ICT import: %d vertices, %d faces, %zu blendshapes in %.2f s\n", rig.vertex_count(),
              rig.neutral.face_count(), rig.blendshape_names.size(), seconds);
  EXPECT_TRUE(rig.Validate().ok());
  EXPECT_EQ(rig.vertex_count(), kIctFaceVertexCount);
  EXPECT_GT(rig.neutral.face_count(), 9000);
  EXPECT_LE(rig.neutral.face_count(), 9230);
  ASSERT_TRUE(rig.neutral.has_uvs());
  EXPECT_GE(rig.neutral.uvs.minCoeff(), 0.0);
  EXPECT_LE(rig.neutral.uvs.maxCoeff(), 1.0);
  EXPECT_EQ(rig.blendshape_names.size(), 55u);
  for (const char* shape :
       {"jawOpen", "mouthSmile_L", "cheekPuff_R", "browInnerUp_L", "noseSneer_R"}) {
    EXPECT_GE(rig.BlendshapeIndex(shape), 0) << shape;
  }
  for (const auto& d : rig.blendshape_deltas_mm) EXPECT_TRUE(d.allFinite());

  // Millimetres: the face (temples, cheeks, forehead) is 120-180 mm wide, eyes ~60-70 mm apart.
  double min_x = 1e9, max_x = -1e9;
  for (const char* region : {"temples", "cheeks", "forehead"}) {
    for (int v : rig.regions.at(region)) {
      min_x = std::min(min_x, rig.neutral.positions_mm(0, v));
      max_x = std::max(max_x, rig.neutral.positions_mm(0, v));
    }
  }
  std::printf("face width %.1f mm\n", max_x - min_x);
  EXPECT_GT(max_x - min_x, 120.0);
  EXPECT_LT(max_x - min_x, 180.0);

  // Skull frame: +Y up, face toward +Z, origin near the centre of the head.
  Eigen::Index tip;
  rig.neutral.positions_mm.row(2).maxCoeff(&tip);
  const Eigen::Vector3d nose = rig.neutral.positions_mm.col(tip);
  std::printf("nose tip (%.1f, %.1f, %.1f) mm\n", nose.x(), nose.y(), nose.z());
  EXPECT_LT(std::abs(nose.x()), 5.0);
  EXPECT_GT(nose.z(), 80.0);
  EXPECT_LT(nose.z(), 140.0);
  EXPECT_LT(nose.y(), 0.0);
  EXPECT_GT(nose.y(), -50.0);
  for (const auto& [name, vertices] : rig.regions) EXPECT_FALSE(vertices.empty()) << name;
  double forehead_y = 0, chin_y = 0;
  for (int v : rig.regions.at("forehead"))
    forehead_y += rig.neutral.positions_mm(1, v) / rig.regions.at("forehead").size();
  for (int v : rig.regions.at("chin"))
    chin_y += rig.neutral.positions_mm(1, v) / rig.regions.at("chin").size();
  EXPECT_GT(forehead_y, 40.0);
  EXPECT_LT(chin_y, -60.0);

  // Jaw: hinge in front of the ears, jawOpen a ~0.3 rad rotation.
  const Eigen::Vector3d pivot = rig.jaw.pivot_in_skull;
  std::printf("jaw pivot (%.1f, %.1f, %.1f) mm, jawOpen %.3f rad\n", pivot.x(), pivot.y(),
              pivot.z(), JawOpenAngleRad(rig));
  EXPECT_GT(pivot.y(), -40.0);
  EXPECT_LT(pivot.y(), 10.0);
  EXPECT_GT(pivot.z(), -20.0);
  EXPECT_LT(pivot.z(), 40.0);
  EXPECT_GT(JawOpenAngleRad(rig), 0.2);
  EXPECT_LT(JawOpenAngleRad(rig), 0.45);

  // Anatomy.
  EXPECT_EQ(rig.skull.vertex_count(), rig.vertex_count());
  EXPECT_EQ(rig.skull_landmarks.size(), 5u);
  EXPECT_EQ(rig.skin_samples.size(), 344u);
  EXPECT_EQ(rig.markers.size(), 150u);
  const Eigen::VectorXd t = physics::TissueThicknessMm(rig);
  const std::vector<double> border = physics::ThicknessBorderDistanceMm(rig);
  for (const auto& [region, range] : physics::RegionThicknessRanges()) {
    for (int v : rig.regions.at(region)) {
      if (border[v] < physics::kThicknessBlendMm) continue;
      EXPECT_GE(t[v], range.min_mm - 1e-9) << region;
      EXPECT_LE(t[v], range.max_mm + 1e-9) << region;
    }
  }

  // An identity moves the neutral but not the expression deltas.
  options.identity_weights = {{"identity000", 1.5}};
  auto other = ImportIctFaceKit(options);
  ASSERT_TRUE(other.ok()) << other.status().ToString();
  const double moved =
      (other->neutral.positions_mm - rig.neutral.positions_mm).colwise().norm().maxCoeff();
  std::printf("identity000:1.5 moves the neutral by up to %.1f mm\n", moved);
  EXPECT_GT(moved, 2.0);
  EXPECT_NE(other->name, rig.name);
  const int jaw = rig.BlendshapeIndex("jawOpen");
  EXPECT_EQ(other->blendshape_deltas_mm[jaw], rig.blendshape_deltas_mm[jaw]);
}

}  // namespace
}  // namespace facedyn::sim
