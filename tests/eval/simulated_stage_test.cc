#include "eval/simulated_stage.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "sim/performance.h"
#include "sim/procedural_face.h"

namespace facedyn::eval {
namespace {

// Samples' RMS distance between a reconstructed and the simulated (dynamic) skin, mm.
double SampleRms(const FaceRig& face, const Take& reconstructed, const Take& simulated) {
  double sq = 0.0;
  long n = 0;
  for (int f = 0; f < simulated.frame_count(); ++f) {
    const Eigen::Matrix3Xd a = face.SamplePositions(reconstructed.FramePositions(f));
    const Eigen::Matrix3Xd b = face.SamplePositions(simulated.FramePositions(f));
    sq += (a - b).colwise().squaredNorm().sum();
    n += a.cols();
  }
  return std::sqrt(sq / n);
}

// A short platform take filmed for real (rendered, detected, triangulated, labelled, fitted)
// lands as close to the simulator's skin as the projected-centres path, says so in its
// metadata, and refuses a take that is not of the face.
TEST(FilmSimulatedTake, RenderedAndDetectedTakeMatchesTheTruth) {
  const auto face = sim::MakeProceduralFace(sim::ProceduralFaceOptions());
  ASSERT_TRUE(face.ok()) << face.status().ToString();
  const auto cameras = CalibrateSimulatedCameraRig(12, 5);
  ASSERT_TRUE(cameras.ok()) << cameras.status().ToString();
  sim::PerformanceOptions performance;
  performance.expression = "smile";
  performance.motion.kind = sim::MotionKind::kPlatform;
  performance.motion.platform_hz = 9.0;
  performance.motion.amplitude_mm = 2.0;
  performance.seconds = 0.125;
  performance.fps = 128.0;
  const auto take = sim::SimulatePerformance(*face, performance);
  ASSERT_TRUE(take.ok()) << take.status().ToString();
  FilmTimings timings;
  FilmOptions film;
  film.timings = &timings;
  const auto filmed = FilmSimulatedTake(*face, *cameras, *take, 3, film);
  ASSERT_TRUE(filmed.ok()) << filmed.status().ToString();
  EXPECT_GT(timings.render_s, 0.0);
  EXPECT_GT(timings.detect_s, 0.0);
  EXPECT_GT(timings.reconstruct_s, 0.0);
  std::printf("filming %d frames: render %.1f ms, detect %.1f ms per frame; reconstruct %.2f s\n",
              take->frame_count(), 1e3 * timings.render_s / take->frame_count(),
              1e3 * timings.detect_s / take->frame_count(), timings.reconstruct_s);
  const auto projected = ReconstructSimulatedTake(*face, *cameras, *take, 3);
  ASSERT_TRUE(projected.ok()) << projected.status().ToString();
  ASSERT_EQ(filmed->take.frame_count(), take->frame_count());
  double labelled = 0.0;
  for (const auto& quality : filmed->quality) labelled += quality.labelled;
  labelled /= filmed->quality.size() * face->markers.size();
  const double filmed_rms = SampleRms(*face, filmed->take, *take);
  const double projected_rms = SampleRms(*face, projected->take, *take);
  std::printf("filmed: %.1f%% of markers labelled, sample RMS %.4f mm (projected centres %.4f)\n",
              100.0 * labelled, filmed_rms, projected_rms);
  EXPECT_GT(labelled, 0.9);
  EXPECT_LT(filmed_rms, 0.45);  // the projected path: 0.31 on this 16-frame take
  EXPECT_LT(filmed_rms, 1.5 * projected_rms + 0.02);
  const std::string source = filmed->take.info.metadata.at("reconstructed_from");
  EXPECT_NE(source.find("filmed"), std::string::npos) << source;
  EXPECT_EQ(filmed->take.info.expression, "smile");

  Take empty;
  EXPECT_FALSE(FilmSimulatedTake(*face, *cameras, empty, 3).ok());
  FaceRig other = *face;
  other.neutral.positions_mm.conservativeResize(3, face->vertex_count() - 1);
  const auto refused = FilmSimulatedTake(other, *cameras, *take, 3);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("vertices"), std::string::npos);
}

}  // namespace
}  // namespace facedyn::eval
