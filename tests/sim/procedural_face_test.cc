#include "sim/procedural_face.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <set>
#include <utility>

#include "core/face_rig.h"
#include "physics/face_anatomy.h"
#include "tests/support/test_support.h"

namespace facedyn::sim {
namespace {

const FaceRig& DefaultFace() {
  static const FaceRig rig = [] {
    const auto start = std::chrono::steady_clock::now();
    StatusOr<FaceRig> made = MakeProceduralFace(ProceduralFaceOptions{});
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    FACEDYN_CHECK(made.ok(), made.status().ToString());
    std::printf("procedural face: %d vertices, %d faces, generated in %.3f s\n",
                made->vertex_count(), made->neutral.face_count(), seconds);
    return std::move(made).value();
  }();
  return rig;
}

// Undirected edge -> number of faces using it.
std::map<std::pair<int, int>, int> EdgeUse(const Mesh& mesh) {
  std::map<std::pair<int, int>, int> use;
  for (int f = 0; f < mesh.face_count(); ++f) {
    const int begin = mesh.face_offsets[f], end = mesh.face_offsets[f + 1];
    for (int c = begin; c < end; ++c) {
      const int a = mesh.corner_vertices[c], b = mesh.corner_vertices[c + 1 < end ? c + 1 : begin];
      ++use[{std::min(a, b), std::max(a, b)}];
    }
  }
  return use;
}

double Centroid(const FaceRig& rig, const std::string& region, const Eigen::Matrix3Xd& field,
                int axis) {
  const auto& vertices = rig.regions.at(region);
  double sum = 0;
  for (int v : vertices) sum += field(axis, v);
  return sum / vertices.size();
}

double MeanNorm(const FaceRig& rig, const std::string& region, const Eigen::Matrix3Xd& delta) {
  const auto& vertices = rig.regions.at(region);
  double sum = 0;
  for (int v : vertices) sum += delta.col(v).norm();
  return sum / vertices.size();
}

TEST(MakeProceduralFace, VertexCountWithinTenPercentOfTarget) {
  for (int target : {4000, 6000, 8000, 10000}) {
    ProceduralFaceOptions options;
    options.target_vertex_count = target;
    StatusOr<FaceRig> rig = MakeProceduralFace(options);
    ASSERT_TRUE(rig.ok()) << rig.status().ToString();
    EXPECT_GE(rig->vertex_count(), 0.9 * target) << target;
    EXPECT_LE(rig->vertex_count(), 1.1 * target) << target;
    std::printf("target %d -> %d vertices\n", target, rig->vertex_count());
  }
}

TEST(MakeProceduralFace, RejectsBadOptions) {
  ProceduralFaceOptions options;
  options.target_vertex_count = 100;
  StatusOr<FaceRig> rig = MakeProceduralFace(options);
  ASSERT_FALSE(rig.ok());
  EXPECT_NE(rig.status().message().find("target_vertex_count"), std::string::npos);
  options = ProceduralFaceOptions{};
  options.name.clear();
  EXPECT_FALSE(options.Check().ok());
  options = ProceduralFaceOptions{};
  options.anatomy.marker_diameter_mm = -1;
  EXPECT_NE(options.Check().message().find("marker_diameter_mm"), std::string::npos);
}

TEST(MakeProceduralFace, MeshIsValidManifoldAndHasEyeAndMouthHoles) {
  const FaceRig& rig = DefaultFace();
  ASSERT_TRUE(rig.Validate().ok()) << rig.Validate().ToString();
  for (const auto& [edge, count] : EdgeUse(rig.neutral)) {
    ASSERT_LE(count, 2) << "edge " << edge.first << "-" << edge.second;
  }
  // Every vertex has a single fan: its boundary edges number 0 or 2.
  std::vector<int> boundary_degree(rig.vertex_count(), 0);
  for (const auto& [edge, count] : EdgeUse(rig.neutral)) {
    if (count == 1) ++boundary_degree[edge.first], ++boundary_degree[edge.second];
  }
  for (int v = 0; v < rig.vertex_count(); ++v)
    ASSERT_TRUE(boundary_degree[v] == 0 || boundary_degree[v] == 2) << v;
  // Outer rim + two eyes + mouth.
  const auto loops = physics::BoundaryLoops(rig.neutral);
  ASSERT_EQ(loops.size(), 4u);
  int eye_loops = 0, mouth_loops = 0;
  for (const auto& loop : loops) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int v : loop) c += rig.neutral.positions_mm.col(v);
    c /= loop.size();
    if (std::abs(c.x()) > 20 && std::abs(c.x()) < 45 && c.y() > 0 && c.y() < 30) ++eye_loops;
    if (std::abs(c.x()) < 3 && c.y() < -40 && c.y() > -65) ++mouth_loops;
  }
  EXPECT_EQ(eye_loops, 2);
  EXPECT_EQ(mouth_loops, 1);
}

TEST(MakeProceduralFace, OrientedOutwardWithUvsInUnitSquare) {
  const FaceRig& rig = DefaultFace();
  const Mesh& mesh = rig.neutral;
  ASSERT_TRUE(mesh.has_uvs());
  EXPECT_GE(mesh.uvs.minCoeff(), 0.0);
  EXPECT_LE(mesh.uvs.maxCoeff(), 1.0);
  const Eigen::Matrix3Xi triangles = mesh.Triangles();
  const Eigen::Matrix2Xd uv = mesh.VertexUvs();
  int outward = 0;
  for (Eigen::Index t = 0; t < triangles.cols(); ++t) {
    const Eigen::Vector2d a = uv.col(triangles(0, t)), b = uv.col(triangles(1, t)),
                          c = uv.col(triangles(2, t));
    const Eigen::Vector2d e1 = b - a, e2 = c - a;
    ASSERT_GT(e1.x() * e2.y() - e1.y() * e2.x(), 0.0) << "uv triangle " << t << " flipped";
    const Eigen::Vector3d p = mesh.positions_mm.col(triangles(0, t));
    const Eigen::Vector3d n = (mesh.positions_mm.col(triangles(1, t)) - p)
                                  .cross(mesh.positions_mm.col(triangles(2, t)) - p);
    // Outward: away from the head's vertical axis.
    if (n.dot(Eigen::Vector3d(p.x(), 0.0, p.z())) > 0) ++outward;
  }
  EXPECT_GE(outward, 0.99 * triangles.cols());
}

TEST(MakeProceduralFace, HasFaceProportions) {
  const FaceRig& rig = DefaultFace();
  const Eigen::Matrix3Xd& p = rig.neutral.positions_mm;
  const double width = p.row(0).maxCoeff() - p.row(0).minCoeff();
  const double height = p.row(1).maxCoeff() - p.row(1).minCoeff();
  EXPECT_GT(width, 130);
  EXPECT_LT(width, 170);
  EXPECT_GT(height, 180);
  EXPECT_LT(height, 220);
  // The nose protrudes beyond everything else; the eyes sit behind the brows.
  Eigen::Index tip;
  p.row(2).maxCoeff(&tip);
  EXPECT_LT(std::abs(p(0, tip)), 2.0);
  EXPECT_GT(p(1, tip), -35);
  EXPECT_LT(p(1, tip), -10);
  EXPECT_GT(Centroid(rig, "nose", p, 2), Centroid(rig, "cheeks", p, 2) + 10);
  // Above each eye the brow ridge stands in front of the eye opening's rim.
  double brow_z = 0, rim_z = 0;
  int brow_n = 0, rim_n = 0;
  for (int v : rig.regions.at("brows")) {
    if (std::abs(std::abs(p(0, v)) - 30.0) < 8.0) brow_z += p(2, v), ++brow_n;
  }
  for (const auto& loop : physics::BoundaryLoops(rig.neutral)) {
    if (loop.size() > 200) continue;  // the outer rim
    for (int v : loop) {
      if (p(1, v) > 0) rim_z += p(2, v), ++rim_n;
    }
  }
  ASSERT_GT(brow_n, 0);
  ASSERT_GT(rim_n, 0);
  EXPECT_GT(brow_z / brow_n, rim_z / rim_n + 2.0);
}

TEST(MakeProceduralFace, RegionsAreNonEmptyAndDisjointWhereExpected) {
  const FaceRig& rig = DefaultFace();
  for (const char* name :
       {"forehead", "brows", "nose_bridge", "temples", "nose", "cheeks", "mouth_corners", "lips",
        "upper_lip", "lower_lip", "chin", "jaw", "eyes"}) {
    ASSERT_TRUE(rig.regions.count(name)) << name;
    EXPECT_FALSE(rig.regions.at(name).empty()) << name;
  }
  const std::vector<std::string> primary = {"forehead",  "brows",  "nose_bridge",   "temples",
                                            "nose",      "cheeks", "mouth_corners", "upper_lip",
                                            "lower_lip", "chin",   "eyes"};
  std::vector<int> owner(rig.vertex_count(), -1);
  for (size_t r = 0; r < primary.size(); ++r) {
    for (int v : rig.regions.at(primary[r])) {
      ASSERT_EQ(owner[v], -1) << "vertex " << v << " in " << primary[r] << " and "
                              << primary[owner[v]];
      owner[v] = static_cast<int>(r);
    }
  }
  const std::set<int> jaw(rig.regions.at("jaw").begin(), rig.regions.at("jaw").end());
  for (const auto& stable : rig.stable_regions) {
    for (int v : rig.regions.at(stable)) EXPECT_FALSE(jaw.count(v)) << stable << " vertex " << v;
  }
  for (int v : rig.regions.at("lower_lip")) EXPECT_TRUE(jaw.count(v));
  for (int v : rig.regions.at("chin")) EXPECT_TRUE(jaw.count(v));
  for (int v : rig.regions.at("upper_lip")) EXPECT_FALSE(jaw.count(v));
  EXPECT_EQ(rig.regions.at("lips").size(),
            rig.regions.at("upper_lip").size() + rig.regions.at("lower_lip").size());
  EXPECT_EQ(rig.jaw.region, "jaw");
  EXPECT_EIGEN_NEAR(rig.jaw.axis_in_skull, Eigen::Vector3d::UnitX(), 1e-12);
}

TEST(MakeProceduralFace, BlendshapesAreFiniteLocalAndPlausible) {
  const FaceRig& rig = DefaultFace();
  ASSERT_EQ(rig.blendshape_names.size(), 10u);
  for (size_t k = 0; k < rig.blendshape_names.size(); ++k) {
    EXPECT_EQ(rig.blendshape_names[k], kProceduralExpressions[k]);
    const Eigen::Matrix3Xd& d = rig.blendshape_deltas_mm[k];
    ASSERT_TRUE(d.allFinite()) << rig.blendshape_names[k];
    const double peak = d.colwise().norm().maxCoeff();
    EXPECT_GT(peak, 2.0) << rig.blendshape_names[k];
    EXPECT_LT(peak, 30.0) << rig.blendshape_names[k];
    // Local: nothing but brow_raise moves the upper forehead; nothing moves the temples much.
    if (rig.blendshape_names[k] != "brow_raise") {
      EXPECT_LT(MeanNorm(rig, "forehead", d), 0.3) << rig.blendshape_names[k];
    }
  }
  const auto& jaw_open = rig.blendshape_deltas_mm[rig.BlendshapeIndex("jaw_open")];
  const double chin = MeanNorm(rig, "chin", jaw_open);
  EXPECT_GT(chin, 12.0);
  EXPECT_LT(chin, 25.0);
  EXPECT_LT(MeanNorm(rig, "forehead", jaw_open) + MeanNorm(rig, "nose", jaw_open), 1e-9);
  EXPECT_LT(Centroid(rig, "chin", jaw_open, 1), -8.0);  // the chin drops (and moves back)
  EXPECT_LT(MeanNorm(rig, "upper_lip", jaw_open), 1.0);

  const auto& smile = rig.blendshape_deltas_mm[rig.BlendshapeIndex("smile")];
  double corner_peak = 0;
  for (int v : rig.regions.at("mouth_corners"))
    corner_peak = std::max(corner_peak, smile.col(v).norm());
  EXPECT_GT(corner_peak, 7.0);
  EXPECT_LT(corner_peak, 11.0);
  EXPECT_GT(Centroid(rig, "mouth_corners", smile, 1), 3.0);  // corners go up

  const auto& puff = rig.blendshape_deltas_mm[rig.BlendshapeIndex("cheek_puff")];
  const double puff_peak = puff.colwise().norm().maxCoeff();
  EXPECT_GT(puff_peak, 7.0);
  EXPECT_LT(puff_peak, 9.0);
  const auto& brow = rig.blendshape_deltas_mm[rig.BlendshapeIndex("brow_raise")];
  EXPECT_GT(Centroid(rig, "brows", brow, 1), 4.0);
  EXPECT_LT(MeanNorm(rig, "chin", brow), 0.05);
}

TEST(MakeProceduralFace, IsDeterministic) {
  const FaceRig& a = DefaultFace();
  StatusOr<FaceRig> b = MakeProceduralFace(ProceduralFaceOptions{});
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(a.neutral.positions_mm, b->neutral.positions_mm);
  EXPECT_EQ(a.neutral.corner_vertices, b->neutral.corner_vertices);
  EXPECT_EQ(a.skull.positions_mm, b->skull.positions_mm);
  for (size_t k = 0; k < a.blendshape_deltas_mm.size(); ++k) {
    EXPECT_EQ(a.blendshape_deltas_mm[k], b->blendshape_deltas_mm[k]);
  }
  ASSERT_EQ(a.skin_samples.size(), b->skin_samples.size());
  for (size_t i = 0; i < a.skin_samples.size(); ++i) {
    EXPECT_EQ(a.skin_samples[i].vertices, b->skin_samples[i].vertices);
  }
}

TEST(MakeProceduralFace, SaveLoadRoundTrip) {
  const FaceRig& rig = DefaultFace();
  testing::TempDir dir;
  ASSERT_TRUE(SaveFaceRig(rig, dir.Join("face")).ok());
  StatusOr<FaceRig> loaded = LoadFaceRig(dir.Join("face"));
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->name, rig.name);
  ASSERT_EQ(loaded->vertex_count(), rig.vertex_count());
  EXPECT_TRUE(SameTopology(loaded->neutral, rig.neutral));
  EXPECT_EIGEN_NEAR(loaded->neutral.positions_mm, rig.neutral.positions_mm, 1e-4);
  EXPECT_EIGEN_NEAR(loaded->skull.positions_mm, rig.skull.positions_mm, 1e-4);
  EXPECT_EQ(loaded->blendshape_names, rig.blendshape_names);
  for (size_t k = 0; k < rig.blendshape_deltas_mm.size(); ++k) {
    EXPECT_EIGEN_NEAR(loaded->blendshape_deltas_mm[k], rig.blendshape_deltas_mm[k], 1e-4);
  }
  EXPECT_EQ(loaded->regions, rig.regions);
  EXPECT_EQ(loaded->stable_regions, rig.stable_regions);
  EXPECT_EQ(loaded->skin_samples.size(), rig.skin_samples.size());
  EXPECT_EQ(loaded->markers.size(), rig.markers.size());
  EXPECT_EQ(loaded->skull_landmarks.size(), 5u);
  EXPECT_EIGEN_NEAR(loaded->jaw.pivot_in_skull, rig.jaw.pivot_in_skull, 1e-9);
  // Tissue thickness is recomputable from the loaded regions.
  EXPECT_EIGEN_NEAR(physics::TissueThicknessMm(*loaded), physics::TissueThicknessMm(rig), 1e-3);
}

}  // namespace
}  // namespace facedyn::sim
