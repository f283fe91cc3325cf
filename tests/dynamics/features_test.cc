// Features of Zoss et al. 2020 (Eq. 1-4, 8) against hand-computed cases.

#include "dynamics/features.h"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/mesh_primitives.h"
#include "sim/procedural_face.h"
#include "tests/support/test_support.h"

namespace facedyn::dynamics {
namespace {

std::vector<SkullLandmark> FiveLandmarks() {
  return {{"b1", {0, 80, 60}}, {"b2", {-50, 20, 40}}, {"b3", {50, 20, 40}},
          {"b4", {0, -60, 50}}, {"b5", {0, 0, -80}}};
}

// A take of `mesh` moving rigidly with `world_from_skull` (positions = T(t) * rest).
Take RigidTake(const Mesh& mesh, const std::vector<Rigid3>& world_from_skull, double fps) {
  Take take;
  take.info.fps = fps;
  take.topology = mesh;
  take.world_from_skull = world_from_skull;
  const int frames = static_cast<int>(world_from_skull.size());
  take.positions.vertex_count = mesh.vertex_count();
  take.positions.positions.resize(3 * mesh.vertex_count(), frames);
  for (int t = 0; t < frames; ++t) {
    take.positions.Frame(t) = world_from_skull[t].Apply(mesh.positions_mm).cast<float>();
  }
  take.SetUniformTimes();
  return take;
}

// A wobbling, drifting head: rotation about a moving axis plus translation.
std::vector<Rigid3> WobblingPoses(int frames, double fps) {
  std::vector<Rigid3> poses;
  for (int t = 0; t < frames; ++t) {
    const double s = t / fps;
    const Eigen::Vector3d axis = Eigen::Vector3d(std::sin(3 * s), 1.0, 0.4).normalized();
    poses.push_back(Rigid3::FromAxisAngle(axis, 0.3 * std::sin(7 * s),
                                          {20 * std::sin(11 * s), 5 * s, 3 * std::cos(9 * s)}));
  }
  return poses;
}

std::vector<SurfacePoint> SomeSamples(const Mesh& mesh) {
  std::vector<SurfacePoint> samples;
  const Eigen::Matrix3Xi triangles = mesh.Triangles();
  for (Eigen::Index f = 0; f < triangles.cols(); f += 7) {
    samples.push_back({{triangles(0, f), triangles(1, f), triangles(2, f)}, {0.2, 0.3, 0.5}});
  }
  return samples;
}

TEST(WindowFrames, ConvertsEightyMillisecondsFromFps) {
  EXPECT_EQ(WindowFrames(0.08, 128.0), 10);
  EXPECT_EQ(WindowFrames(0.08, 96.0), 8);
  FeatureConfig config;
  EXPECT_EQ(config.window_frames(), 10);
  EXPECT_EQ(config.window_length(), 21);
  EXPECT_EQ(config.SkullDescriptorSize(5), 5 * 21 * 3);
  EXPECT_EQ(config.SkinDescriptorSize(), 63);
  config.fps = 96.0;
  EXPECT_EQ(config.window_frames(), 8);
}

TEST(FeatureConfig, CheckNamesTheField) {
  FeatureConfig config;
  EXPECT_TRUE(config.Check().ok());
  config.fps = 0;
  EXPECT_THAT(config.Check().message(), ::testing::HasSubstr("fps"));
  config = FeatureConfig();
  config.window_s = -0.1;
  EXPECT_THAT(config.Check().message(), ::testing::HasSubstr("window_s"));
  config = FeatureConfig();
  config.stretch_step_mm = 0;
  EXPECT_THAT(config.Check().message(), ::testing::HasSubstr("stretch_step_mm"));
}

TEST(SkullDescriptors, ConstantVelocityTranslationGivesConstantB) {
  const double fps = 128.0;
  const Eigen::Vector3d velocity_mm_s(30.0, -120.0, 45.0);
  const Rigid3 tilt = Rigid3::FromAxisAngle(Eigen::Vector3d(1, 2, 3).normalized(), 0.4);
  std::vector<Rigid3> poses;
  for (int t = 0; t < 60; ++t) {
    poses.push_back(Rigid3(tilt.rotation(), Eigen::Vector3d(1, 2, 3) + velocity_mm_s * (t / fps)));
  }
  FeatureConfig config;
  const auto b = SkullDescriptors(poses, FiveLandmarks(), config);
  ASSERT_TRUE(b.ok()) << b.status().message();
  ASSERT_EQ(b->rows(), 315);
  ASSERT_EQ(b->cols(), 60);
  // Eq. (2) is in the skull frame: the world velocity rotated back by the constant tilt.
  const Eigen::Vector3d expected = tilt.RotationMatrix().transpose() * velocity_mm_s;
  for (int t = 11; t < 49; ++t) {  // windows fully inside [1, F-1]
    for (int k = 0; k < 5 * 21; ++k) {
      EXPECT_EIGEN_NEAR((b->block<3, 1>(3 * k, t)), expected, 1e-8);
    }
  }
  // End policy: at t = 0 the offsets j <= 0 read frames <= 0, whose velocity is zero.
  for (int j = -10; j <= 10; ++j) {
    const Eigen::Vector3d v = b->block<3, 1>((j + 10) * 3, 0);
    EXPECT_EIGEN_NEAR(v, (j <= 0 ? Eigen::Vector3d::Zero() : expected), 1e-8);
  }
  // Past the last frame the take is held: zero velocity.
  EXPECT_EIGEN_NEAR((b->block<3, 1>(20 * 3, 59)), Eigen::Vector3d::Zero(), 1e-12);
  EXPECT_EIGEN_NEAR((b->block<3, 1>(10 * 3, 59)), expected, 1e-8);
}

TEST(SkullDescriptors, ConstantRotationGivesCrossProduct) {
  const double fps = 128.0;
  const double omega_rad_s = 2.0;
  std::vector<Rigid3> poses;
  for (int t = 0; t < 30; ++t) poses.push_back(Rigid3::FromAxisAngle(Eigen::Vector3d::UnitY(), omega_rad_s * t / fps));
  FeatureConfig config;
  config.window_s = 0.0;
  const auto landmarks = FiveLandmarks();
  const auto b = SkullDescriptors(poses, landmarks, config).value();
  ASSERT_EQ(b.rows(), 15);
  for (int i = 0; i < 5; ++i) {
    // [I - R(-omega dt)] b / dt, exactly.
    const Eigen::Vector3d& p = landmarks[i].position_in_skull;
    const Eigen::Vector3d expected =
        (p - Rigid3::FromAxisAngle(Eigen::Vector3d::UnitY(), -omega_rad_s / fps) * p) * fps;
    EXPECT_EIGEN_NEAR((b.block<3, 1>(3 * i, 15)), expected, 1e-8);
    // omega x b up to the backward difference's first-order error, omega^2 |b| dt / 2.
    const Eigen::Vector3d tangential = (omega_rad_s * Eigen::Vector3d::UnitY()).cross(p);
    EXPECT_LT((expected - tangential).norm(), 1.01 * omega_rad_s * omega_rad_s * p.norm() / (2 * fps));
  }
}

TEST(SkinDescriptors, RigidlyMovingFaceHasZeroStabilisedVelocity) {
  const double fps = 128.0;
  const Mesh mesh = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 12, 10);
  const Take take = RigidTake(mesh, WobblingPoses(50, fps), fps);
  const auto samples = SomeSamples(mesh);
  FeatureConfig config;
  const auto x = SkinDescriptors(take, samples, config);
  ASSERT_TRUE(x.ok()) << x.status().message();
  EXPECT_EQ(x->rows(), 63);
  EXPECT_EQ(x->cols(), 50 * static_cast<long>(samples.size()));
  // Positions are float (~1e-5 mm at 100 mm), velocities multiply by fps.
  EXPECT_LT(x->cwiseAbs().maxCoeff(), 0.01);
  // The same points' world velocity is large: stabilisation is what made it zero.
  const double world_speed = (take.positions.Frame(20) - take.positions.Frame(19)).norm() * fps;
  EXPECT_GT(world_speed, 100.0);
}

TEST(SkinDescriptors, WindowHoldsTheStabilisedVelocities) {
  const double fps = 96.0;
  Mesh mesh = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 4, 4);
  const int frames = 30;
  Take take = RigidTake(mesh, WobblingPoses(frames, fps), fps);
  // Vertex 0 slides along x in the skull frame at 24 mm/s (0.25 mm per frame).
  for (int t = 0; t < frames; ++t) {
    const Eigen::Vector3d in_skull = mesh.positions_mm.col(0) + Eigen::Vector3d(0.25 * t, 0, 0);
    take.positions.Frame(t).col(0) = (take.world_from_skull[t] * in_skull).cast<float>();
  }
  FeatureConfig config;
  config.fps = fps;
  const auto x = SkinDescriptors(take, {SurfacePoint::AtVertex(0)}, config).value();
  ASSERT_EQ(x.rows(), 17 * 3);
  for (int j = -8; j <= 8; ++j) {
    EXPECT_EIGEN_NEAR((x.block<3, 1>((j + 8) * 3, 15)), Eigen::Vector3d(24, 0, 0), 2e-3);
  }
}

TEST(SkinDescriptors, ShortTakesNeverReadOutOfBounds) {
  const Mesh mesh = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 4, 4);
  const auto samples = SomeSamples(mesh);
  FeatureConfig config;  // w = 10 >> take length
  for (int frames : {1, 2, 3}) {
    const Take take = RigidTake(mesh, WobblingPoses(frames, 128.0), 128.0);
    const auto x = SkinDescriptors(take, samples, config);
    ASSERT_TRUE(x.ok()) << x.status().message();
    EXPECT_EQ(x->cols(), frames * static_cast<long>(samples.size()));
    EXPECT_TRUE(x->allFinite());
    const auto b = SkullDescriptors(take.world_from_skull, FiveLandmarks(), config);
    ASSERT_TRUE(b.ok());
    EXPECT_EQ(b->cols(), frames);
    EXPECT_TRUE(b->allFinite());
    if (frames == 1) {
      EXPECT_EQ(b->cwiseAbs().maxCoeff(), 0.0);
    }
  }
}

TEST(SkinDescriptors, RefusesAnotherFpsAndBadSamples) {
  const Mesh mesh = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 4, 4);
  const Take take = RigidTake(mesh, WobblingPoses(5, 96.0), 96.0);
  FeatureConfig config;  // 128 fps
  const auto wrong_fps = SkinDescriptors(take, SomeSamples(mesh), config);
  ASSERT_FALSE(wrong_fps.ok());
  EXPECT_THAT(wrong_fps.status().message(), ::testing::HasSubstr("fps"));
  config.fps = 96.0;
  const auto bad_sample = SkinDescriptors(take, {SurfacePoint::AtVertex(10000)}, config);
  ASSERT_FALSE(bad_sample.ok());
  EXPECT_THAT(bad_sample.status().message(), ::testing::HasSubstr("vertex 10000"));
}

// A flat grid in the z = 0 plane, spacing 1 mm, uvs = positions / size.
FaceRig FlatGridRig(int n) {
  FaceRig rig;
  rig.name = "grid";
  Mesh& mesh = rig.neutral;
  mesh.positions_mm.resize(3, n * n);
  mesh.uvs.resize(2, n * n);
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) {
      mesh.positions_mm.col(r * n + c) = Eigen::Vector3d(c, r, 0);
      mesh.uvs.col(r * n + c) = Eigen::Vector2d(c, r) / (n - 1);
    }
  }
  for (int r = 0; r + 1 < n; ++r) {
    for (int c = 0; c + 1 < n; ++c) {
      const int a = r * n + c;
      mesh.AddFace({a, a + 1, a + n + 1}, {a, a + 1, a + n + 1});
      mesh.AddFace({a, a + n + 1, a + n}, {a, a + n + 1, a + n});
    }
  }
  return rig;
}

TEST(Stretch, UnstretchedIsZeroAndScaledPatchGivesKnownStretch) {
  FaceRig rig = FlatGridRig(21);
  const std::vector<SurfacePoint> samples = {SurfacePoint::AtVertex(10 * 21 + 10),
                                             {{50, 51, 72}, {0.3, 0.3, 0.4}},
                                             SurfacePoint::AtVertex(0)};  // corner: one-sided
  const auto stencil = BuildStretchStencil(rig, samples, 2.0);
  ASSERT_TRUE(stencil.ok()) << stencil.status().message();
  // The interior stencil spans 2 mm each side.
  EXPECT_NEAR(stencil->rest_length_mm(0, 0), 4.0, 1e-9);
  EXPECT_NEAR(stencil->rest_length_mm(1, 0), 4.0, 1e-9);
  const Eigen::Matrix3Xf neutral = rig.neutral.positions_mm.cast<float>();
  Eigen::VectorXd s(6);
  EvaluateStretch(*stencil, neutral, s.data());
  EXPECT_EIGEN_NEAR(s, Eigen::VectorXd::Zero(6), 1e-6);
  // Uniform scale by 1.1: stretch 0.1 in u and v everywhere.
  const Eigen::Matrix3Xf scaled = 1.1f * neutral;
  EvaluateStretch(*stencil, scaled, s.data());
  EXPECT_EIGEN_NEAR(s, Eigen::VectorXd::Constant(6, 0.1), 1e-6);
  // Stretch along x (u) by 1.25 only; moved rigidly it stays the same (rigid invariance).
  Eigen::Matrix3Xf along_u = neutral;
  along_u.row(0) *= 1.25f;
  const Eigen::Matrix3Xf moved =
      Rigid3::FromAxisAngle(Eigen::Vector3d::UnitZ(), 0.7, {5, 6, 7}).Apply(along_u.cast<double>()).cast<float>();
  EvaluateStretch(*stencil, moved, s.data());
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(s[2 * i], 0.25, 1e-5);
    EXPECT_NEAR(s[2 * i + 1], 0.0, 1e-5);
  }
}

TEST(Stretch, ProceduralFaceSamples) {
  sim::ProceduralFaceOptions options;
  options.target_vertex_count = 4000;
  const FaceRig rig = sim::MakeProceduralFace(options).value();
  const auto stencil = BuildStretchStencil(rig, rig.skin_samples, 2.0);
  ASSERT_TRUE(stencil.ok()) << stencil.status().message();
  EXPECT_EQ(stencil->sample_count(), static_cast<int>(rig.skin_samples.size()));
  // Steps are ~2 mm on each side (4 mm total) except near holes and borders.
  const double median_u = [&] {
    std::vector<double> v(stencil->rest_length_mm.row(0).data(),
                          stencil->rest_length_mm.row(0).data() + stencil->sample_count());
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  }();
  EXPECT_NEAR(median_u, 4.0, 0.5);
  Take take;
  take.info.fps = 128;
  take.topology = rig.neutral;
  take.positions.vertex_count = rig.vertex_count();
  take.positions.positions.resize(3 * rig.vertex_count(), 2);
  take.positions.Frame(0) = rig.neutral.positions_mm.cast<float>();
  take.positions.Frame(1) = (1.05 * rig.neutral.positions_mm).cast<float>();
  const auto s = StretchFeatures(take, *stencil);
  ASSERT_TRUE(s.ok()) << s.status().message();
  EXPECT_LT(s->col(0).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_LT((s->col(1).array() - 0.05).abs().maxCoeff(), 1e-5);
  // A smile stretches some samples by more than 5%.
  const Eigen::VectorXd smile_weights = Eigen::VectorXd::Unit(rig.blendshape_names.size(), rig.BlendshapeIndex("smile"));
  take.positions.Frame(1) = rig.Evaluate(smile_weights).cast<float>();
  const auto smile = StretchFeatures(take, *stencil).value();
  EXPECT_GT(smile.col(1).cwiseAbs().maxCoeff(), 0.05);
}

TEST(Stretch, NeedsUvsAndMatchingTakes) {
  FaceRig rig = FlatGridRig(5);
  rig.neutral.corner_uvs.clear();
  const auto no_uvs = BuildStretchStencil(rig, {SurfacePoint::AtVertex(12)}, 2.0);
  ASSERT_FALSE(no_uvs.ok());
  EXPECT_THAT(no_uvs.status().message(), ::testing::HasSubstr("UVs"));
  const FaceRig grid = FlatGridRig(5);
  const auto stencil = BuildStretchStencil(grid, {SurfacePoint::AtVertex(12)}, 1.0).value();
  Take take;
  take.positions.vertex_count = 7;
  take.positions.positions.resize(21, 1);
  const auto mismatch = StretchFeatures(take, stencil);
  ASSERT_FALSE(mismatch.ok());
  EXPECT_THAT(mismatch.status().message(), ::testing::HasSubstr("25 vertices"));
}

}  // namespace
}  // namespace facedyn::dynamics
