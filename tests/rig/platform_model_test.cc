#include "rig/platform_model.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>

namespace facedyn::rig {
namespace {

TEST(PlatformModel, RatioAndSlipRoundTrip) {
  PlatformModelOptions options;
  options.ratio = 0.5;  // 4-pole motor on the shaft
  options.slip = 0.04;
  ASSERT_TRUE(options.Check().ok());
  const PlatformModel model(options);
  EXPECT_NEAR(model.PlatformHzFor(20.0), 20.0 * 0.5 * 0.96, 1e-12);
  for (double hz : {6.0, 8.5, 11.0})
    EXPECT_NEAR(model.PlatformHzFor(model.MotorHzFor(hz)), hz, 1e-12);
}

TEST(PlatformModelOptions, CheckNamesField) {
  PlatformModelOptions options;
  options.slip = 0.6;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("platform.slip"));
  options = PlatformModelOptions();
  options.ratio = 0.0;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("platform.ratio"));
}

// The trim against a plant with an unknown gain error: the loop must converge to the target.
TEST(FrequencyTrim, RemovesAConstantSlipErrorAndStaysBounded) {
  TrimOptions options;
  options.gain_per_s = 0.8;
  options.max_correction_hz = 0.6;
  FrequencyTrim trim(options);
  const double target_hz = 10.0;
  auto plant = [](double commanded_hz) {
    return commanded_hz * 0.97;
  };  // 3% more slip than assumed
  trim.Jump(target_hz, plant(target_hz));
  for (int i = 0; i < 200; ++i)
    trim.Update(target_hz, plant(target_hz + trim.correction_hz()), 0.1);
  EXPECT_NEAR(plant(target_hz + trim.correction_hz()), target_hz, 1e-6);
  EXPECT_FALSE(trim.saturated());
  // An error the trim cannot cover saturates at the bound instead of running away.
  FrequencyTrim small(TrimOptions{true, 0.8, 0.1, 0.6});
  for (int i = 0; i < 200; ++i)
    small.Update(target_hz, plant(target_hz + small.correction_hz()), 0.1);
  EXPECT_NEAR(small.correction_hz(), 0.1, 1e-12);
  EXPECT_TRUE(small.saturated());
}

TEST(FrequencyTrim, DisabledDoesNothing) {
  FrequencyTrim trim(TrimOptions{false, 0.8, 0.6, 0.6});
  trim.Jump(10.0, 9.0);
  trim.Update(10.0, 9.0, 1.0);
  EXPECT_EQ(trim.correction_hz(), 0.0);
}

TEST(SettleDetector, NeedsTheWholeTimeWithinTolerance) {
  SettleDetector settle(SettleOptions{0.05, 1.0});
  double t = 0.0;
  for (; t < 0.95; t += 0.1) settle.Update(t, 8.0, 8.02, true);
  EXPECT_FALSE(settle.settled());
  settle.Update(t, 8.0, 8.10, true);  // one excursion restarts the clock
  for (t += 0.1; t < 1.9; t += 0.1) settle.Update(t, 8.0, 7.97, true);
  EXPECT_FALSE(settle.settled());
  for (; t < 3.0; t += 0.1) settle.Update(t, 8.0, 7.97, true);
  EXPECT_TRUE(settle.settled());
  settle.Update(t, 8.0, 8.0, false);  // ramping again
  EXPECT_FALSE(settle.settled());
}

TEST(VibrationExposure, MatchesTheSinusoidFormula) {
  VibrationExposure exposure(2.0);
  for (int i = 0; i < 600; ++i) exposure.Add(10.0, 0.1);  // 60 s at 10 Hz, 2 mm
  const double rms = std::pow(2.0 * M_PI * 10.0, 2) * 0.002 / std::sqrt(2.0);
  EXPECT_NEAR(exposure.vibrating_s(), 60.0, 1e-9);
  EXPECT_NEAR(exposure.peak_rms_m_s2(), rms, 1e-9);
  EXPECT_NEAR(exposure.A8_m_s2(), rms * std::sqrt(60.0 / 28800.0), 1e-9);
  exposure.Add(0.0, 10.0);  // standing still adds nothing
  EXPECT_NEAR(exposure.vibrating_s(), 60.0, 1e-9);
  VibrationExposure resumed(2.0);
  resumed.Restore(exposure.vibrating_s(), exposure.dose_m2_s3(), exposure.peak_rms_m_s2());
  EXPECT_NEAR(resumed.A8_m_s2(), exposure.A8_m_s2(), 1e-12);
  // The peak survives a resume (issue 18, item 6): it was reset to 0 before.
  EXPECT_GT(exposure.peak_rms_m_s2(), 0.0);
  EXPECT_EQ(resumed.peak_rms_m_s2(), exposure.peak_rms_m_s2());
}

}  // namespace
}  // namespace facedyn::rig
