#include "physics/face_anatomy.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <set>

#include "core/mesh_primitives.h"
#include "sim/procedural_face.h"
#include "tests/support/test_support.h"

namespace facedyn::physics {
namespace {

const FaceRig& Face() {
  static const FaceRig rig = [] {
    StatusOr<FaceRig> made = sim::MakeProceduralFace(sim::ProceduralFaceOptions{});
    FACEDYN_CHECK(made.ok(), made.status().ToString());
    return std::move(made).value();
  }();
  return rig;
}

double SurfaceAreaMm2(const Mesh& mesh) {
  const Eigen::Matrix3Xi t = mesh.Triangles();
  double area = 0;
  for (Eigen::Index i = 0; i < t.cols(); ++i) {
    const Eigen::Vector3d a = mesh.positions_mm.col(t(0, i));
    area +=
        0.5 * (mesh.positions_mm.col(t(1, i)) - a).cross(mesh.positions_mm.col(t(2, i)) - a).norm();
  }
  return area;
}

TEST(TissueThicknessMm, InsideEachRegionWithinItsClinicalRange) {
  const FaceRig& rig = Face();
  const Eigen::VectorXd t = TissueThicknessMm(rig);
  ASSERT_EQ(t.size(), rig.vertex_count());
  const std::vector<double> border = ThicknessBorderDistanceMm(rig);
  for (const auto& [region, range] : RegionThicknessRanges()) {
    int interior = 0;
    double sum = 0;
    for (int v : rig.regions.at(region)) {
      if (border[v] < kThicknessBlendMm) continue;
      ++interior;
      sum += t[v];
      EXPECT_GE(t[v], range.min_mm - 1e-9) << region << " vertex " << v;
      EXPECT_LE(t[v], range.max_mm + 1e-9) << region << " vertex " << v;
    }
    // Small regions (mouth corners, nose bridge) may be all border; the rest have an interior.
    if (rig.regions.at(region).size() > 150) {
      EXPECT_GT(interior, 0) << region;
    }
    if (interior > 0) {
      std::printf("%-14s mean thickness %.1f mm over %d interior vertices\n", region.c_str(),
                  sum / interior, interior);
    }
  }
  EXPECT_GE(t.minCoeff(), 2.0);
  EXPECT_LE(t.maxCoeff(), 20.0);
}

TEST(TissueThicknessMm, BlendsSmoothlyAcrossRegionBorders) {
  const FaceRig& rig = Face();
  const Eigen::VectorXd t = TissueThicknessMm(rig);
  const auto neighbors = VertexNeighbors(rig.neutral);
  double steepest = 0;  // mm of thickness per mm along the surface
  for (int v = 0; v < rig.vertex_count(); ++v) {
    for (int w : neighbors[v]) {
      const double edge =
          (rig.neutral.positions_mm.col(v) - rig.neutral.positions_mm.col(w)).norm();
      steepest = std::max(steepest, std::abs(t[v] - t[w]) / edge);
    }
  }
  std::printf("steepest thickness slope %.2f mm/mm\n", steepest);
  // A jump between nose (4 mm) and cheek (12 mm) spread over the 2 x 5 mm blend band.
  EXPECT_LT(steepest, 1.5);
}

TEST(CompleteFaceAnatomy, SkullLiesUnderTheSkinAtTheTissueThickness) {
  const FaceRig& rig = Face();
  ASSERT_EQ(rig.skull.vertex_count(), rig.vertex_count());
  EXPECT_TRUE(SameTopology(rig.skull, rig.neutral));
  const Eigen::VectorXd t = TissueThicknessMm(rig);
  const Eigen::Matrix3Xd normals = VertexNormals(rig.neutral, rig.neutral.positions_mm);
  for (int v = 0; v < rig.vertex_count(); ++v) {
    const Eigen::Vector3d depth = rig.neutral.positions_mm.col(v) - rig.skull.positions_mm.col(v);
    ASSERT_NEAR(depth.norm(), t[v], 1e-9) << v;
    ASSERT_GT(depth.dot(normals.col(v)), 0.3 * t[v]) << "skull vertex " << v << " is not inside";
  }
  // The inner surface keeps the skin's orientation almost everywhere (no folding).
  const Eigen::Matrix3Xi tri = rig.neutral.Triangles();
  int flipped = 0;
  for (Eigen::Index i = 0; i < tri.cols(); ++i) {
    auto normal = [&](const Eigen::Matrix3Xd& p) {
      const Eigen::Vector3d a = p.col(tri(0, i));
      return Eigen::Vector3d((p.col(tri(1, i)) - a).cross(p.col(tri(2, i)) - a));
    };
    if (normal(rig.skull.positions_mm).dot(normal(rig.neutral.positions_mm)) <= 0) ++flipped;
  }
  std::printf("skull triangles flipped against the skin: %d of %ld\n", flipped, long(tri.cols()));
  EXPECT_LT(flipped, 0.01 * tri.cols());
}

TEST(CompleteFaceAnatomy, FiveLandmarksSpreadOverTheCranium) {
  const FaceRig& rig = Face();
  ASSERT_EQ(rig.skull_landmarks.size(), 5u);
  const char* names[] = {"b1", "b2", "b3", "b4", "b5"};
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(rig.skull_landmarks[i].name, names[i]);
    EXPECT_TRUE(rig.skull_landmarks[i].position_in_skull.allFinite());
  }
  const Eigen::Vector3d b1 = rig.skull_landmarks[0].position_in_skull,
                        b2 = rig.skull_landmarks[1].position_in_skull,
                        b3 = rig.skull_landmarks[2].position_in_skull,
                        b4 = rig.skull_landmarks[3].position_in_skull,
                        b5 = rig.skull_landmarks[4].position_in_skull;
  EXPECT_GT(b1.y(), 60);               // forehead top
  EXPECT_GT(b2.x(), 40);               // left temple
  EXPECT_LT(b3.x(), -40);              // right temple
  EXPECT_NEAR(b2.x(), -b3.x(), 1e-6);  // symmetric face
  EXPECT_LT(std::abs(b4.x()), 1.0);    // nasion on the midline, in front
  EXPECT_GT(b4.z(), 70);
  EXPECT_LT(b5.z(), -30);  // crown: back and top
  EXPECT_GT(b5.y(), 50);
  for (int i = 0; i < 5; ++i) {
    for (int j = i + 1; j < 5; ++j) {
      EXPECT_GT(
          (rig.skull_landmarks[i].position_in_skull - rig.skull_landmarks[j].position_in_skull)
              .norm(),
          40.0);
    }
  }
}

TEST(CompleteFaceAnatomy, SkinSamplesAreEvenlySpreadOffTheHoles) {
  const FaceRig& rig = Face();
  ASSERT_EQ(rig.skin_samples.size(), 344u);
  const std::vector<bool> boundary = BoundaryVertices(rig.neutral);
  std::set<int> unique;
  for (const auto& s : rig.skin_samples) {
    EXPECT_FALSE(boundary[s.vertices[0]]);
    unique.insert(s.vertices[0]);
  }
  EXPECT_EQ(unique.size(), 344u);
  const Eigen::Matrix3Xd p = rig.SamplePositions(rig.neutral.positions_mm);
  double closest = 1e300;
  for (Eigen::Index i = 0; i < p.cols(); ++i) {
    for (Eigen::Index j = i + 1; j < p.cols(); ++j)
      closest = std::min(closest, (p.col(i) - p.col(j)).norm());
  }
  // Samples cover the front-facing part of the mesh (about half of it); a packing of 344 discs
  // over an area A has spacing ~sqrt(A / 344).
  const double bound = 0.5 * std::sqrt(0.5 * SurfaceAreaMm2(rig.neutral) / 344.0);
  std::printf("closest samples %.2f mm (bound %.2f mm)\n", closest, bound);
  EXPECT_GT(closest, bound);
  // Spread: samples in every major region.
  for (const char* region : {"forehead", "cheeks", "nose", "chin", "lips", "temples"}) {
    const std::set<int> vertices(rig.regions.at(region).begin(), rig.regions.at(region).end());
    int count = 0;
    for (const auto& s : rig.skin_samples) count += vertices.count(s.vertices[0]);
    EXPECT_GT(count, 0) << region;
  }
}

TEST(CompleteFaceAnatomy, MarkersAndStableRegions) {
  const FaceRig& rig = Face();
  ASSERT_EQ(rig.markers.size(), 150u);
  EXPECT_EQ(rig.markers.front().name, "m000");
  EXPECT_EQ(rig.markers.back().name, "m149");
  for (const auto& m : rig.markers) EXPECT_DOUBLE_EQ(m.diameter_mm, 2.0);
  EXPECT_EQ(rig.stable_regions, (std::vector<std::string>{"forehead", "nose_bridge", "temples"}));
}

TEST(CompleteFaceAnatomy, DeterministicGivenTheSeed) {
  FaceRig a = Face(), b = Face();
  AnatomyOptions options;
  options.seed = 7;
  ASSERT_TRUE(CompleteFaceAnatomy(options, &a).ok());
  ASSERT_TRUE(CompleteFaceAnatomy(options, &b).ok());
  ASSERT_EQ(a.skin_samples.size(), b.skin_samples.size());
  bool differs_from_default = false;
  for (size_t i = 0; i < a.skin_samples.size(); ++i) {
    EXPECT_EQ(a.skin_samples[i].vertices, b.skin_samples[i].vertices);
    differs_from_default |= a.skin_samples[i].vertices != Face().skin_samples[i].vertices;
  }
  EXPECT_TRUE(differs_from_default);
  EXPECT_EQ(a.skull.positions_mm, b.skull.positions_mm);
}

TEST(CompleteFaceAnatomy, RejectsBadOptionsAndMissingRegions) {
  FaceRig rig = Face();
  AnatomyOptions options;
  options.skin_sample_count = 0;
  Status status = CompleteFaceAnatomy(options, &rig);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("skin_sample_count"), std::string::npos);
  options = AnatomyOptions{};
  options.marker_count = -3;
  EXPECT_NE(options.Check().message().find("marker_count"), std::string::npos);
  options = AnatomyOptions{};
  options.skin_sample_count = 100000;
  status = CompleteFaceAnatomy(options, &rig);
  EXPECT_EQ(status.code(), StatusCode::kFailedPrecondition);
  rig.regions.erase("temples");
  status = CompleteFaceAnatomy(AnatomyOptions{}, &rig);
  EXPECT_EQ(status.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(status.message().find("temples"), std::string::npos);
}

TEST(BoundaryLoops, OnePatchHasOneLoop) {
  const Mesh patch = MakeEllipsoidPatch(80, 100, 90, 1.0, 0.8, 10, 8);
  const auto loops = BoundaryLoops(patch);
  ASSERT_EQ(loops.size(), 1u);
  EXPECT_EQ(loops[0].size(), 2u * (10 + 8));
  const std::vector<bool> boundary = BoundaryVertices(patch);
  EXPECT_EQ(std::count(boundary.begin(), boundary.end(), true), 2 * (10 + 8));
}

TEST(FarthestPointSample, PicksSpreadPointsDeterministically) {
  const Mesh patch = MakeEllipsoidPatch(80, 100, 90, 1.0, 0.8, 30, 30);
  std::vector<int> all(patch.vertex_count());
  for (int i = 0; i < patch.vertex_count(); ++i) all[i] = i;
  const auto a = FarthestPointSample(patch.positions_mm, all, 20, 3);
  EXPECT_EQ(a, FarthestPointSample(patch.positions_mm, all, 20, 3));
  EXPECT_EQ(a.front(), 3);
  EXPECT_EQ(std::set<int>(a.begin(), a.end()).size(), 20u);
}

TEST(FitHingeAngleRad, RecoversARigidRotation) {
  const Mesh patch = MakeEllipsoidPatch(60, 40, 80, 0.6, 0.5, 8, 8);
  const Eigen::Vector3d pivot(0, 40, -10);
  const double angle = 0.27;
  const Eigen::Matrix3d r = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitX()).toRotationMatrix();
  Eigen::Matrix3Xd deltas(3, patch.vertex_count());
  for (int v = 0; v < patch.vertex_count(); ++v) {
    const Eigen::Vector3d p = patch.positions_mm.col(v);
    deltas.col(v) = pivot + r * (p - pivot) - p;
  }
  EXPECT_NEAR(FitHingeAngleRad(patch.positions_mm, deltas, Eigen::Vector3d::UnitX(), pivot), angle,
              1e-12);
}

}  // namespace
}  // namespace facedyn::physics
