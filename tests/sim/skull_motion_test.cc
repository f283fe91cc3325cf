// SkullMotion: generated motions against their models (transmissibility, flight under gravity),
// numerical kinematics against analytic derivatives and independent finite differences, and the
// skull.csv-driven motion against its samples.
#include "sim/skull_motion.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <memory>
#include <vector>

#include "core/take.h"
#include "physics/body_transmissibility.h"
#include "tests/support/test_support.h"

namespace facedyn::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kG = 9810.0;

std::unique_ptr<SkullMotion> Make(const MotionOptions& options) {
  StatusOr<std::unique_ptr<SkullMotion>> motion = MakeSkullMotion(options);
  EXPECT_TRUE(motion.ok()) << motion.status().ToString();
  return motion.ok() ? std::move(motion).value() : nullptr;
}

MotionOptions OptionsFor(MotionKind kind) {
  MotionOptions options;
  options.kind = kind;
  return options;
}

// The rotation of a pose as a rotation vector (axis times angle, rad).
Eigen::Vector3d RotationVector(const Rigid3& pose) {
  const Eigen::AngleAxisd rotation(pose.rotation());
  return rotation.angle() * rotation.axis();
}

// Amplitude of the component at `hz` of samples x_i = x(t0 + i dt) (single-bin DFT); the window
// must hold a whole number of periods.
double AmplitudeAt(const std::vector<double>& x, double dt, double hz) {
  std::complex<double> sum = 0.0;
  for (size_t i = 0; i < x.size(); ++i) {
    sum +=
        x[i] * std::exp(std::complex<double>(0.0, -2.0 * kPi * hz * dt * static_cast<double>(i)));
  }
  return 2.0 * std::abs(sum) / static_cast<double>(x.size());
}

// Body angular velocity from rotation matrices by central differences: vee(R^T dR/dt).
Eigen::Vector3d AngularVelocityByDifferences(const SkullMotion& motion, double t, double h) {
  const Eigen::Matrix3d r = motion.WorldFromSkull(t).RotationMatrix();
  const Eigen::Matrix3d dr = (motion.WorldFromSkull(t + h).RotationMatrix() -
                              motion.WorldFromSkull(t - h).RotationMatrix()) /
                             (2.0 * h);
  const Eigen::Matrix3d omega = r.transpose() * dr;
  return 0.5 * Eigen::Vector3d(omega(2, 1) - omega(1, 2), omega(0, 2) - omega(2, 0),
                               omega(1, 0) - omega(0, 1));
}

Eigen::Vector3d WorldAccelerationByDifferences(const SkullMotion& motion, double t, double h) {
  return (motion.WorldFromSkull(t + h).translation() -
          2.0 * motion.WorldFromSkull(t).translation() +
          motion.WorldFromSkull(t - h).translation()) /
         (h * h);
}

// Test motions with known derivatives.
class SinusoidalTranslation : public SkullMotion {
 public:
  static constexpr double kAmplitudeMm = 3.0, kHz = 9.0;
  const Eigen::Quaterniond rotation{Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())};
  const Eigen::Vector3d direction = Eigen::Vector3d(0.3, 1.0, -0.2).normalized();
  Rigid3 WorldFromSkull(double t) const override {
    return Rigid3(rotation, kAmplitudeMm * std::sin(2 * kPi * kHz * t) * direction);
  }
};

class ConstantRateRotation : public SkullMotion {
 public:
  static constexpr double kRateRadPerS = 3.0, kRadiusMm = 100.0;
  Rigid3 WorldFromSkull(double t) const override {
    // world_from_skull = Rot_Y(w t) * Translate(r, 0, 0): the origin circles the Y axis.
    return Rigid3::FromAxisAngle(Eigen::Vector3d::UnitY(), kRateRadPerS * t) *
           Rigid3::FromTranslation(Eigen::Vector3d(kRadiusMm, 0, 0));
  }
};

TEST(MakeSkullMotion, NoneIsIdentity) {
  const auto motion = Make(OptionsFor(MotionKind::kNone));
  ASSERT_NE(motion, nullptr);
  for (double t : {-1.0, 0.0, 0.37, 5.0, 100.0}) {
    EXPECT_TRUE(motion->WorldFromSkull(t).IsApprox(Rigid3::Identity(), 0.0)) << "t = " << t;
    const physics::SkullKinematics k = motion->Kinematics(t);
    EXPECT_EIGEN_NEAR(k.origin_acceleration_in_skull, Eigen::Vector3d::Zero(), 0.0);
    EXPECT_EIGEN_NEAR(k.angular_velocity_in_skull, Eigen::Vector3d::Zero(), 0.0);
    EXPECT_EIGEN_NEAR(k.angular_acceleration_in_skull, Eigen::Vector3d::Zero(), 0.0);
    EXPECT_EIGEN_NEAR(k.GravityInSkull(), physics::kGravityInWorld, 0.0);
  }
}

TEST(BodyTransmissibility, ResonanceAmplifiesAndHighFrequenciesAttenuate) {
  const MotionOptions o;
  const auto t = [&o](double hz) {
    return physics::BodyTransmissibility(hz, o.body_resonance_hz, o.body_damping_ratio);
  };
  EXPECT_NEAR(std::abs(t(1e-6)), 1.0, 1e-9);
  EXPECT_GT(std::abs(t(o.body_resonance_hz)), 1.0);
  EXPECT_LT(std::abs(t(11.0)), std::abs(t(6.0)));
  EXPECT_LT(std::abs(t(11.0)), 1.0);
  // Above resonance the head lags the platform.
  EXPECT_LT(std::arg(t(8.0)), 0.0);
  // The single-DOF closed form at r = 1: sqrt(1 + (2 zeta)^2) / (2 zeta).
  const double two_zeta = 2.0 * o.body_damping_ratio;
  EXPECT_NEAR(std::abs(t(o.body_resonance_hz)), std::sqrt(1 + two_zeta * two_zeta) / two_zeta,
              1e-12);
}

TEST(PlatformMotion, VerticalMotionIsTransmittedPlatformSinusoid) {
  for (double hz : {6.0, 8.0, 11.0}) {
    MotionOptions o;
    o.platform_hz = hz;
    const auto motion = Make(o);
    ASSERT_NE(motion, nullptr);
    // 4 s after the ramp-in, sampled at 1 kHz: a whole number of periods at every frequency
    // tried, so each DFT bin on the 0.25 Hz grid is leak-free.
    const double dt = 1e-3;
    std::vector<double> y;
    for (int i = 0; i < 4000; ++i)
      y.push_back(motion->WorldFromSkull(1.0 + i * dt).translation().y());
    double best_hz = 0.0, best = 0.0;
    for (double f = 1.0; f <= 30.0; f += 0.25) {
      const double a = AmplitudeAt(y, dt, f);
      if (a > best) best = a, best_hz = f;
    }
    EXPECT_DOUBLE_EQ(best_hz, hz);
    const double expected =
        std::abs(physics::BodyTransmissibility(hz, o.body_resonance_hz, o.body_damping_ratio)) *
        o.amplitude_mm;
    EXPECT_NEAR(best, expected, 0.02 * expected) << hz << " Hz";
    // Peak of the time series as well (the vertical channel is the sinusoid alone).
    const double peak =
        std::max(*std::max_element(y.begin(), y.end()), -*std::min_element(y.begin(), y.end()));
    EXPECT_NEAR(peak, expected, 0.02 * expected) << hz << " Hz";
  }
}

TEST(PlatformMotion, StartsAtRestAndRampsInSmoothly) {
  const auto motion = Make(MotionOptions());
  ASSERT_NE(motion, nullptr);
  EXPECT_TRUE(motion->WorldFromSkull(0.0).IsApprox(Rigid3::Identity(), 1e-15));
  EXPECT_TRUE(motion->WorldFromSkull(-0.5).IsApprox(Rigid3::Identity(), 1e-15));
  // C2 at t = 0: the acceleration grows from zero instead of jumping.
  EXPECT_LT(motion->Kinematics(0.0).origin_acceleration_in_skull.norm(), 1.0);
  EXPECT_LT(motion->Kinematics(0.002).origin_acceleration_in_skull.norm(), 100.0);
  EXPECT_GT(motion->Kinematics(0.5).origin_acceleration_in_skull.norm(), 1000.0);
}

TEST(PlatformMotion, PitchAndSwayAreSmall) {
  const auto motion = Make(MotionOptions());
  ASSERT_NE(motion, nullptr);
  double max_angle = 0.0, max_horizontal = 0.0;
  for (double t = 0.5; t < 10.0; t += 1e-3) {
    const Rigid3 pose = motion->WorldFromSkull(t);
    max_angle = std::max(max_angle, pose.AngleRad());
    max_horizontal = std::max(max_horizontal, std::abs(pose.translation().x()));
    max_horizontal = std::max(max_horizontal, std::abs(pose.translation().z()));
  }
  // Nod ~0.3 degrees at 8 Hz plus postural tilt ~0.1 degrees.
  EXPECT_GT(max_angle, 0.2 * kPi / 180.0);
  EXPECT_LT(max_angle, 0.6 * kPi / 180.0);
  EXPECT_GT(max_horizontal, 0.5);
  EXPECT_LE(max_horizontal, MotionOptions().sway_mm + 1e-9);
}

TEST(SkullMotionKinematics, MatchesAnalyticForSinusoidalTranslation) {
  const SinusoidalTranslation motion;
  const double w = 2 * kPi * SinusoidalTranslation::kHz;
  for (double t : {0.0, 0.013, 0.1, 0.377, 2.5}) {
    const physics::SkullKinematics k = motion.Kinematics(t);
    const Eigen::Vector3d a_world =
        -w * w * SinusoidalTranslation::kAmplitudeMm * std::sin(w * t) * motion.direction;
    const double scale = w * w * SinusoidalTranslation::kAmplitudeMm;  // ~9600 mm/s^2
    EXPECT_EIGEN_NEAR(k.origin_acceleration_in_skull, motion.rotation.conjugate() * a_world,
                      1e-6 * scale);
    EXPECT_EIGEN_NEAR(k.angular_velocity_in_skull, Eigen::Vector3d::Zero(), 1e-9);
    EXPECT_EIGEN_NEAR(k.angular_acceleration_in_skull, Eigen::Vector3d::Zero(), 1e-6);
  }
}

TEST(SkullMotionKinematics, MatchesAnalyticForConstantRateRotation) {
  const ConstantRateRotation motion;
  const double w = ConstantRateRotation::kRateRadPerS, r = ConstantRateRotation::kRadiusMm;
  for (double t : {0.0, 0.21, 1.0, 3.7}) {
    const physics::SkullKinematics k = motion.Kinematics(t);
    EXPECT_EIGEN_NEAR(k.angular_velocity_in_skull, Eigen::Vector3d(0, w, 0), 1e-9);
    EXPECT_EIGEN_NEAR(k.angular_acceleration_in_skull, Eigen::Vector3d::Zero(), 1e-5);
    // Centripetal: w^2 r towards the axis, i.e. along -X of the skull (900 mm/s^2).
    EXPECT_EIGEN_NEAR(k.origin_acceleration_in_skull, Eigen::Vector3d(-w * w * r, 0, 0),
                      1e-6 * w * w * r);
  }
}

// Independent references: 3-point differences of the translation, and angular velocity from
// rotation matrices (differenced again for the angular acceleration). Sampled after the ramp-in:
// the ramp is C2, so its third derivative jumps at 0 and ramp_in_s and every difference
// formula straddling those instants is off by O(h * jump); that window is checked on its own
// with a tolerance that reflects it.
TEST(SkullMotionKinematics, AgreesWithFiniteDifferencesForGaits) {
  for (MotionKind kind : {MotionKind::kWalk, MotionKind::kRun, MotionKind::kJump,
                          MotionKind::kPlatform, MotionKind::kNod, MotionKind::kShake}) {
    SCOPED_TRACE(MotionKindName(kind));
    const auto motion = Make(OptionsFor(kind));
    ASSERT_NE(motion, nullptr);
    const auto compare = [&motion](double t0, double t1, double* error_a, double* max_a,
                                   double* error_w, double* error_alpha) {
      *error_a = *max_a = *error_w = *error_alpha = 0.0;
      for (double t = t0; t < t1; t += 0.0037) {
        const physics::SkullKinematics k = motion->Kinematics(t);
        const Eigen::Matrix3d r = k.world_from_skull.RotationMatrix();
        const Eigen::Vector3d a = r.transpose() * WorldAccelerationByDifferences(*motion, t, 2e-4);
        *error_a = std::max(*error_a, (k.origin_acceleration_in_skull - a).norm());
        *max_a = std::max(*max_a, a.norm());
        const double h = 1e-4;
        *error_w = std::max(
            *error_w,
            (k.angular_velocity_in_skull - AngularVelocityByDifferences(*motion, t, h)).norm());
        const Eigen::Vector3d alpha = (AngularVelocityByDifferences(*motion, t + 2e-4, h) -
                                       AngularVelocityByDifferences(*motion, t - 2e-4, h)) /
                                      4e-4;
        *error_alpha = std::max(*error_alpha, (k.angular_acceleration_in_skull - alpha).norm());
      }
    };
    double error_a, max_a, error_w, error_alpha;
    compare(0.3, 3.0, &error_a, &max_a, &error_w, &error_alpha);
    EXPECT_GT(max_a, 500.0);  // shake: the origin is 20 mm off the yaw axis, ~830 mm/s^2
    EXPECT_LT(error_a, 1e-3 * max_a);
    EXPECT_LT(error_w, 5e-6);  // the reference's own error: h^2 w''' / 6 ~ 1e-6 at 8 Hz
    EXPECT_LT(error_alpha, 1e-3);
    compare(-0.01, 0.3, &error_a, &max_a, &error_w, &error_alpha);
    EXPECT_LT(error_a, 1e-2 * max_a);
    EXPECT_LT(error_w, 1e-5);
    EXPECT_LT(error_alpha, 0.1);
  }
}

TEST(JumpMotion, FallsFreelyDuringFlightAndIsPushedOnlyUpward) {
  const MotionOptions o = OptionsFor(MotionKind::kJump);
  const auto motion = Make(o);
  ASSERT_NE(motion, nullptr);
  int samples = 0, free_fall = 0;
  double min_a = 1e9, max_a = -1e9, min_y = 1e9, max_y = -1e9;
  for (double t = 1.0; t < 1.0 + 4 * o.jump_period_s; t += 1e-3, ++samples) {  // 4 jumps
    const physics::SkullKinematics k = motion->Kinematics(t);
    const double a_y = (k.world_from_skull.rotation() * k.origin_acceleration_in_skull).y();
    if (std::abs(a_y + kG) < 1e-3 * kG) ++free_fall;
    min_a = std::min(min_a, a_y);
    max_a = std::max(max_a, a_y);
    min_y = std::min(min_y, k.world_from_skull.translation().y());
    max_y = std::max(max_y, k.world_from_skull.translation().y());
  }
  const double flight_share = o.jump_flight_s / o.jump_period_s;
  EXPECT_NEAR(static_cast<double>(free_fall) / samples, flight_share, 0.01);
  EXPECT_GE(min_a, -kG - 2.0);  // the ground pushes, never pulls (2 mm/s^2: differencing)
  EXPECT_GT(max_a, 2.0 * kG);   // landing and push-off
  // Rise during flight: g F^2 / 8 = 196 mm; the squat adds to the total excursion.
  EXPECT_GT(max_y - min_y, kG * o.jump_flight_s * o.jump_flight_s / 8.0);
  EXPECT_LT(max_y - min_y, 600.0);
}

TEST(RunMotion, BouncesWithFlightAndSharpImpacts) {
  const MotionOptions o = OptionsFor(MotionKind::kRun);
  const auto motion = Make(o);
  ASSERT_NE(motion, nullptr);
  double min_y = 1e9, max_y = -1e9, max_a = -1e9;
  int free_fall = 0, samples = 0;
  for (double t = 1.0; t < 1.0 + 6 / o.run_step_hz; t += 1e-3, ++samples) {  // 6 steps
    const physics::SkullKinematics k = motion->Kinematics(t);
    const double a_y = (k.world_from_skull.rotation() * k.origin_acceleration_in_skull).y();
    if (std::abs(a_y + kG) < 1e-3 * kG) ++free_fall;
    max_a = std::max(max_a, a_y);
    min_y = std::min(min_y, k.world_from_skull.translation().y());
    max_y = std::max(max_y, k.world_from_skull.translation().y());
  }
  EXPECT_NEAR(static_cast<double>(free_fall) / samples, o.run_flight_s * o.run_step_hz, 0.01);
  EXPECT_GT(max_y - min_y, 60.0);
  EXPECT_LT(max_y - min_y, 110.0);
  EXPECT_GT(max_a, 1.5 * kG);
  EXPECT_LT(max_a, 4.0 * kG);
  // Mean forward speed.
  const double z0 = motion->WorldFromSkull(1.0).translation().z();
  const double z1 = motion->WorldFromSkull(1.0 + 10.0 / o.run_step_hz).translation().z();
  EXPECT_NEAR((z1 - z0) / (10.0 / o.run_step_hz), o.run_speed_mm_per_s,
              1e-6 * o.run_speed_mm_per_s);
}

TEST(WalkMotion, BobsAndProgressesForward) {
  const MotionOptions o = OptionsFor(MotionKind::kWalk);
  const auto motion = Make(o);
  ASSERT_NE(motion, nullptr);
  double min_y = 1e9, max_y = -1e9, min_x = 1e9, max_x = -1e9;
  for (double t = 1.0; t < 5.0; t += 1e-3) {
    const Eigen::Vector3d p = motion->WorldFromSkull(t).translation();
    min_y = std::min(min_y, p.y()), max_y = std::max(max_y, p.y());
    min_x = std::min(min_x, p.x()), max_x = std::max(max_x, p.x());
  }
  EXPECT_NEAR(max_y - min_y, o.walk_vertical_mm, 0.3 * o.walk_vertical_mm);
  EXPECT_NEAR(max_x - min_x, o.walk_lateral_mm, 0.05 * o.walk_lateral_mm);
  const double stride_s = 2.0 / o.walk_step_hz;
  const double dz = motion->WorldFromSkull(1.0 + 3 * stride_s).translation().z() -
                    motion->WorldFromSkull(1.0).translation().z();
  EXPECT_NEAR(dz / (3 * stride_s), o.walk_speed_mm_per_s, 1e-6 * o.walk_speed_mm_per_s);
}

TEST(MakeSkullMotion, SameSeedSameMotionOtherSeedOtherMotion) {
  for (MotionKind kind :
       {MotionKind::kPlatform, MotionKind::kWalk, MotionKind::kRun, MotionKind::kJump}) {
    MotionOptions o = OptionsFor(kind);
    const auto a = Make(o);
    const auto b = Make(o);
    o.seed = 2;
    const auto c = Make(o);
    ASSERT_TRUE(a && b && c);
    double same = 0.0, different = 0.0;
    for (double t = 0.0; t < 3.0; t += 0.01) {
      same = std::max(same, (a->WorldFromSkull(t).ToMatrix4() - b->WorldFromSkull(t).ToMatrix4())
                                .cwiseAbs()
                                .maxCoeff());
      different =
          std::max(different, (a->WorldFromSkull(t).ToMatrix4() - c->WorldFromSkull(t).ToMatrix4())
                                  .cwiseAbs()
                                  .maxCoeff());
    }
    EXPECT_EQ(same, 0.0) << MotionKindName(kind);
    EXPECT_GT(different, 0.1) << MotionKindName(kind);
  }
}

TEST(FileMotion, ReproducesSamplesAndInterpolatesSmoothly) {
  const auto walk = Make(OptionsFor(MotionKind::kWalk));
  ASSERT_NE(walk, nullptr);
  // Uneven sample times around 100 Hz.
  std::vector<double> times;
  std::vector<Rigid3> poses;
  for (int i = 0; i < 300; ++i) {
    times.push_back(0.01 * i + 0.003 * std::sin(1.7 * i));
    poses.push_back(walk->WorldFromSkull(times.back()));
  }
  facedyn::testing::TempDir dir;
  const std::string path = dir.Join("skull.csv");
  ASSERT_TRUE(WriteTransformCsv(path, times, poses).ok());
  MotionOptions o = OptionsFor(MotionKind::kFile);
  o.file = path;
  const auto motion = Make(o);
  ASSERT_NE(motion, nullptr);
  for (size_t i = 0; i < times.size(); ++i) {
    // The CSV stores decimals, so compare with what was read back, ~1e-9.
    EXPECT_TRUE(motion->WorldFromSkull(times[i]).IsApprox(poses[i], 1e-6)) << "sample " << i;
  }
  // Between samples it follows the original motion closely.
  double max_mm = 0.0, max_rad = 0.0;
  for (double t = 0.5; t < 2.9; t += 0.0013) {
    const Rigid3 difference = walk->WorldFromSkull(t).Inverse() * motion->WorldFromSkull(t);
    max_mm = std::max(max_mm, difference.translation().norm());
    max_rad = std::max(max_rad, difference.AngleRad());
  }
  EXPECT_LT(max_mm, 0.05);
  EXPECT_LT(max_rad, 1e-4);
  // C1: the angular velocity is continuous across a sample.
  for (size_t i : {50u, 123u, 250u}) {
    const double eps = 1e-6;
    const auto one_sided = [&](double t0, double t1) {
      const Eigen::Matrix3d r0 = motion->WorldFromSkull(t0).RotationMatrix();
      const Eigen::Matrix3d omega =
          r0.transpose() * (motion->WorldFromSkull(t1).RotationMatrix() - r0) / (t1 - t0);
      return Eigen::Vector3d(omega(2, 1) - omega(1, 2), omega(0, 2) - omega(2, 0),
                             omega(1, 0) - omega(0, 1)) *
             0.5;
    };
    const Eigen::Vector3d left = one_sided(times[i] - eps, times[i]);
    const Eigen::Vector3d right = one_sided(times[i], times[i] + eps);
    EXPECT_EIGEN_NEAR(left, right, 1e-4);
  }
  // Held beyond the ends.
  EXPECT_TRUE(motion->WorldFromSkull(-1.0).IsApprox(motion->WorldFromSkull(times.front()), 1e-12));
  EXPECT_TRUE(motion->WorldFromSkull(99.0).IsApprox(motion->WorldFromSkull(times.back()), 1e-12));
}

TEST(FileMotion, ExactForConstantRateRotationAndVelocity) {
  const Eigen::Vector3d axis = Eigen::Vector3d(1, -2, 0.5).normalized();
  const double rate = 2.0;
  const Eigen::Vector3d velocity(10, -20, 300);
  const auto truth = [&](double t) { return Rigid3::FromAxisAngle(axis, rate * t, velocity * t); };
  std::vector<double> times = {0.0, 0.05, 0.08, 0.2, 0.21, 0.4, 0.55};
  std::vector<Rigid3> poses;
  for (double t : times) poses.push_back(truth(t));
  facedyn::testing::TempDir dir;
  MotionOptions o = OptionsFor(MotionKind::kFile);
  o.file = dir.Join("skull.csv");
  ASSERT_TRUE(WriteTransformCsv(o.file, times, poses).ok());
  const auto motion = Make(o);
  ASSERT_NE(motion, nullptr);
  for (double t = 0.0; t <= 0.55; t += 0.0071) {
    EXPECT_TRUE(motion->WorldFromSkull(t).IsApprox(truth(t), 1e-6)) << "t = " << t;
  }
  const physics::SkullKinematics k = motion->Kinematics(0.3);
  EXPECT_EIGEN_NEAR(k.angular_velocity_in_skull, rate * axis, 1e-5);
}

TEST(FileMotion, BadFileErrorNamesTheFile) {
  facedyn::testing::TempDir dir;
  MotionOptions o = OptionsFor(MotionKind::kFile);
  o.file = dir.Join("broken_skull.csv");
  facedyn::testing::WriteBytes(o.file, "frame,time_s,qw,qx,qy,qz,tx,ty,tz\n0,0,1,0,0,0,1,2\n");
  StatusOr<std::unique_ptr<SkullMotion>> motion = MakeSkullMotion(o);
  ASSERT_FALSE(motion.ok());
  EXPECT_NE(motion.status().message().find("broken_skull.csv"), std::string::npos)
      << motion.status().ToString();

  o.file = dir.Join("missing_skull.csv");
  motion = MakeSkullMotion(o);
  ASSERT_FALSE(motion.ok());
  EXPECT_NE(motion.status().message().find("missing_skull.csv"), std::string::npos)
      << motion.status().ToString();

  o.file = dir.Join("header_only.csv");
  facedyn::testing::WriteBytes(o.file, "frame,time_s,qw,qx,qy,qz,tx,ty,tz\n");
  motion = MakeSkullMotion(o);
  ASSERT_FALSE(motion.ok());
  EXPECT_NE(motion.status().message().find("header_only.csv"), std::string::npos)
      << motion.status().ToString();
}

TEST(MotionOptionsCheck, ErrorsNameTheField) {
  EXPECT_TRUE(MotionOptions().Check().ok());
  const auto expect_field = [](MotionOptions o, const std::string& field) {
    const Status status = o.Check();
    EXPECT_FALSE(status.ok()) << field;
    EXPECT_NE(status.message().find(field), std::string::npos) << status.ToString();
    EXPECT_FALSE(MakeSkullMotion(o).ok()) << field;
  };
  MotionOptions o;
  o.platform_hz = -1;
  expect_field(o, "platform_hz");
  o = MotionOptions();
  o.head_motion_deg = 60;
  expect_field(o, "head_motion_deg");
  o = MotionOptions();
  o.neck_pivot_y_mm = 10;
  expect_field(o, "neck_pivot_y_mm");
  o = MotionOptions();
  o.head_sway_mm = 250;
  expect_field(o, "head_sway_mm");
  o = MotionOptions();
  o.lie_back_deg = 100;
  expect_field(o, "lie_back_deg");
  o = MotionOptions();
  o.lie_back_s = 0.1;
  expect_field(o, "lie_back_s");
  o = MotionOptions();
  o.amplitude_mm = std::nan("");
  expect_field(o, "amplitude_mm");
  o = MotionOptions();
  o.ramp_in_s = 0.0;
  expect_field(o, "ramp_in_s");
  o = MotionOptions();
  o.sway_max_hz = 0.1;  // below sway_min_hz
  expect_field(o, "sway_max_hz");
  o = MotionOptions();
  o.jump_flight_s = 0.95;  // leaves a 50 ms stance
  expect_field(o, "jump_flight_s");
  o = MotionOptions();
  o.run_impact_g = 100.0;
  expect_field(o, "run_impact_g");
  o = MotionOptions();
  o.kind = MotionKind::kFile;
  expect_field(o, "file");
}

// Nod and shake turn the head about the neck pivot: the pivot stays put in the world, the
// rotation is about X (nod) or Y (shake) with the configured peak at the configured rate, and
// the face in front of the pivot swings through the arc.
TEST(HeadRotationMotion, TurnsAboutTheNeckPivot) {
  for (MotionKind kind : {MotionKind::kNod, MotionKind::kShake}) {
    SCOPED_TRACE(MotionKindName(kind));
    MotionOptions options = OptionsFor(kind);
    options.head_motion_hz = 2.0;
    options.head_motion_deg = 15.0;
    const auto motion = Make(options);
    ASSERT_NE(motion, nullptr);
    const Eigen::Vector3d pivot(0.0, options.neck_pivot_y_mm, options.neck_pivot_z_mm);
    const Eigen::Vector3d axis =
        kind == MotionKind::kNod ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    double peak_rad = 0.0, pivot_drift_mm = 0.0, off_axis_rad = 0.0;
    std::vector<double> angle;
    const double dt = 1.0 / 256;
    for (int i = 0; i < 512; ++i) {  // 0.5 s ramp excluded: 2 s from t = 1 s, 4 whole periods
      const double t = 1.0 + i * dt;
      const Rigid3 pose = motion->WorldFromSkull(t);
      pivot_drift_mm = std::max(pivot_drift_mm, (pose.Apply(pivot) - pivot).norm());
      const Eigen::Vector3d vector = RotationVector(pose);
      angle.push_back(vector.dot(axis));
      peak_rad = std::max(peak_rad, std::abs(vector.dot(axis)));
      off_axis_rad = std::max(off_axis_rad, (vector - vector.dot(axis) * axis).norm());
    }
    EXPECT_LT(pivot_drift_mm, 1e-9);
    EXPECT_NEAR(peak_rad, 15.0 * kPi / 180, 1e-3);
    EXPECT_LT(off_axis_rad, 1e-12);
    EXPECT_NEAR(AmplitudeAt(angle, dt, 2.0), 15.0 * kPi / 180, 1e-3);
    // The face (100 mm in front of the skull origin) moves by centimetres.
    double face_travel_mm = 0.0;
    for (double t = 1.0; t < 1.5; t += dt) {
      face_travel_mm = std::max(
          face_travel_mm,
          (motion->WorldFromSkull(t).Apply(Eigen::Vector3d(0, 0, 100)) - Eigen::Vector3d(0, 0, 100))
              .norm());
    }
    EXPECT_GT(face_travel_mm, 20.0);
  }
}

// Sway: the head along X by head_sway_mm at head_motion_hz, rolling with it as the top of an
// inverted pendulum, so gravity in the skull frame swings sideways by the same angle.
TEST(SwayMotion, MovesSidewaysAndTiltsGravity) {
  MotionOptions options = OptionsFor(MotionKind::kSway);
  options.head_motion_hz = 1.0;
  options.head_sway_mm = 40.0;
  const auto motion = Make(options);
  ASSERT_NE(motion, nullptr);
  std::vector<double> x, roll, gravity_x;
  const double dt = 1.0 / 128;
  for (int i = 0; i < 256; ++i) {  // 2 whole periods after the ramp
    const double t = 1.0 + i * dt;
    const Rigid3 pose = motion->WorldFromSkull(t);
    x.push_back(pose.translation().x());
    roll.push_back(RotationVector(pose).z());
    gravity_x.push_back(motion->Kinematics(t).GravityInSkull().x());
    EXPECT_NEAR(pose.translation().y(), 0.0, 1e-9);
  }
  EXPECT_NEAR(AmplitudeAt(x, dt, 1.0), 40.0, 1e-6);
  const double tilt = std::atan(40.0 / kStandingPendulumMm);
  EXPECT_NEAR(AmplitudeAt(roll, dt, 1.0), tilt, 1e-9);
  EXPECT_NEAR(AmplitudeAt(gravity_x, dt, 1.0), 9810.0 * std::sin(tilt), 1.0);
  // Towards +X is a negative roll (the top of the head leads): in phase opposition.
  double dot = 0;
  for (size_t i = 0; i < x.size(); ++i) dot += x[i] * roll[i];
  EXPECT_LT(dot, 0.0);
}

// Lying back: the pitch goes smoothly from 0 to -lie_back_deg over lie_back_s about the hips
// and stays; gravity ends up along the skull's -Y rotated by that angle, the body at rest.
TEST(LieBackMotion, TurnsGravityAndComesToRest) {
  MotionOptions options = OptionsFor(MotionKind::kLieBack);
  options.lie_back_deg = 60.0;
  options.lie_back_s = 1.5;
  const auto motion = Make(options);
  ASSERT_NE(motion, nullptr);
  EXPECT_TRUE(motion->WorldFromSkull(0.0).rotation().isApprox(Eigen::Quaterniond::Identity()));
  const Eigen::Vector3d hip(0.0, -kHipBelowSkullMm, 0.0);
  double previous_angle = 0.0;
  for (double t = 0.0; t <= 3.0; t += 0.01) {
    const Rigid3 pose = motion->WorldFromSkull(t);
    EXPECT_LT((pose.Apply(hip) - hip).norm(), 1e-9) << t;  // about the hips
    const double pitch = RotationVector(pose).x();
    EXPECT_LE(pitch, previous_angle + 1e-12) << t;  // monotone: lying back, never rocking
    previous_angle = pitch;
  }
  EXPECT_NEAR(previous_angle, -60.0 * kPi / 180, 1e-12);
  const physics::SkullKinematics end = motion->Kinematics(2.5);
  EXPECT_LT(end.origin_acceleration_in_skull.norm(), 1e-3);
  EXPECT_LT(end.angular_velocity_in_skull.norm(), 1e-9);
  // Gravity (-Y world) seen from the reclined skull: towards the back of the head (-Z) by 60 deg.
  const Eigen::Vector3d g = end.GravityInSkull() / 9810.0;
  EXPECT_NEAR(g.y(), -std::cos(60.0 * kPi / 180), 1e-9);
  EXPECT_NEAR(g.z(), -std::sin(60.0 * kPi / 180), 1e-9);
  // C2: the angular acceleration is continuous through the transition.
  double jump = 0.0;
  for (double t = 0.01; t < 1.6; t += 0.01) {
    jump = std::max(jump, (motion->Kinematics(t + 1e-4).angular_acceleration_in_skull -
                           motion->Kinematics(t).angular_acceleration_in_skull)
                              .norm());
  }
  EXPECT_LT(jump, 0.05);  // rad/s^2 over 0.1 ms; peak angular acceleration is ~1.9 rad/s^2
}

// Turning while walking: the walk's progress and bobbing plus a yaw of head_motion_deg at
// head_motion_hz about the neck.
TEST(TurnWalkMotion, WalksForwardWhileTurningTheHead) {
  MotionOptions options = OptionsFor(MotionKind::kTurnWalk);
  options.head_motion_hz = 0.5;
  options.head_motion_deg = 30.0;
  const auto motion = Make(options);
  ASSERT_NE(motion, nullptr);
  std::vector<double> yaw;
  const double dt = 1.0 / 128;
  for (int i = 0; i < 512; ++i) {  // 4 s: 2 head turns, 7.6 steps
    yaw.push_back(RotationVector(motion->WorldFromSkull(1.0 + i * dt)).y());
  }
  EXPECT_NEAR(AmplitudeAt(yaw, dt, 0.5), 30.0 * kPi / 180, 0.01);
  const double advanced_mm =
      motion->WorldFromSkull(3.0).translation().z() - motion->WorldFromSkull(1.0).translation().z();
  EXPECT_NEAR(advanced_mm, 2.0 * options.walk_speed_mm_per_s, 100.0);
}

TEST(ParseMotionKind, AcceptsKindsAndFilePaths) {
  std::string path;
  for (MotionKind kind :
       {MotionKind::kPlatform, MotionKind::kWalk, MotionKind::kRun, MotionKind::kJump,
        MotionKind::kNod, MotionKind::kShake, MotionKind::kSway, MotionKind::kTurnWalk,
        MotionKind::kLieBack, MotionKind::kNone}) {
    StatusOr<MotionKind> parsed = ParseMotionKind(MotionKindName(kind), &path);
    ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
    EXPECT_EQ(*parsed, kind);
  }
  StatusOr<MotionKind> file = ParseMotionKind("file:/x.csv", &path);
  ASSERT_TRUE(file.ok()) << file.status().ToString();
  EXPECT_EQ(*file, MotionKind::kFile);
  EXPECT_EQ(path, "/x.csv");
}

TEST(ParseMotionKind, BadSpecListsValidKinds) {
  std::string path;
  StatusOr<MotionKind> parsed = ParseMotionKind("wobble", &path);
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidArgument);
  for (const char* name : {"wobble", "platform", "walk", "run", "jump", "nod", "shake", "sway",
                           "turn_walk", "lie_back", "none", "file:PATH"}) {
    EXPECT_NE(parsed.status().message().find(name), std::string::npos)
        << parsed.status().ToString();
  }
  EXPECT_FALSE(ParseMotionKind("file:", &path).ok());
  EXPECT_FALSE(ParseMotionKind("Platform", &path).ok());
}

TEST(Ramp, IsC2AtBothEnds) {
  EXPECT_EQ(Ramp(-1.0), 0.0);
  EXPECT_EQ(Ramp(0.0), 0.0);
  EXPECT_EQ(Ramp(1.0), 1.0);
  EXPECT_EQ(Ramp(2.0), 1.0);
  EXPECT_NEAR(Ramp(0.5), 0.5, 1e-15);
  const double h = 1e-4;
  for (double s : {0.0, 1.0}) {
    const double first = (Ramp(s + h) - Ramp(s - h)) / (2 * h);
    const double second = (Ramp(s + h) - 2 * Ramp(s) + Ramp(s - h)) / (h * h);
    EXPECT_NEAR(first, 0.0, 1e-6);
    EXPECT_NEAR(second, 0.0, 1e-3);
  }
}

}  // namespace
}  // namespace facedyn::sim
