// Quasistatic extraction, Eq. (5)-(6) of Zoss et al. 2020.

#include "dynamics/quasistatic.h"

#include <chrono>
#include <cmath>
#include <cstdio>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/mesh_primitives.h"
#include "eval/metrics.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"
#include "tests/support/test_support.h"

namespace facedyn::dynamics {
namespace {

constexpr double kPi = 3.14159265358979323846;

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

// positions(t) = T(t) * (rest + offset_in_skull(t)), offsets from `offset(t, vertex)`.
template <typename Offset>
Take HeldExpressionTake(const Mesh& rest, int frames, double fps, Offset offset) {
  Take take;
  take.info.fps = fps;
  take.topology = rest;
  take.world_from_skull = WobblingPoses(frames, fps);
  take.positions.vertex_count = rest.vertex_count();
  take.positions.positions.resize(3 * rest.vertex_count(), frames);
  for (int t = 0; t < frames; ++t) {
    Eigen::Matrix3Xd in_skull = rest.positions_mm;
    for (int v = 0; v < rest.vertex_count(); ++v) in_skull.col(v) += offset(t, v);
    take.positions.Frame(t) = take.world_from_skull[t].Apply(in_skull).cast<float>();
  }
  take.SetUniformTimes();
  return take;
}

// Largest distance (mm) between skull_from_world * y(t) and the rest shape over frames [a, b).
double MaxStabilisedError(const Take& estimate, const Mesh& rest, int a, int b) {
  double worst = 0;
  for (int t = a; t < b; ++t) {
    const Eigen::Matrix3Xd in_skull =
        estimate.world_from_skull[t].Inverse().Apply(estimate.FramePositions(t));
    worst = std::max(worst, (in_skull - rest.positions_mm).colwise().norm().maxCoeff());
  }
  return worst;
}

TEST(ExtractQuasistatic, RigidlyMovingHeldExpressionReturnsTheRestShape) {
  const Mesh rest = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 12, 10);
  const Take take = HeldExpressionTake(rest, 60, 128.0, [](int, int) { return Eigen::Vector3d::Zero(); });
  const auto result = ExtractQuasistatic(take, QuasistaticOptions());
  ASSERT_TRUE(result.ok()) << result.status().message();
  // Every frame, ends included (replicated frames are rigidly placed too). Float storage.
  EXPECT_LT(MaxStabilisedError(*result, rest, 0, 60), 1e-4);
  ASSERT_EQ(result->channels.count("dynamic_offset"), 1u);
  EXPECT_LT(result->channels.at("dynamic_offset").positions.cwiseAbs().maxCoeff(), 1e-4);
  EXPECT_EQ(result->info.source, "dynamics quasistatic");
  EXPECT_EQ(result->info.metadata.at("quasistatic_window_frames").get<int>(), 10);
  EXPECT_TRUE(result->Validate().ok()) << result->Validate().message();
}

TEST(ExtractQuasistatic, JiggleWithTheWindowPeriodAveragesOutExactly) {
  const Mesh rest = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 8, 8);
  const int w = 10;  // 128 fps, 80 ms
  // A jiggle whose period is exactly 2w+1 frames sums to zero over every full window.
  auto jiggle = [&](int t, int v) {
    const double phase = 2 * kPi * t / (2 * w + 1) + 0.1 * v;
    return Eigen::Vector3d(0.5 * std::sin(phase), 2.0 * std::cos(phase), -1.0 * std::sin(phase));
  };
  const Take take = HeldExpressionTake(rest, 80, 128.0, jiggle);
  const Take result = ExtractQuasistatic(take, QuasistaticOptions()).value();
  EXPECT_LT(MaxStabilisedError(result, rest, w, 80 - w), 1e-4);
  // dx of Eq. (6) recovers the jiggle (skull frame) away from the ends.
  const PointCache& offsets = result.channels.at("dynamic_offset");
  for (int t = w; t < 80 - w; t += 7) {
    for (int v = 0; v < rest.vertex_count(); v += 5) {
      EXPECT_EIGEN_NEAR(offsets.Frame(t).col(v).cast<double>(), jiggle(t, v), 1e-4);
    }
  }
  // At the ends the replicated frames do not cancel: the estimate is off, but finite.
  EXPECT_GT(MaxStabilisedError(result, rest, 0, 1), 1e-3);
}

// The held mean: a jiggle that is not periodic in any window (a walk-like mix of 1.3 Hz and
// 9.7 Hz, whole periods of neither in the take) is recovered exactly at every frame, ends
// included, up to the jiggle's own mean over the held frames; frames before the hold start
// neither count in the mean nor break it.
TEST(ExtractQuasistatic, HeldMeanRecoversAnyJiggleAboutTheHeldShape) {
  const Mesh rest = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 8, 8);
  const double fps = 128.0;
  auto jiggle = [&](int t, int v) {
    const double s = t / fps;
    return Eigen::Vector3d(0.4 * std::sin(2 * kPi * 1.3 * s + 0.1 * v),
                           1.5 * std::sin(2 * kPi * 9.7 * s), 0.3 * std::cos(2 * kPi * 1.3 * s));
  };
  Take take = HeldExpressionTake(rest, 200, fps, [&](int t, int v) {
    // Before the hold (frames < 32) the expression is still forming: 3 mm off, fading.
    Eigen::Vector3d forming(0.0, 0.0, 0.0);
    if (t < 32) forming.z() = 3.0 * (32 - t) / 32.0;
    return Eigen::Vector3d(jiggle(t, v) + forming);
  });
  take.info.hold_start_s = 32 / fps;
  QuasistaticOptions options;
  options.method = QuasistaticMethod::kHeldMean;
  const Take result = ExtractQuasistatic(take, options).value();
  EXPECT_EQ(result.info.metadata.at("quasistatic_method").get<std::string>(), "held-mean");
  // The jiggle's mean over the held frames, per vertex: what the held mean cannot tell apart.
  Eigen::Matrix3Xd mean = Eigen::Matrix3Xd::Zero(3, rest.vertex_count());
  for (int t = 32; t < 200; ++t) {
    for (int v = 0; v < rest.vertex_count(); ++v) mean.col(v) += jiggle(t, v) / 168.0;
  }
  const PointCache& offsets = result.channels.at("dynamic_offset");
  for (int t = 32; t < 200; t += 3) {
    for (int v = 0; v < rest.vertex_count(); v += 5) {
      EXPECT_EIGEN_NEAR(offsets.Frame(t).col(v).cast<double>(), jiggle(t, v) - mean.col(v), 2e-4);
    }
  }
  // The moving average cannot: its 80 ms window leaves most of the 1.3 Hz sway in y.
  const Take moving = ExtractQuasistatic(take, QuasistaticOptions()).value();
  EXPECT_GT(MaxStabilisedError(moving, rest, 40, 190), 0.2);
  take.info.hold_start_s = 300 / fps;
  EXPECT_THAT(ExtractQuasistatic(take, options).status().message(), ::testing::HasSubstr("no held frame"));
}

TEST(ExtractQuasistatic, ShortTakesAndWindowZero) {
  const Mesh rest = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 4, 4);
  for (int frames : {1, 3}) {
    const Take take = HeldExpressionTake(rest, frames, 128.0, [](int t, int) { return Eigen::Vector3d(t, 0, 0); });
    const auto result = ExtractQuasistatic(take, QuasistaticOptions());
    ASSERT_TRUE(result.ok()) << result.status().message();
    EXPECT_EQ(result->frame_count(), frames);
    EXPECT_TRUE(result->positions.positions.allFinite());
  }
  // 3 frames, w = 10: frame 0's window k = -10..10 reads frame 0 for k <= 0 (11 times),
  // frame 1 once and frame 2 for k = 2..10 (9 times).
  const Take take = HeldExpressionTake(rest, 3, 128.0, [](int t, int) { return Eigen::Vector3d(t, 0, 0); });
  const Take result = ExtractQuasistatic(take, QuasistaticOptions()).value();
  const double expected_x = (11 * 0.0 + 1 * 1.0 + 9 * 2.0) / 21.0;
  const Eigen::Vector3d in_skull = result.world_from_skull[0].Inverse() * result.FramePositions(0).col(0);
  EXPECT_NEAR(in_skull.x() - rest.positions_mm(0, 0), expected_x, 1e-4);
  // Window 0 is the identity.
  QuasistaticOptions none;
  none.window_s = 0.0;
  const Take same = ExtractQuasistatic(take, none).value();
  EXPECT_LT((same.positions.positions - take.positions.positions).cwiseAbs().maxCoeff(), 1e-4);
}

TEST(ExtractQuasistatic, RejectsBadOptionsAndPoseCounts) {
  QuasistaticOptions options;
  options.window_s = -1;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("window_s"));
  const Mesh rest = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 4, 4);
  Take take = HeldExpressionTake(rest, 5, 128.0, [](int, int) { return Eigen::Vector3d::Zero(); });
  take.world_from_skull.pop_back();
  const auto result = ExtractQuasistatic(take, QuasistaticOptions());
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result.status().message(), ::testing::HasSubstr("4 skull poses"));
}

TEST(PlatformSynchronous, WeightsPassAConstantAndCancelThePlatformAndItsHarmonics) {
  for (double hz : {6.0, 8.3, 11.0}) {
    const auto weights = PlatformSynchronousWeights(128.0, hz, 10, 2);
    ASSERT_TRUE(weights.ok()) << weights.status().message();
    ASSERT_EQ(weights->size(), 21u);
    double sum = 0, fundamental = 0, second = 0, third = 0;
    for (int k = -10; k <= 10; ++k) {
      const double h = (*weights)[k + 10];
      sum += h;
      fundamental += h * std::sin(2 * kPi * hz * k / 128.0 + 0.7);
      second += h * std::cos(2 * kPi * 2 * hz * k / 128.0 + 0.2);
      third += h * std::cos(2 * kPi * 3 * hz * k / 128.0);  // (a sine sums to 0 by symmetry)
    }
    EXPECT_NEAR(sum, 1.0, 1e-9) << hz;
    EXPECT_NEAR(fundamental, 0.0, 1e-9) << hz;
    EXPECT_NEAR(second, 0.0, 1e-9) << hz;
    EXPECT_GT(std::abs(third), 1e-6) << hz << " (the third harmonic is not fitted)";
  }
  EXPECT_THAT(PlatformSynchronousWeights(128.0, 40.0, 10, 2).status().message(),
              ::testing::HasSubstr("Nyquist"));
  EXPECT_THAT(PlatformSynchronousWeights(128.0, 0.01, 2, 2).status().message(),
              ::testing::HasSubstr("too short"));
}

TEST(PlatformSynchronous, ATrendOfDegreeTwoPassesAQuadraticExactly) {
  const int w = 12;  // 2.1 periods of 11 Hz at 128 fps
  const auto trend = PlatformSynchronousWeights(128.0, 11.0, w, 2, 2);
  const auto constant = PlatformSynchronousWeights(128.0, 11.0, w, 2, 0);
  ASSERT_TRUE(trend.ok()) << trend.status().message();
  ASSERT_TRUE(constant.ok()) << constant.status().message();
  auto moments = [&](const std::vector<double>& h) {
    Eigen::Vector4d m = Eigen::Vector4d::Zero();  // sum h, sum h k^2, fundamental, 2nd harmonic
    for (int k = -w; k <= w; ++k) {
      m(0) += h[k + w];
      m(1) += h[k + w] * k * k;
      m(2) += h[k + w] * std::cos(2 * kPi * 11.0 * k / 128.0 + 0.4);
      m(3) += h[k + w] * std::sin(2 * kPi * 22.0 * k / 128.0 + 1.1);
    }
    return m;
  };
  const Eigen::Vector4d with_trend = moments(*trend);
  EXPECT_NEAR(with_trend(0), 1.0, 1e-9);
  EXPECT_NEAR(with_trend(1), 0.0, 1e-7);  // a quadratic's centre value is reproduced
  EXPECT_NEAR(with_trend(2), 0.0, 1e-9);
  EXPECT_NEAR(with_trend(3), 0.0, 1e-9);
  // The constant fit smears a quadratic: its weights have a second moment.
  EXPECT_GT(std::abs(moments(*constant)(1)), 1.0);
  EXPECT_THAT(PlatformSynchronousWeights(128.0, 11.0, w, 2, 5).status().message(),
              ::testing::HasSubstr("trend_degree"));
  QuasistaticOptions options;
  options.trend_degree = -1;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("trend_degree"));
}

// An expression that changes on the platform (a slow quadratic drift of every vertex under an
// 11 Hz jiggle): the fit with a trend follows the drift, the constant lags it.
TEST(ExtractQuasistatic, PlatformSynchronousWithATrendFollowsAChangingExpression) {
  const Mesh rest = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 6, 6);
  const double hz = 11.0;
  auto drift = [](int t) {
    const double s = t / 128.0;
    return Eigen::Vector3d(12.0 * s * s, -8.0 * s * s + s, 6.0 * s * s);
  };
  Take take = HeldExpressionTake(rest, 120, 128.0, [&](int t, int v) -> Eigen::Vector3d {
    const double phase = 2 * kPi * hz * t / 128.0 + 0.1 * v;
    return drift(t) + Eigen::Vector3d(0.5 * std::sin(phase), 2.0 * std::cos(phase), 0.0);
  });
  take.info.platform_hz = hz;
  QuasistaticOptions options;
  options.method = QuasistaticMethod::kPlatformSynchronous;
  options.min_periods = 2.0;
  auto worst_error = [&](const Take& estimate) {
    const int w = estimate.info.metadata.at("quasistatic_window_frames").get<int>();
    double worst = 0;
    for (int t = w; t < 120 - w; ++t) {
      Eigen::Matrix3Xd truth = rest.positions_mm;
      truth.colwise() += drift(t);
      const Eigen::Matrix3Xd in_skull =
          estimate.world_from_skull[t].Inverse().Apply(estimate.FramePositions(t));
      worst = std::max(worst, (in_skull - truth).colwise().norm().maxCoeff());
    }
    return worst;
  };
  const double constant_mm = worst_error(ExtractQuasistatic(take, options).value());
  options.trend_degree = 2;
  const double trend_mm = worst_error(ExtractQuasistatic(take, options).value());
  EXPECT_LT(trend_mm, 1e-3);  // float storage
  EXPECT_GT(constant_mm, 0.02) << constant_mm;
  std::printf("worst error: constant %.4f mm, trend %.6f mm\n", constant_mm, trend_mm);
}

TEST(ExtractQuasistatic, PlatformSynchronousRemovesAJiggleTheMovingAverageCannot) {
  const Mesh rest = MakeEllipsoidPatch(75, 100, 90, 1.0, 0.8, 8, 8);
  // 11 Hz at 128 fps: the 21-frame box spans 1.8 periods and leaves part of the jiggle.
  const double hz = 11.0;
  auto jiggle = [&](int t, int v) {
    const double phase = 2 * kPi * hz * t / 128.0 + 0.1 * v;
    return Eigen::Vector3d(0.5 * std::sin(phase), 2.0 * std::cos(phase) + 0.3 * std::sin(2 * phase),
                           -1.0 * std::sin(phase));
  };
  Take take = HeldExpressionTake(rest, 120, 128.0, jiggle);
  QuasistaticOptions options;
  options.method = QuasistaticMethod::kPlatformSynchronous;
  // No frequency anywhere: a clear error naming it.
  EXPECT_THAT(ExtractQuasistatic(take, options).status().message(),
              ::testing::HasSubstr("platform_hz"));
  take.info.platform_hz = hz;
  const Take synchronous = ExtractQuasistatic(take, options).value();
  const Take box = ExtractQuasistatic(take, QuasistaticOptions()).value();
  const int w = synchronous.info.metadata.at("quasistatic_window_frames").get<int>();
  EXPECT_EQ(synchronous.info.metadata.at("quasistatic_method"), "platform-synchronous");
  EXPECT_EQ(synchronous.info.metadata.at("quasistatic_platform_hz").get<double>(), hz);
  EXPECT_LT(MaxStabilisedError(synchronous, rest, w, 120 - w), 1e-4);
  EXPECT_GT(MaxStabilisedError(box, rest, w, 120 - w), 0.05);
  // The options' frequency overrides the take's.
  options.platform_hz = 9.0;
  EXPECT_GT(MaxStabilisedError(ExtractQuasistatic(take, options).value(), rest, w, 120 - w), 0.05);
  options.harmonics = 0;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("harmonics"));
}

// The simulator's exact quasistatic channel as truth (4000 vertices, 1.5 s; one simulation
// keeps the test under 10 s).
class SimulatedTakes : public ::testing::Test {
 protected:
  static const FaceRig& Face() {
    static const FaceRig* rig = [] {
      sim::ProceduralFaceOptions options;
      options.target_vertex_count = 4000;
      return new FaceRig(sim::MakeProceduralFace(options).value());
    }();
    return *rig;
  }
  static Take Perform(sim::MotionKind kind, double hz, double seconds) {
    sim::PerformanceOptions options;
    options.motion.kind = kind;
    options.motion.platform_hz = hz;
    options.seconds = seconds;
    return sim::SimulatePerformance(Face(), options).value();
  }
};

TEST_F(SimulatedTakes, PlatformAt11HzMovingAverageBeatsNoRemoval) {
  const Take take = Perform(sim::MotionKind::kPlatform, 11.0, 1.5);
  const auto start = std::chrono::steady_clock::now();
  const Take estimate = ExtractQuasistatic(take, QuasistaticOptions()).value();
  const double extract_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  eval::EvaluateOptions options;
  options.skip_edge_frames = 64;  // skip the 0.25 s ramp-in plus the window
  const eval::Evaluation evaluation = eval::Evaluate(estimate, take, &take, &Face(), options).value();
  std::printf("%s", eval::EvaluationToText(evaluation).c_str());
  std::printf("extraction %.1f ms for %d frames x %d vertices\n", extract_s * 1e3,
              take.frame_count(), take.vertex_count());
  ASSERT_EQ(evaluation.reports.size(), 5u);  // prediction, 3 baselines, the low-pass oracle
  EXPECT_EQ(evaluation.reports[4].name, "lowpass_oracle");
  const eval::ErrorReport& moving_average = evaluation.reports[0];
  const eval::ErrorReport& no_removal = evaluation.reports[1];
  EXPECT_EQ(no_removal.name, "no_removal");
  EXPECT_LT(moving_average.face.mean_mm, 0.5 * no_removal.face.mean_mm);
  EXPECT_LT(moving_average.face.p95_mm, no_removal.face.p95_mm);
  EXPECT_LT(moving_average.regions.at("cheeks").mean_mm, 0.5 * no_removal.regions.at("cheeks").mean_mm);
  // The baseline of the same name is the same computation.
  EXPECT_NEAR(evaluation.reports[3].face.mean_mm, moving_average.face.mean_mm, 1e-6);
  // The dynamic offset channel is Eq. (6) of the estimate: x - y in the skull frame.
  const PointCache& dx = estimate.channels.at("dynamic_offset");
  const int t = 100;
  const Eigen::Matrix3Xd expected = take.world_from_skull[t].RotationMatrix().transpose() *
                                    (take.FramePositions(t) - estimate.FramePositions(t));
  EXPECT_EIGEN_NEAR(dx.Frame(t).cast<double>(), expected, 1e-4);

  // The platform-synchronous fit on the same take: the take knows its platform frequency.
  ASSERT_TRUE(take.info.platform_hz.has_value());
  QuasistaticOptions synchronous;
  synchronous.method = QuasistaticMethod::kPlatformSynchronous;
  const Take fitted = ExtractQuasistatic(take, synchronous).value();
  const eval::Evaluation fitted_evaluation = eval::Evaluate(fitted, take, nullptr, &Face(), options).value();
  std::printf("platform-synchronous: mean %.4f mm (moving average %.4f, no removal %.4f)\n",
              fitted_evaluation.reports[0].face.mean_mm, moving_average.face.mean_mm,
              no_removal.face.mean_mm);
  EXPECT_LT(fitted_evaluation.reports[0].face.mean_mm, 0.5 * moving_average.face.mean_mm);
}

}  // namespace
}  // namespace facedyn::dynamics
