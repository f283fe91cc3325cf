// FaceRig: evaluation of blendshapes and skin samples, the folder round trip, and the errors
// a hand-edited or corrupted rig folder produces.
#include "core/face_rig.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include "core/json_io.h"
#include "core/pc2.h"
#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::ReadBytes;
using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::AllOf;
using ::testing::HasSubstr;

constexpr int kColumns = 5;
constexpr int kRows = 4;  // 20 skin vertices

Mesh MakeSkin() {
  Mesh mesh;
  mesh.positions_mm.resize(3, kColumns * kRows);
  mesh.uvs.resize(2, kColumns * kRows);
  for (int j = 0; j < kRows; ++j) {
    for (int i = 0; i < kColumns; ++i) {
      const int v = j * kColumns + i;
      mesh.positions_mm.col(v) << 12.5 * i - 25.0, 15.0 * j - 22.5, 90.0 - 0.5 * i * j;
      mesh.uvs.col(v) << i / double(kColumns - 1), j / double(kRows - 1);
    }
  }
  for (int j = 0; j + 1 < kRows; ++j) {
    for (int i = 0; i + 1 < kColumns; ++i) {
      const int a = j * kColumns + i, b = a + 1, c = a + kColumns + 1, d = a + kColumns;
      mesh.AddFace({a, b, c, d}, {a, b, c, d});
    }
  }
  return mesh;
}

// A closed octahedron standing in for the skull surface (no uvs).
Mesh MakeSkull() {
  Mesh mesh;
  mesh.positions_mm.resize(3, 6);
  mesh.positions_mm << 60, -60, 0, 0, 0, 0,  //
      0, 0, 70, -70, 0, 0,                   //
      0, 0, 0, 0, 80, -80;
  const int faces[8][3] = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4},
                           {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  for (const auto& f : faces) mesh.AddFace({f[0], f[1], f[2]});
  return mesh;
}

FaceRig MakeRig() {
  FaceRig rig;
  rig.name = "grid_subject";
  rig.neutral = MakeSkin();
  const int v_count = rig.neutral.vertex_count();
  rig.blendshape_names = {"smile", "jaw_open"};
  Eigen::Matrix3Xd smile = Eigen::Matrix3Xd::Zero(3, v_count);
  Eigen::Matrix3Xd jaw_open = Eigen::Matrix3Xd::Zero(3, v_count);
  for (int v = 0; v < v_count; ++v) {
    smile.col(v) << 0.25 * (v % kColumns) - 0.5, 0.125 * (v / kColumns), 0.0;
    if (v < kColumns) jaw_open.col(v) << 0.0, -8.0, -1.5;  // bottom row drops
  }
  rig.blendshape_deltas_mm = {smile, jaw_open};
  rig.skull = MakeSkull();
  const char* landmark_names[5] = {"b1", "b2", "b3", "b4", "b5"};
  const double landmark_xyz[5][3] = {
      {0, 60, 70}, {-45, 40, 30}, {45, 40, 30}, {-50, -10, 10}, {50, -10, 10}};
  for (int i = 0; i < 5; ++i) {
    rig.skull_landmarks.push_back(
        {landmark_names[i],
         Eigen::Vector3d(landmark_xyz[i][0], landmark_xyz[i][1], landmark_xyz[i][2])});
  }
  rig.skin_samples = {SurfacePoint::AtVertex(0), SurfacePoint{{1, 2, 7}, {0.2, 0.3, 0.5}},
                      SurfacePoint{{12, 13, 18}, {1.0 / 3, 1.0 / 3, 1.0 / 3}},
                      SurfacePoint{{19, 18, 14}, {0.0, 0.75, 0.25}}};
  rig.markers = {{"brow_l", SurfacePoint{{15, 16, 11}, {0.5, 0.25, 0.25}}, 2.5},
                 {"chin", SurfacePoint::AtVertex(2), 3.0}};
  rig.regions = {
      {"forehead", {15, 16, 17, 18, 19}}, {"nose_bridge", {12, 17}}, {"jaw", {0, 1, 2, 3, 4, 5}}};
  rig.stable_regions = {"forehead", "nose_bridge"};
  rig.jaw.pivot_in_skull = Eigen::Vector3d(0, -30, 20);
  rig.jaw.axis_in_skull = Eigen::Vector3d(1, 0, 0);
  rig.jaw.region = "jaw";
  return rig;
}

void SaveGoodRig(const std::string& dir) {
  const Status saved = SaveFaceRig(MakeRig(), dir);
  ASSERT_TRUE(saved.ok()) << saved.message();
  const auto loaded = LoadFaceRig(dir);
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
}

Status LoadError(const std::string& dir) {
  const auto loaded = LoadFaceRig(dir);
  EXPECT_FALSE(loaded.ok()) << "LoadFaceRig(" << dir << ") should have failed";
  return loaded.ok() ? Status::Ok() : loaded.status();
}

// Replaces 1-based line `line` of a text file.
void ReplaceLine(const std::string& path, int line, const std::string& text) {
  std::istringstream in(ReadBytes(path));
  std::string out, current;
  int n = 0;
  while (std::getline(in, current)) out += (++n == line ? text : current) + "\n";
  ASSERT_GE(n, line) << path;
  WriteBytes(path, out);
}

void EditJson(const std::string& path, const std::function<void(Json*)>& edit) {
  Json json = Json::parse(ReadBytes(path));
  edit(&json);
  WriteBytes(path, json.dump(2) + "\n");
}

TEST(FaceRigValidate, AcceptsTheTestRig) {
  const Status status = MakeRig().Validate();
  EXPECT_TRUE(status.ok()) << status.message();
}

TEST(FaceRigEvaluate, AddsWeightedDeltasToTheNeutral) {
  const FaceRig rig = MakeRig();
  EXPECT_EIGEN_NEAR(rig.Evaluate(Eigen::Vector2d(0, 0)), rig.neutral.positions_mm, 0.0);
  const Eigen::Vector2d weights(0.5, -0.25);
  const Eigen::Matrix3Xd shaped = rig.Evaluate(weights);
  ASSERT_EQ(shaped.cols(), 20);
  for (int v = 0; v < 20; ++v) {
    const Eigen::Vector3d expected = rig.neutral.positions_mm.col(v) +
                                     0.5 * rig.blendshape_deltas_mm[0].col(v) -
                                     0.25 * rig.blendshape_deltas_mm[1].col(v);
    EXPECT_EIGEN_NEAR(shaped.col(v), expected, 1e-12);
  }
  // Bottom-row vertex 2 with jaw_open = 1: y drops by 8 mm, z by 1.5 mm.
  const Eigen::Matrix3Xd open = rig.Evaluate(Eigen::Vector2d(0, 1));
  EXPECT_EIGEN_NEAR(open.col(2),
                    (rig.neutral.positions_mm.col(2) + Eigen::Vector3d(0, -8, -1.5)).eval(), 1e-12);
  EXPECT_EIGEN_NEAR(open.col(12), rig.neutral.positions_mm.col(12), 0.0);
}

TEST(FaceRigBlendshapeIndex, FindsNames) {
  const FaceRig rig = MakeRig();
  EXPECT_EQ(rig.BlendshapeIndex("smile"), 0);
  EXPECT_EQ(rig.BlendshapeIndex("jaw_open"), 1);
  EXPECT_EQ(rig.BlendshapeIndex("frown"), -1);
}

TEST(FaceRigSamplePositions, BarycentricCombinations) {
  const FaceRig rig = MakeRig();
  const Eigen::Matrix3Xd& x = rig.neutral.positions_mm;
  const Eigen::Matrix3Xd samples = rig.SamplePositions(x);
  ASSERT_EQ(samples.cols(), 4);
  EXPECT_EIGEN_NEAR(samples.col(0), x.col(0), 0.0);
  EXPECT_EIGEN_NEAR(samples.col(1), (0.2 * x.col(1) + 0.3 * x.col(2) + 0.5 * x.col(7)).eval(),
                    1e-12);
  EXPECT_EIGEN_NEAR(samples.col(2), ((x.col(12) + x.col(13) + x.col(18)) / 3.0).eval(), 1e-12);
  EXPECT_EIGEN_NEAR(samples.col(3), (0.75 * x.col(18) + 0.25 * x.col(14)).eval(), 1e-12);
  // Samples follow the skin: on a rigidly translated skin they translate too.
  const Eigen::Matrix3Xd moved = x.colwise() + Eigen::Vector3d(1, 2, 3);
  EXPECT_EIGEN_NEAR(rig.SamplePositions(moved),
                    (samples.colwise() + Eigen::Vector3d(1, 2, 3)).eval(), 1e-12);
}

TEST(SurfacePointEvaluate, WorksOnFloatPositions) {
  Eigen::Matrix3Xf positions(3, 3);
  positions << 0, 1, 0,  //
      0, 0, 1,           //
      0, 0, 0;
  const SurfacePoint p{{0, 1, 2}, {0.5, 0.25, 0.25}};
  EXPECT_EIGEN_NEAR(p.Evaluate(positions), Eigen::Vector3d(0.25, 0.25, 0), 1e-7);
}

TEST(SaveFaceRig, RoundTrip) {
  TempDir dir;
  const FaceRig rig = MakeRig();
  const Status saved = SaveFaceRig(rig, dir.path());
  ASSERT_TRUE(saved.ok()) << saved.message();
  for (const char* file : {"face_rig.json", "neutral.obj", "blendshapes.pc2", "skull.obj",
                           "skin_samples.csv", "markers.csv"}) {
    EXPECT_TRUE(std::filesystem::exists(dir.Join(file))) << file;
  }
  const auto loaded = LoadFaceRig(dir.path());
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  const FaceRig& r = *loaded;
  EXPECT_EQ(r.name, "grid_subject");
  EXPECT_TRUE(SameTopology(r.neutral, rig.neutral));
  EXPECT_EIGEN_NEAR(r.neutral.positions_mm, rig.neutral.positions_mm, 1e-4);  // float32 OBJ read
  EXPECT_EQ(r.blendshape_names, rig.blendshape_names);
  ASSERT_EQ(r.blendshape_deltas_mm.size(), 2u);
  for (int k = 0; k < 2; ++k) {
    EXPECT_EIGEN_NEAR(r.blendshape_deltas_mm[k], rig.blendshape_deltas_mm[k], 1e-6);  // float32 PC2
  }
  EXPECT_TRUE(SameTopology(r.skull, rig.skull));
  EXPECT_EIGEN_NEAR(r.skull.positions_mm, rig.skull.positions_mm, 1e-4);
  ASSERT_EQ(r.skull_landmarks.size(), 5u);
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(r.skull_landmarks[i].name, rig.skull_landmarks[i].name);
    EXPECT_EIGEN_NEAR(r.skull_landmarks[i].position_in_skull,
                      rig.skull_landmarks[i].position_in_skull, 0.0);
  }
  ASSERT_EQ(r.skin_samples.size(), rig.skin_samples.size());
  for (size_t i = 0; i < rig.skin_samples.size(); ++i) {
    EXPECT_EQ(r.skin_samples[i].vertices, rig.skin_samples[i].vertices) << i;
    EXPECT_EIGEN_NEAR(r.skin_samples[i].weights, rig.skin_samples[i].weights, 1e-9);
  }
  ASSERT_EQ(r.markers.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(r.markers[i].name, rig.markers[i].name);
    EXPECT_EQ(r.markers[i].point.vertices, rig.markers[i].point.vertices);
    EXPECT_EIGEN_NEAR(r.markers[i].point.weights, rig.markers[i].point.weights, 1e-9);
    EXPECT_DOUBLE_EQ(r.markers[i].diameter_mm, rig.markers[i].diameter_mm);
  }
  EXPECT_EQ(r.regions, rig.regions);
  EXPECT_EQ(r.stable_regions, rig.stable_regions);
  EXPECT_EIGEN_NEAR(r.jaw.pivot_in_skull, rig.jaw.pivot_in_skull, 0.0);
  EXPECT_EIGEN_NEAR(r.jaw.axis_in_skull, rig.jaw.axis_in_skull, 0.0);
  EXPECT_EQ(r.jaw.region, "jaw");
  // The loaded rig evaluates like the original.
  EXPECT_EIGEN_NEAR(r.Evaluate(Eigen::Vector2d(0.3, 0.7)), rig.Evaluate(Eigen::Vector2d(0.3, 0.7)),
                    1e-4);
}

TEST(SaveFaceRig, RoundTripWithoutBlendshapesOrSkull) {
  TempDir dir;
  FaceRig rig = MakeRig();
  rig.blendshape_names.clear();
  rig.blendshape_deltas_mm.clear();
  rig.skull = Mesh();
  rig.skin_samples.clear();
  rig.markers.clear();
  ASSERT_TRUE(SaveFaceRig(rig, dir.path()).ok());
  EXPECT_FALSE(std::filesystem::exists(dir.Join("blendshapes.pc2")));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("skull.obj")));
  const auto loaded = LoadFaceRig(dir.path());
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  EXPECT_TRUE(loaded->blendshape_names.empty());
  EXPECT_EQ(loaded->skull.vertex_count(), 0);
  EXPECT_TRUE(loaded->skin_samples.empty());
  EXPECT_TRUE(loaded->markers.empty());
  EXPECT_EIGEN_NEAR(loaded->Evaluate(Eigen::VectorXd(0)), rig.neutral.positions_mm, 1e-4);
}

TEST(SaveFaceRig, RefusesAnInvalidRigAndWritesNothing) {
  TempDir dir;
  FaceRig rig = MakeRig();
  rig.stable_regions.push_back("cheek");
  const std::string folder = dir.Join("rig");
  const Status status = SaveFaceRig(rig, folder);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("stable region 'cheek' is not defined"));
  EXPECT_FALSE(std::filesystem::exists(folder));
}

TEST(SaveFaceRig, MarkerNameThatCsvCannotHold) {
  // markers.csv has no quoting: a name with a comma or newline must be refused on save, not
  // written into a file LoadFaceRig then rejects.
  TempDir dir;
  for (const std::string name : {"brow,left", "brow\nleft"}) {
    FaceRig rig = MakeRig();
    rig.markers[0].name = name;
    const Status status = SaveFaceRig(rig, dir.path());
    ASSERT_FALSE(status.ok()) << "saved a marker named '" << name << "'";
    EXPECT_THAT(status.message(), HasSubstr("marker name"));
  }
}

TEST(FaceRigValidate, ReportsEachInconsistency) {
  FaceRig rig = MakeRig();
  rig.blendshape_deltas_mm.pop_back();
  EXPECT_THAT(rig.Validate().message(), HasSubstr("blendshape names and deltas differ in number"));

  rig = MakeRig();
  rig.blendshape_names[1] = "smile";
  EXPECT_THAT(rig.Validate().message(), HasSubstr("blendshape 'smile' appears twice"));

  rig = MakeRig();
  rig.blendshape_deltas_mm[1] = Eigen::Matrix3Xd::Zero(3, 19);
  EXPECT_THAT(rig.Validate().message(),
              HasSubstr("blendshape 'jaw_open' does not match the neutral mesh"));

  rig = MakeRig();
  rig.skin_samples[2].vertices[1] = 20;
  EXPECT_THAT(rig.Validate().message(),
              AllOf(HasSubstr("face rig 'grid_subject'"), HasSubstr("skin sample 2"),
                    HasSubstr("vertex 20 out of range (mesh has 20)")));

  rig = MakeRig();
  rig.skin_samples[1].weights << 0.5, 0.6, -0.1;
  EXPECT_THAT(rig.Validate().message(),
              AllOf(HasSubstr("skin sample 1"), HasSubstr("not barycentric")));

  rig = MakeRig();
  rig.markers[1].diameter_mm = 0.0;
  EXPECT_THAT(rig.Validate().message(), HasSubstr("marker chin has no size"));

  rig = MakeRig();
  rig.regions["jaw"].push_back(-1);
  EXPECT_THAT(rig.Validate().message(), HasSubstr("region 'jaw' has vertex -1 out of range"));

  rig = MakeRig();
  rig.jaw.region = "mandible";
  EXPECT_THAT(rig.Validate().message(), HasSubstr("jaw region 'mandible' is not defined"));

  rig = MakeRig();
  rig.jaw.axis_in_skull = Eigen::Vector3d(2, 0, 0);
  EXPECT_THAT(rig.Validate().message(), HasSubstr("jaw axis must be a unit vector"));

  rig = MakeRig();
  rig.skull_landmarks[3].position_in_skull.x() = std::nan("");
  EXPECT_THAT(rig.Validate().message(), HasSubstr("landmark 'b4' is not finite"));
}

TEST(LoadFaceRig, MissingFolder) {
  TempDir dir;
  const Status status = LoadError(dir.Join("nobody"));
  EXPECT_EQ(status.code(), StatusCode::kNotFound);
  EXPECT_THAT(status.message(), HasSubstr("nobody"));
}

TEST(LoadFaceRig, MissingNeutral) {
  TempDir dir;
  SaveGoodRig(dir.path());
  std::filesystem::remove(dir.Join("neutral.obj"));
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kNotFound);
  EXPECT_THAT(status.message(), HasSubstr(dir.Join("neutral.obj")));
}

TEST(LoadFaceRig, BlendshapeCountMismatch) {
  TempDir dir;
  SaveGoodRig(dir.path());
  PointCache three;
  three.vertex_count = 20;
  three.positions = Eigen::MatrixXf::Zero(60, 3);
  ASSERT_TRUE(WritePc2(dir.Join("blendshapes.pc2"), three).ok());
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(status.message(), AllOf(HasSubstr(dir.Join("blendshapes.pc2")),
                                      HasSubstr("holds 3 shapes of 20 vertices"),
                                      HasSubstr("face_rig.json names 2 shapes")));
}

TEST(LoadFaceRig, BlendshapeVertexCountMismatch) {
  TempDir dir;
  SaveGoodRig(dir.path());
  PointCache wrong;
  wrong.vertex_count = 21;
  wrong.positions = Eigen::MatrixXf::Zero(63, 2);
  ASSERT_TRUE(WritePc2(dir.Join("blendshapes.pc2"), wrong).ok());
  EXPECT_THAT(LoadError(dir.path()).message(), AllOf(HasSubstr("holds 2 shapes of 21 vertices"),
                                                     HasSubstr("neutral.obj has 20 vertices")));
}

TEST(LoadFaceRig, MissingBlendshapes) {
  TempDir dir;
  SaveGoodRig(dir.path());
  std::filesystem::remove(dir.Join("blendshapes.pc2"));
  EXPECT_THAT(LoadError(dir.path()).message(), HasSubstr(dir.Join("blendshapes.pc2")));
}

TEST(LoadFaceRig, SampleVertexOutOfRangeNamesTheLine) {
  TempDir dir;
  SaveGoodRig(dir.path());
  ReplaceLine(dir.Join("skin_samples.csv"), 3, "1,2,99,0.2,0.3,0.5");
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), AllOf(HasSubstr(dir.Join("skin_samples.csv") + ":3:"),
                                      HasSubstr("vertex 99 out of range (mesh has 20)")));
}

TEST(LoadFaceRig, NonBarycentricWeights) {
  TempDir dir;
  SaveGoodRig(dir.path());
  ReplaceLine(dir.Join("skin_samples.csv"), 4, "12,13,18,0.5,0.5,0.5");
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr(dir.Join("skin_samples.csv") + ":4:"),
                    HasSubstr("weights (0.5, 0.5, 0.5) are not barycentric")));
}

TEST(LoadFaceRig, NonIntegerSampleVertex) {
  TempDir dir;
  SaveGoodRig(dir.path());
  ReplaceLine(dir.Join("skin_samples.csv"), 2, "0.5,0,0,1,0,0");
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr(dir.Join("skin_samples.csv") + ":2:"),
                    HasSubstr("column v0 is '0.5', not an integer")));
}

TEST(LoadFaceRig, MarkerWithBadDiameter) {
  TempDir dir;
  SaveGoodRig(dir.path());
  ReplaceLine(dir.Join("markers.csv"), 3, "chin,2,2,2,1,0,0,big");
  EXPECT_THAT(LoadError(dir.path()).message(), AllOf(HasSubstr(dir.Join("markers.csv") + ":3:"),
                                                     HasSubstr("column diameter_mm is 'big'")));
}

TEST(LoadFaceRig, UnknownStableRegion) {
  TempDir dir;
  SaveGoodRig(dir.path());
  EditJson(dir.Join("face_rig.json"),
           [](Json* json) { (*json)["stable_regions"].push_back("temples"); });
  const Status status = LoadError(dir.path());
  EXPECT_EQ(status.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(status.message(),
              AllOf(HasSubstr(dir.path()), HasSubstr("stable region 'temples' is not defined")));
}

TEST(LoadFaceRig, RegionVertexOutOfRangeNamesTheField) {
  TempDir dir;
  SaveGoodRig(dir.path());
  EditJson(dir.Join("face_rig.json"), [](Json* json) { (*json)["regions"]["jaw"].push_back(40); });
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr("face_rig.json"), HasSubstr("field 'regions.jaw'"),
                    HasSubstr("vertex 40 out of range (neutral.obj has 20)")));
}

TEST(LoadFaceRig, LandmarkWithTwoCoordinates) {
  TempDir dir;
  SaveGoodRig(dir.path());
  EditJson(dir.Join("face_rig.json"), [](Json* json) {
    (*json)["skull_landmarks"][2]["position_in_skull"] = Json::array({1.0, 2.0});
  });
  EXPECT_THAT(
      LoadError(dir.path()).message(),
      AllOf(HasSubstr("face_rig.json"), HasSubstr("field 'skull_landmarks[2].position_in_skull'"),
            HasSubstr("expected [x, y, z], got 2 numbers")));
}

TEST(LoadFaceRig, ZeroJawAxis) {
  TempDir dir;
  SaveGoodRig(dir.path());
  EditJson(dir.Join("face_rig.json"), [](Json* json) {
    (*json)["jaw"]["axis_in_skull"] = Json::array({0.0, 0.0, 0.0});
  });
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr("field 'jaw.axis_in_skull'"), HasSubstr("non-zero")));
}

TEST(LoadFaceRig, NonUnitJawAxisIsNormalised) {
  TempDir dir;
  SaveGoodRig(dir.path());
  EditJson(dir.Join("face_rig.json"), [](Json* json) {
    (*json)["jaw"]["axis_in_skull"] = Json::array({0.0, 3.0, 4.0});
  });
  const auto loaded = LoadFaceRig(dir.path());
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  EXPECT_EIGEN_NEAR(loaded->jaw.axis_in_skull, Eigen::Vector3d(0, 0.6, 0.8), 1e-15);
}

TEST(LoadFaceRig, WrongUnitsAndVersion) {
  TempDir dir;
  SaveGoodRig(dir.path());
  EditJson(dir.Join("face_rig.json"), [](Json* json) { (*json)["units"] = "cm"; });
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr("field 'units'"), HasSubstr("'cm' is not supported")));
  EditJson(dir.Join("face_rig.json"), [](Json* json) {
    (*json)["units"] = "mm";
    (*json)["format_version"] = 9;
  });
  EXPECT_THAT(LoadError(dir.path()).message(),
              AllOf(HasSubstr("field 'format_version'"), HasSubstr("version 9 is not supported")));
}

// A sparse layout: a count (the first N), a list of names, or a saved rig's markers.csv.
TEST(SelectMarkerLayout, CountNamesAndRigCsv) {
  FaceRig rig = MakeRig();
  for (int i = 0; i < 4; ++i) {
    rig.markers.push_back({"extra" + std::to_string(i), SurfacePoint::AtVertex(i), 2.0});
  }
  auto first = SelectMarkerLayout(rig, "4", "--markers");
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  ASSERT_EQ(first->size(), 4u);
  EXPECT_EQ((*first)[0].name, "brow_l");
  EXPECT_EQ((*first)[3].name, "extra1");
  EXPECT_THAT(SelectMarkerLayout(rig, "3", "--markers").status().message(),
              HasSubstr("--markers 3: need 4..6"));
  EXPECT_THAT(SelectMarkerLayout(rig, "99", "sim.markers").status().message(),
              HasSubstr("sim.markers 99: need 4..6"));

  TempDir dir;
  testing::WriteBytes(dir.Join("names.txt"), "# layout\nextra3\nbrow_l\r\nextra0\nextra2\n");
  auto named = SelectMarkerLayout(rig, dir.Join("names.txt"), "--markers");
  ASSERT_TRUE(named.ok()) << named.status().ToString();
  ASSERT_EQ(named->size(), 4u);
  EXPECT_EQ((*named)[0].name, "extra3");
  EXPECT_EQ((*named)[1].name, "brow_l");

  // A saved rig with a subset of the markers: its markers.csv is a layout for the full rig.
  FaceRig subset = rig;
  subset.markers = {rig.markers[5], rig.markers[1], rig.markers[2], rig.markers[4]};
  ASSERT_TRUE(SaveFaceRig(subset, dir.Join("subset")).ok());
  auto from_csv = SelectMarkerLayout(rig, dir.Join("subset/markers.csv"), "--markers");
  ASSERT_TRUE(from_csv.ok()) << from_csv.status().ToString();
  ASSERT_EQ(from_csv->size(), 4u);
  for (size_t i = 0; i < 4; ++i) EXPECT_EQ((*from_csv)[i].name, subset.markers[i].name);

  testing::WriteBytes(dir.Join("bad.txt"), "extra0\nnose_tip\n");
  EXPECT_THAT(SelectMarkerLayout(rig, dir.Join("bad.txt"), "--markers").status().message(),
              AllOf(HasSubstr("bad.txt:2"), HasSubstr("'nose_tip' is not in rig")));
  testing::WriteBytes(dir.Join("twice.txt"), "extra0\nextra1\nextra0\nextra2\n");
  EXPECT_THAT(SelectMarkerLayout(rig, dir.Join("twice.txt"), "--markers").status().message(),
              HasSubstr("twice.txt:3: marker 'extra0' listed twice"));
  EXPECT_THAT(SelectMarkerLayout(rig, dir.Join("missing.txt"), "--markers").status().message(),
              HasSubstr("neither a count nor a readable file"));
}

}  // namespace
}  // namespace facedyn
