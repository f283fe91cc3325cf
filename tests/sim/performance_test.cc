// End-to-end physics checks on the procedural face (issue "Simulator I", Done means):
// quasistatic agreement without motion, impulse response of the cheeks, peak offsets by
// region on the platform, expression-dependent jiggle, resonance across 6-11 Hz, and the
// Take that `sim perform` writes.

#include "sim/performance.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>

#include "sim/expressions.h"
#include "sim/procedural_face.h"
#include "sim/sim_capture.h"
#include "tests/support/test_support.h"

namespace facedyn::sim {
namespace {

const FaceRig& Face() {
  static const FaceRig* rig = new FaceRig(MakeProceduralFace(ProceduralFaceOptions()).value());
  return *rig;
}

Take Perform(const std::string& expression, MotionKind motion, double hz, double seconds) {
  PerformanceOptions options;
  options.expression = expression;
  options.motion.kind = motion;
  options.motion.platform_hz = hz;
  options.seconds = seconds;
  auto take = SimulatePerformance(Face(), options);
  EXPECT_TRUE(take.ok()) << take.status().message();
  return take.ok() ? std::move(take).value() : Take();
}

// Mean over a region's vertices of the peak |dynamic_offset| after `skip_s`.
double MeanPeakOffset(const Take& take, const std::string& region, double skip_s) {
  const PointCache& offset = take.channels.at("dynamic_offset");
  const auto& vertices = Face().regions.at(region);
  double sum = 0;
  for (int v : vertices) {
    double peak = 0;
    for (int f = static_cast<int>(skip_s * take.info.fps); f < take.frame_count(); ++f) {
      peak = std::max(peak, double(offset.Frame(f).col(v).norm()));
    }
    sum += peak;
  }
  return sum / vertices.size();
}

// A held expression's take says from when it is held (take.json hold_start_s): the fade-ins of
// the expression (0.3 s) and the motion (0.25 s) plus the fixed settle margin, whatever the
// tissue (the true f0 and zeta never reach the metadata). After it the quasistatic skin barely
// changes in the skull frame (drift only); before it, it forms. Speech is never held.
TEST(SimulatePerformance, HeldExpressionRecordsWhenItIsHeld) {
  const Take take = Perform("smile", MotionKind::kPlatform, 8.0, 1.0);
  ASSERT_TRUE(take.info.hold_start_s.has_value());
  EXPECT_NEAR(*take.info.hold_start_s, 0.3 + kHeldExpressionSettleS, 1e-9);
  {
    PerformanceOptions softer;
    softer.expression = "smile";
    softer.motion.kind = MotionKind::kPlatform;
    softer.motion.platform_hz = 8.0;
    softer.seconds = 0.2;
    softer.tissue.fundamental_hz = 6.0;
    softer.tissue.damping_ratio = 0.1;
    auto other = SimulatePerformance(Face(), softer);
    ASSERT_TRUE(other.ok()) << other.status().message();
    EXPECT_EQ(other->info.hold_start_s, take.info.hold_start_s) << "the tissue's truth leaked";
  }
  const PointCache& quasistatic = take.channels.at("quasistatic");
  auto in_skull = [&](int f) {
    return take.world_from_skull[f].Inverse().Apply(quasistatic.Frame(f).cast<double>());
  };
  const int held = FirstHeldFrame(take);
  double onset_change = 0, held_change = 0;
  for (int f = 1; f < take.frame_count(); ++f) {
    const double change = (in_skull(f) - in_skull(f - 1)).colwise().norm().maxCoeff();
    (f <= held ? onset_change : held_change) =
        std::max(f <= held ? onset_change : held_change, change);
  }
  EXPECT_GT(onset_change, 0.05);  // mm per frame while the smile forms
  EXPECT_LT(held_change, 0.05 * onset_change) << onset_change << " " << held_change;
  EXPECT_FALSE(Perform("speech", MotionKind::kPlatform, 8.0, 0.5).info.hold_start_s.has_value());
  // HeldExpressionStartS is the same figure, from the options alone (what a capture writes).
  PerformanceOptions smile;
  smile.expression = "smile";
  smile.motion.kind = MotionKind::kPlatform;
  EXPECT_EQ(HeldExpressionStartS(smile), take.info.hold_start_s);
  smile.motion.kind = MotionKind::kNone;
  EXPECT_NEAR(*HeldExpressionStartS(smile), 0.3 + kHeldExpressionSettleS, 1e-12);
  smile.expression = "speech";
  EXPECT_FALSE(HeldExpressionStartS(smile).has_value());
}

// A capture's lead-in is trimmed off the simulated take: the held part's start moves with it,
// and never before the first frame.
TEST(TrimTake, ShiftsTheHeldPartWithTheFirstFrame) {
  const Take take = Perform("smile", MotionKind::kPlatform, 8.0, 1.0);
  ASSERT_TRUE(take.info.hold_start_s.has_value());
  const Take trimmed = TrimTake(take, 32);
  ASSERT_TRUE(trimmed.info.hold_start_s.has_value());
  EXPECT_NEAR(*trimmed.info.hold_start_s, *take.info.hold_start_s - 32 / take.info.fps, 1e-12);
  EXPECT_EQ(FirstHeldFrame(trimmed), FirstHeldFrame(take) - 32);
  EXPECT_EQ(*TrimTake(take, 100).info.hold_start_s, 0.0);
}

// What a head-mounted camera sees: the skin (and quasistatic channel) in the skull frame, the
// head's motion gone.
TEST(TakeInSkullFrame, RemovesTheHeadMotion) {
  const Take take = Perform("smile", MotionKind::kWalk, 8.0, 0.5);
  const Take in_skull = TakeInSkullFrame(take);
  ASSERT_EQ(in_skull.frame_count(), take.frame_count());
  ASSERT_TRUE(in_skull.channels.count("quasistatic"));
  double travel = 0.0;
  for (int f = 0; f < take.frame_count(); ++f) {
    travel = std::max(travel, take.world_from_skull[f].translation().norm());
    EXPECT_LT(in_skull.world_from_skull[f].translation().norm(), 1e-12);
    const Eigen::Matrix3Xd expected =
        take.world_from_skull[f].Inverse().Apply(take.FramePositions(f));
    EXPECT_LT((in_skull.FramePositions(f) - expected).cwiseAbs().maxCoeff(), 1e-3);
    const Eigen::Matrix3Xd q_world = take.channels.at("quasistatic").Frame(f).cast<double>();
    const Eigen::Matrix3Xd q_skull = in_skull.channels.at("quasistatic").Frame(f).cast<double>();
    EXPECT_LT((q_skull - take.world_from_skull[f].Inverse().Apply(q_world)).cwiseAbs().maxCoeff(),
              1e-3);
  }
  EXPECT_GT(travel, 1.0);  // the walk moved the head, so the test compares something
}

// A head-mounted camera's layout: only markers both cameras see nearly face-on, in the rig's
// order; a camera looking from behind sees none.
TEST(MarkersSeenByEveryCamera, KeepsTheFrontOfTheFace) {
  const auto rig = MakeProceduralFace(ProceduralFaceOptions());
  ASSERT_TRUE(rig.ok());
  capture::CameraRing ring;
  ring.count = 2;
  ring.width_px = 720;
  ring.height_px = 1280;
  ring.focal_px = 1300;
  ring.distance_mm = 250;
  ring.span_deg = 20;
  ring.elevation_deg = -10;
  ring.target_mm = Eigen::Vector3d(0, -15, 60);
  const std::vector<capture::CameraModel> cameras = ring.Cameras();
  const std::vector<Marker> seen = MarkersSeenByEveryCamera(*rig, cameras, 72.0);
  EXPECT_GT(seen.size(), 30u);
  EXPECT_LT(seen.size(), rig->markers.size() / 2);
  // In the rig's order, and every one in front (+Z) of the face's centre.
  size_t next = 0;
  const double centre_z = rig->neutral.positions_mm.row(2).mean();
  for (const Marker& m : seen) {
    while (next < rig->markers.size() && rig->markers[next].name != m.name) ++next;
    ASSERT_LT(next, rig->markers.size()) << m.name << " out of order";
    EXPECT_GT(m.point.Evaluate(rig->neutral.positions_mm).z(), centre_z) << m.name;
  }
  // A tighter angle keeps a subset.
  EXPECT_LT(MarkersSeenByEveryCamera(*rig, cameras, 50.0).size(), seen.size());
  ring.target_mm = Eigen::Vector3d(0, -15, 60);
  ring.distance_mm = 400;
  ring.span_deg = 20;
  std::vector<capture::CameraModel> behind = ring.Cameras();
  for (capture::CameraModel& camera : behind) {
    camera = capture::CameraModel::LookAt(camera.name, 720, 1280, 1300,
                                          Eigen::Vector3d(0, -15, -400), Eigen::Vector3d(0, -15, 60),
                                          Eigen::Vector3d::UnitY());
  }
  EXPECT_TRUE(MarkersSeenByEveryCamera(*rig, behind, 72.0).empty());
}

TEST(SimulatePerformance, NoMotionHeldExpressionIsQuasistatic) {
  const Take take = Perform("smile", MotionKind::kNone, 8.0, 1.5);
  const PointCache& quasistatic = take.channels.at("quasistatic");
  double worst = 0;
  for (int f = static_cast<int>(1.0 * take.info.fps); f < take.frame_count(); ++f) {
    worst = std::max(worst, double((take.positions.Frame(f) - quasistatic.Frame(f)).cwiseAbs().maxCoeff()));
  }
  EXPECT_LT(worst, 0.01);
}

TEST(SimulatePerformance, PlatformAt11HzJigglesCheeksNotForehead) {
  const Take take = Perform("neutral", MotionKind::kPlatform, 11.0, 2.5);
  const auto peaks = PeakOffsetByRegionMm(Face(), take, 1.0).value();
  // Zoss et al. 2020, Fig. 3: offsets up to about +-5 mm on soft regions.
  EXPECT_GE(peaks.at("cheeks"), 2.0);
  EXPECT_LE(peaks.at("cheeks"), 5.0);
  EXPECT_GE(peaks.at("mouth_corners"), 2.0);
  EXPECT_LE(peaks.at("mouth_corners"), 5.0);
  EXPECT_LT(peaks.at("forehead"), 0.5);
  EXPECT_LT(peaks.at("nose_bridge"), 0.5);
}

TEST(SimulatePerformance, SmileChangesCheekJiggle) {
  const double neutral = MeanPeakOffset(Perform("neutral", MotionKind::kPlatform, 11.0, 2.5), "cheeks", 1.0);
  const double smile = MeanPeakOffset(Perform("smile", MotionKind::kPlatform, 11.0, 2.5), "cheeks", 1.0);
  // Active flesh is stiffer (the muscle springs of soft_tissue.h), which moves its resonance
  // above the 11 Hz platform: a smile's cheeks jiggle less, by more than 20%.
  EXPECT_LT(smile, 0.8 * neutral) << "neutral " << neutral << " smile " << smile;
}

// Cheek offset per unit of head acceleration rises toward the configured 11 Hz resonance.
TEST(SimulatePerformance, ResponseFollowsTheResonance) {
  std::vector<double> gain;
  for (double hz : {6.0, 8.0, 11.0}) {
    const Take take = Perform("neutral", MotionKind::kPlatform, hz, 2.0);
    double head_min = 1e9, head_max = -1e9;
    for (int f = static_cast<int>(1.0 * take.info.fps); f < take.frame_count(); ++f) {
      head_min = std::min(head_min, take.world_from_skull[f].translation().y());
      head_max = std::max(head_max, take.world_from_skull[f].translation().y());
    }
    const double head_acceleration = 0.5 * (head_max - head_min) * std::pow(2 * M_PI * hz, 2);
    gain.push_back(MeanPeakOffset(take, "cheeks", 1.0) / head_acceleration);
  }
  EXPECT_LT(gain[0], gain[1]);
  EXPECT_LT(gain[1], gain[2]);
  // A single-DOF oscillator at 11 Hz with damping 0.22 predicts gain(11)/gain(6) =
  // |H(11)|/|H(6)| ~ 1.7 with |H(f)| = 1/sqrt((f0^2-f^2)^2 + (2 zeta f0 f)^2). The face has a
  // cluster of modes from 11 to ~12.5 Hz, which adds gain near 11 Hz and none at 6 Hz, so the
  // measured ratio may exceed the single-mode figure but not fall short of it.
  auto h = [](double f) { return 1.0 / std::hypot(121.0 - f * f, 2 * 0.22 * 11.0 * f); };
  const double relative = (gain[2] / gain[0]) / (h(11) / h(6));
  EXPECT_GT(relative, 0.85);
  EXPECT_LT(relative, 1.6);
}

TEST(SoftTissueModel, CheekImpulseResponseMatchesConfiguredFrequencyAndDamping) {
  physics::TissueOptions options;  // defaults: fundamental 11 Hz, damping ratio 0.22
  auto created = physics::SoftTissueModel::Create(Face(), options);
  ASSERT_TRUE(created.ok());
  physics::SoftTissueModel& model = **created;
  // dt = 2 ms: the calibration compensates Newmark's error for the calibrated mode at any step
  // (soft_tissue_test's ShippedStepShows... checks 1/128 s); a jolt also rings the modes around
  // it, whose residual error (omega dt)^2 / 12 minus the fundamental's is negligible at 2 ms.
  const double dt = 0.002;
  ASSERT_TRUE(model.SetReference(Eigen::VectorXd::Zero(Face().blendshape_names.size()), 0.0, dt).ok());
  physics::TissueForcing forcing;
  forcing.weights = Eigen::VectorXd::Zero(Face().blendshape_names.size());
  model.Reset(forcing);
  const auto& cheeks = Face().regions.at("cheeks");
  auto cheek_y = [&] {
    const Eigen::Matrix3Xd skin = model.DynamicSkin();
    double sum = 0;
    for (int v : cheeks) sum += skin(1, v);
    return sum / cheeks.size();
  };
  const double rest = cheek_y();
  std::vector<double> y;
  for (int step = 0; step < 400; ++step) {  // 0.8 s
    forcing.kinematics.origin_acceleration_in_skull = step < 3 ? Eigen::Vector3d(0, 2e4, 0) : Eigen::Vector3d::Zero();
    model.Step(forcing);
    y.push_back(cheek_y() - rest);
  }
  // After 0.15 s (higher modes gone): zero crossings give the frequency, the RMS envelope's
  // decay gives sigma = zeta omega.
  int crossings = 0, first = -1, last = -1;
  const int settle = static_cast<int>(0.15 / dt), end = static_cast<int>(0.75 / dt);
  for (int i = settle + 1; i < end; ++i) {
    if ((y[i - 1] < 0) != (y[i] < 0)) {
      if (first < 0) first = i;
      last = i;
      ++crossings;
    }
  }
  ASSERT_GE(crossings, 8);
  const double hz = (crossings - 1) / 2.0 / ((last - first) * dt);
  EXPECT_NEAR(hz, 11.0, 1.1);
  auto rms = [&](int from, int to) {
    double s = 0;
    for (int i = from; i < to; ++i) s += y[i] * y[i];
    return std::sqrt(s / (to - from));
  };
  const int window = static_cast<int>(std::lround(2.0 / 11.0 / dt));  // two periods
  const int later = settle + static_cast<int>(0.3 / dt);
  const double sigma = std::log(rms(settle, settle + window) / rms(later, later + window)) / 0.3;
  EXPECT_NEAR(sigma / (2 * M_PI * hz), 0.22, 0.022);
}

TEST(SimulatePerformance, WritesChannelsJawAndParameters) {
  const Take take = Perform("jaw_open", MotionKind::kWalk, 8.0, 0.5);
  EXPECT_EQ(take.frame_count(), 64);
  EXPECT_TRUE(take.Validate().ok());
  EXPECT_TRUE(take.channels.count("quasistatic"));
  EXPECT_TRUE(take.channels.count("dynamic_offset"));
  ASSERT_EQ(take.skull_from_jaw.size(), 64u);
  EXPECT_GT(take.skull_from_jaw.back().AngleRad(), 0.05);  // the jaw is open
  EXPECT_EQ(take.info.metadata["motion"]["kind"], "walk");
  EXPECT_EQ(take.info.metadata["expression"], "jaw_open");
  EXPECT_TRUE(take.info.metadata["tissue"].contains("fundamental_hz"));
  // dynamic_offset is skull_from_world (dynamic - quasistatic).
  const int f = 40;
  const Eigen::Matrix3Xd expected = take.world_from_skull[f].Inverse().Apply(take.FramePositions(f)) -
                                    take.world_from_skull[f].Inverse().Apply(
                                        take.channels.at("quasistatic").Frame(f).cast<double>());
  EXPECT_LT((expected - take.channels.at("dynamic_offset").Frame(f).cast<double>()).cwiseAbs().maxCoeff(), 1e-3);
}

TEST(SimulatePerformance, DeterministicForASeed) {
  const Take a = Perform("speech", MotionKind::kPlatform, 9.0, 0.4);
  const Take b = Perform("speech", MotionKind::kPlatform, 9.0, 0.4);
  EXPECT_EQ(a.positions.positions, b.positions.positions);
}

TEST(SimulatePerformance, BadOptionsNameTheField) {
  PerformanceOptions options;
  options.fps = 0;
  EXPECT_THAT(SimulatePerformance(Face(), options).status().message(), ::testing::HasSubstr("fps"));
  options = PerformanceOptions();
  options.expression = "grimace";
  EXPECT_THAT(SimulatePerformance(Face(), options).status().message(), ::testing::HasSubstr("grimace"));
}

}  // namespace
}  // namespace facedyn::sim
