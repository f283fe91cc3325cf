// The skull-frame metric and the lower reference (eval/skull_frame.h), on hand-built cases.

#include "eval/skull_frame.h"

#include <gtest/gtest.h>

#include <cmath>

namespace facedyn::eval {
namespace {

PointCache Points(int vertices, int frames) {
  PointCache cache;
  cache.vertex_count = vertices;
  cache.positions = Eigen::MatrixXf::Random(3 * vertices, frames) * 50.0f;
  return cache;
}

std::vector<Rigid3> Poses(int frames, double wobble_rad) {
  std::vector<Rigid3> poses;
  for (int t = 0; t < frames; ++t) {
    poses.push_back(Rigid3::FromAxisAngle(Eigen::Vector3d(0.2, 1, 0.1).normalized(),
                                          0.3 + wobble_rad * std::sin(0.7 * t),
                                          {10.0 * t, 2.0, -3.0}));
  }
  return poses;
}

// A constant offset between the estimated and the true skull frame costs nothing; a pose that
// jitters does, even when the world positions are exact.
TEST(SkullFrameMeanDistance, FixedOffsetIsFreeJitterIsNot) {
  const int frames = 40, vertices = 6;
  const std::vector<Rigid3> true_poses = Poses(frames, 0.0);
  // Points within 50 mm per axis of the skull origin, carried by the true skull.
  PointCache truth = Points(vertices, frames);
  for (int t = 0; t < frames; ++t) {
    truth.Frame(t) = true_poses[t].Apply(truth.Frame(t).cast<double>()).cast<float>();
  }
  const Rigid3 fixed = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), 0.05, {1.0, -2.0, 0.5});
  std::vector<Rigid3> estimated;
  for (const Rigid3& pose : true_poses) estimated.push_back(pose * fixed);
  const std::vector<int> all = {0, 1, 2, 3, 4, 5};
  const dynamics::FrameRange range{0, frames};
  EXPECT_TRUE(FixedSkullOffset(estimated, true_poses, range).IsApprox(fixed.Inverse(), 1e-9));
  EXPECT_NEAR(SkullFrameMeanDistance(truth, estimated, truth, true_poses, all, range), 0.0, 1e-4);
  // Jitter: the estimated skull rotates by +-1 mrad about the skull origin.
  std::vector<Rigid3> jittering;
  for (int t = 0; t < frames; ++t) {
    jittering.push_back(true_poses[t] *
                        Rigid3::FromAxisAngle(Eigen::Vector3d::UnitY(), t % 2 ? 1e-3 : -1e-3));
  }
  const double jitter_mm =
      SkullFrameMeanDistance(truth, jittering, truth, true_poses, all, range);
  // Points up to 87 mm from the origin move by at most 1 mrad of that (the fixed offset is
  // the identity here: the jitter averages out).
  EXPECT_GT(jitter_mm, 1e-3 * 5);
  EXPECT_LT(jitter_mm, 1e-3 * 87);
}

// Eq. 7 with the exact offsets undoes offsets applied in the same skull frame exactly.
// An estimate off the truth by a constant 0.3 mm along x plus +-0.1 mm along y alternating per
// frame (and a constant 0.02 degrees about z): the constant, the varying part and the total.
TEST(ScoreSkullPoses, SplitsConstantFromVarying) {
  std::vector<Rigid3> truth, estimate;
  const Rigid3 tilt = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitZ(), 0.02 * M_PI / 180.0);
  for (int f = 0; f < 10; ++f) {
    truth.push_back(Rigid3::FromAxisAngle(Eigen::Vector3d(1, 2, 3).normalized(), 0.1 * f,
                                          Eigen::Vector3d(5.0 * f, 1400, -20)));
    const double wobble = (f % 2 == 0) ? 0.1 : -0.1;
    estimate.push_back(truth.back() * Rigid3::FromTranslation(Eigen::Vector3d(0.3, wobble, 0)) *
                       tilt);
  }
  const SkullPoseError error = ScoreSkullPoses(estimate, truth, {2, 10});
  EXPECT_EQ(error.frames, 8);
  EXPECT_NEAR(error.origin_constant_mm, 0.3, 1e-9);
  EXPECT_NEAR(error.origin_varying_rms_mm, 0.1, 1e-9);
  EXPECT_NEAR(error.origin_rms_mm, std::sqrt(0.3 * 0.3 + 0.1 * 0.1), 1e-9);
  EXPECT_NEAR(error.origin_max_mm, std::sqrt(0.3 * 0.3 + 0.1 * 0.1), 1e-9);
  EXPECT_NEAR(error.rotation_constant_deg, 0.02, 1e-9);
  EXPECT_NEAR(error.rotation_varying_rms_deg, 0.0, 1e-9);
  EXPECT_NEAR(error.origin_mean_mm.x(), 0.3, 1e-9);
  const Json json = SkullPoseErrorJson(error);
  EXPECT_NEAR(json["origin_varying_rms_mm"].get<double>(), 0.1, 1e-9);
  EXPECT_EQ(ScoreSkullPoses(estimate, truth, {4, 4}).frames, 0);
}

TEST(RemoveExactOffsets, UndoesOffsetsRotatedByTheSkull) {
  const int frames = 10, vertices = 4;
  Take take;
  take.info.fps = 100;
  take.world_from_skull = Poses(frames, 0.2);
  const PointCache quasistatic = Points(vertices, frames);
  const PointCache offsets = Points(vertices, frames);
  take.positions = quasistatic;
  for (int t = 0; t < frames; ++t) {
    take.positions.Frame(t) +=
        take.world_from_skull[t].RotationMatrix().cast<float>() * offsets.Frame(t);
  }
  const PointCache removed = RemoveExactOffsets(take, offsets);
  EXPECT_LT((removed.positions - quasistatic.positions).cwiseAbs().maxCoeff(), 1e-3);
}

}  // namespace
}  // namespace facedyn::eval
