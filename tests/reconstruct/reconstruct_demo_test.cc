// The reconstruction stage of `facedyn demo` on a short simulated take.

#include "app/reconstruct_demo.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "sim/performance.h"
#include "tests/reconstruct/reconstruct_test_util.h"
#include "tests/support/test_support.h"

namespace facedyn::app {
namespace {

TEST(RunReconstructDemoStage, ReportsErrorsAgainstTruth) {
  const FaceRig& face = reconstruct::testing::ProceduralFace();
  sim::PerformanceOptions performance;
  performance.motion.kind = sim::MotionKind::kPlatform;
  performance.motion.platform_hz = 11.0;
  performance.seconds = 0.9;
  const auto take = sim::SimulatePerformance(face, performance);
  ASSERT_TRUE(take.ok()) << take.status().ToString();
  testing::TempDir dir;
  Json metrics;
  const Status status = RunReconstructDemoStage(face, *take, dir.path(), true, &metrics);
  ASSERT_TRUE(status.ok()) << status.ToString();
  EXPECT_TRUE(std::filesystem::exists(dir.Join("takes/reconstructed/take.json")));
  EXPECT_TRUE(std::filesystem::exists(dir.Join("reconstruct/calibration.yaml")));
  EXPECT_LT(metrics["calibration_worst_centre_error_mm"].get<double>(), 0.5);
  // Through a calibration (not the true cameras) errors are larger than the figures of the
  // reconstruction tests, which use the true cameras.
  EXPECT_LT(metrics["skull_origin_rms_mm"].get<double>(), 0.5);
  // The error splits into its mean over the take and what varies about it: the RMS about the
  // mean and the mean's size combine to the total RMS (Pythagoras over the frames).
  const double total = metrics["skull_origin_rms_mm"].get<double>();
  const double constant = metrics["skull_origin_constant_mm"].get<double>();
  const double varying = metrics["skull_origin_varying_rms_mm"].get<double>();
  EXPECT_NEAR(constant * constant + varying * varying, total * total, 1e-9 + 1e-6 * total * total);
  EXPECT_GE(metrics["skull_rotation_varying_rms_deg"].get<double>(), 0.0);
  EXPECT_LE(metrics["skull_rotation_varying_rms_deg"].get<double>(),
            metrics["skull_rotation_rms_deg"].get<double>() + 1e-9);
  EXPECT_LT(metrics["sample_rms_mm"].get<double>(), 0.5);
  EXPECT_GT(metrics["dynamic_offset_correlation"].get<double>(), 0.9);
  // A take that does not belong to the face is refused by name.
  Take wrong = *take;
  wrong.topology.positions_mm.resize(3, 10);
  EXPECT_FALSE(RunReconstructDemoStage(face, wrong, dir.path(), true, nullptr).ok());
}

}  // namespace
}  // namespace facedyn::app
