// The body's transmissibility fit (physics/body_transmissibility.h): the formula against
// analytic cases, and the fit against the simulator's platform motion for bodies it is not told.
#include "physics/body_transmissibility.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "core/take.h"
#include "sim/skull_motion.h"

namespace facedyn::physics {
namespace {

TEST(BodyTransmissibility, AnalyticCases) {
  // Static: the head follows the platform.
  EXPECT_NEAR(std::abs(BodyTransmissibility(1e-9, 5, 0.35)), 1.0, 1e-12);
  // At resonance: |T| = sqrt(1 + 4 zeta^2) / (2 zeta), phase lag atan(2 zeta) - pi/2.
  const double zeta = 0.35;
  const auto at_resonance = BodyTransmissibility(5, 5, zeta);
  EXPECT_NEAR(std::abs(at_resonance), std::sqrt(1 + 4 * zeta * zeta) / (2 * zeta), 1e-12);
  EXPECT_NEAR(std::arg(at_resonance), std::atan(2 * zeta) - M_PI / 2, 1e-12);
  // r = sqrt(2): |T| = 1 for every damping.
  for (double z : {0.1, 0.35, 1.0}) {
    EXPECT_NEAR(std::abs(BodyTransmissibility(5 * std::sqrt(2.0), 5, z)), 1.0, 1e-12) << z;
  }
}

// A platform take of the simulator's skull motion only (one vertex; the fit reads the pose),
// sampled at 128 fps, with `noise_mm` of Gaussian noise on the skull translation standing in
// for the reconstruction's pose error.
Take PlatformTake(double hz, double body_hz, double body_zeta, double pitch_per_g, double noise_mm,
                  uint64_t seed) {
  sim::MotionOptions motion;
  motion.platform_hz = hz;
  motion.body_resonance_hz = body_hz;
  motion.body_damping_ratio = body_zeta;
  motion.pitch_rad_per_g = pitch_per_g;
  motion.seed = seed;
  auto skull = sim::MakeSkullMotion(motion);
  EXPECT_TRUE(skull.ok());
  Take take;
  take.info.fps = 128;
  take.info.platform_hz = hz;
  take.info.hold_start_s = 0.5;
  const int frames = 256;
  take.positions.vertex_count = 1;
  take.positions.positions = Eigen::MatrixXf::Zero(3, frames);
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, noise_mm);
  for (int f = 0; f < frames; ++f) {
    const double t = f / 128.0;
    take.time_s.push_back(t);
    Rigid3 pose = (*skull)->WorldFromSkull(t);
    if (noise_mm > 0) {
      pose = Rigid3(pose.rotation(),
                    pose.translation() + Eigen::Vector3d(normal(rng), normal(rng), normal(rng)));
    }
    take.world_from_skull.push_back(pose);
  }
  return take;
}

struct Body {
  double hz, zeta, pitch_per_g;
};

class BodyFitTest : public ::testing::TestWithParam<Body> {};

// Platform takes at 6-10 Hz (the session's) of a body the fit is not told: resonance and damping
// within 3%, pitch per g within 5%, noiseless; the truth lies inside a few reported standard
// deviations with 0.05 mm of pose noise.
TEST_P(BodyFitTest, RecoversTheBodyFromPlatformTakes) {
  const Body body = GetParam();
  for (double noise_mm : {0.0, 0.05}) {
    std::vector<Take> takes;
    for (double hz : {6.0, 7.0, 8.0, 9.0, 10.0}) {
      takes.push_back(PlatformTake(hz, body.hz, body.zeta, body.pitch_per_g, noise_mm,
                                   static_cast<uint64_t>(hz * 10)));
    }
    std::vector<std::pair<std::string, const Take*>> named;
    for (const Take& take : takes) named.push_back({"take", &take});
    BodyFitOptions options;
    options.platform_amplitude_mm = 2.0;  // sim::MotionOptions' default
    auto fit = FitBodyTransmissibility(named, options);
    ASSERT_TRUE(fit.ok()) << fit.status().message();
    EXPECT_EQ(fit->distinct_frequencies, 5);
    EXPECT_FALSE(fit->at_bound);
    if (noise_mm == 0) {
      EXPECT_NEAR(fit->resonance_hz, body.hz, 0.03 * body.hz);
      EXPECT_NEAR(fit->damping_ratio, body.zeta, 0.03 * body.zeta);
      EXPECT_NEAR(fit->pitch_rad_per_g, body.pitch_per_g, 0.05 * body.pitch_per_g);
      EXPECT_LT(fit->rms_log_residual, 0.01);
    } else {
      EXPECT_GT(fit->resonance_hz_stddev, 0.0);
      EXPECT_NEAR(fit->resonance_hz, body.hz, 4 * fit->resonance_hz_stddev + 0.02 * body.hz);
      EXPECT_NEAR(fit->damping_ratio, body.zeta, 4 * fit->damping_ratio_stddev + 0.02 * body.zeta);
    }
    const Json json = BodyFitToJson(*fit, 2.0);
    EXPECT_EQ(json["takes"].size(), 5u);
    EXPECT_DOUBLE_EQ(json["resonance_hz"].get<double>(), fit->resonance_hz);
  }
}

INSTANTIATE_TEST_SUITE_P(Bodies, BodyFitTest,
                         ::testing::Values(Body{5.0, 0.35, 0.013}, Body{4.2, 0.5, 0.02},
                                           Body{6.0, 0.25, 0.008}));

TEST(BodyFit, RefusesWhatCannotIdentifyTheBody) {
  std::vector<Take> takes;
  for (double hz : {8.0, 8.0, 10.0}) takes.push_back(PlatformTake(hz, 5, 0.35, 0.013, 0, 1));
  std::vector<std::pair<std::string, const Take*>> named;
  for (const Take& take : takes) named.push_back({"take", &take});
  BodyFitOptions options;
  options.platform_amplitude_mm = 2.0;
  auto fit = FitBodyTransmissibility(named, options);
  ASSERT_FALSE(fit.ok());
  EXPECT_NE(fit.status().message().find("2 distinct platform frequencies"), std::string::npos)
      << fit.status().message();

  options.platform_amplitude_mm = 0;
  fit = FitBodyTransmissibility(named, options);
  ASSERT_FALSE(fit.ok());
  EXPECT_NE(fit.status().message().find("amplitude"), std::string::npos);

  Take no_platform = takes[0];
  no_platform.info.platform_hz.reset();
  auto response = MeasureBodyResponse("walk-1", no_platform, 2.0);
  ASSERT_FALSE(response.ok());
  EXPECT_NE(response.status().message().find("walk-1"), std::string::npos);

  Take short_take = takes[0];
  short_take.info.hold_start_s = 1.95;
  response = MeasureBodyResponse("short-1", short_take, 2.0);
  ASSERT_FALSE(response.ok());
  EXPECT_NE(response.status().message().find("short-1"), std::string::npos);

  Take still = takes[0];
  for (Rigid3& pose : still.world_from_skull) pose = Rigid3();
  response = MeasureBodyResponse("still-1", still, 2.0);
  ASSERT_FALSE(response.ok());
  EXPECT_NE(response.status().message().find("does not move"), std::string::npos);
}

}  // namespace
}  // namespace facedyn::physics
