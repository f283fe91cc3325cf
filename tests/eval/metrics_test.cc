// Evaluation statistics on hand-built cases, and the errors for takes that disagree.

#include "eval/metrics.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace facedyn::eval {
namespace {

using ::testing::HasSubstr;

PointCache Zeros(int vertices, int frames) {
  PointCache cache;
  cache.vertex_count = vertices;
  cache.positions = Eigen::MatrixXf::Zero(3 * vertices, frames);
  return cache;
}

// Vertex v is (v + 1) mm off along x in every frame.
PointCache KnownErrors(int vertices, int frames) {
  PointCache cache = Zeros(vertices, frames);
  for (int t = 0; t < frames; ++t) {
    for (int v = 0; v < vertices; ++v) cache.Frame(t)(0, v) = static_cast<float>(v + 1);
  }
  return cache;
}

FaceRig RigWithRegions(int vertices) {
  FaceRig rig;
  rig.name = "test";
  rig.neutral.positions_mm = Eigen::Matrix3Xd::Zero(3, vertices);
  for (int v = 0; v < 10; ++v) rig.regions["first_ten"].push_back(v);
  rig.regions["last"].push_back(vertices - 1);
  return rig;
}

TEST(ComputeErrorStats, MeanPercentileMax) {
  std::vector<float> errors;
  for (int i = 100; i >= 1; --i) errors.push_back(static_cast<float>(i));
  const ErrorStats stats = ComputeErrorStats(&errors);
  EXPECT_EQ(stats.count, 100);
  EXPECT_DOUBLE_EQ(stats.mean_mm, 50.5);
  EXPECT_NEAR(stats.p95_mm, 1 + 0.95 * 99, 1e-9);  // 95.05, linear interpolation
  EXPECT_DOUBLE_EQ(stats.max_mm, 100.0);
  std::vector<float> one = {3.0f};
  EXPECT_DOUBLE_EQ(ComputeErrorStats(&one).p95_mm, 3.0);
  std::vector<float> none;
  EXPECT_EQ(ComputeErrorStats(&none).count, 0);
}

TEST(ComparePositions, FaceAndRegionsOnAHandBuiltCase) {
  const FaceRig rig = RigWithRegions(100);
  const ErrorReport report = ComparePositions(KnownErrors(100, 3), Zeros(100, 3), &rig, EdgeSkipped(3, 0), "p").value();
  EXPECT_EQ(report.face.count, 300);
  EXPECT_NEAR(report.face.mean_mm, 50.5, 1e-9);
  EXPECT_NEAR(report.face.p95_mm, 95.05, 1e-4);
  EXPECT_NEAR(report.face.max_mm, 100.0, 1e-9);
  const ErrorStats& first = report.regions.at("first_ten");
  EXPECT_EQ(first.count, 30);
  EXPECT_NEAR(first.mean_mm, 5.5, 1e-9);
  EXPECT_NEAR(first.p95_mm, 10.0, 1e-9);  // 30 values, position 27.55 lies among the 10s
  EXPECT_NEAR(first.max_mm, 10.0, 1e-9);
  EXPECT_NEAR(report.regions.at("last").mean_mm, 100.0, 1e-9);
}

TEST(ComparePositions, SkipsEdgeFrames) {
  PointCache predicted = Zeros(4, 7);
  predicted.Frame(0).setConstant(1000.0f);
  predicted.Frame(6).setConstant(1000.0f);
  predicted.Frame(3)(1, 2) = 2.0f;
  const ErrorReport report = ComparePositions(predicted, Zeros(4, 7), nullptr, EdgeSkipped(7, 1), "p").value();
  EXPECT_EQ(report.face.count, 4 * 5);
  EXPECT_NEAR(report.face.max_mm, 2.0, 1e-9);
  EXPECT_NEAR(report.face.mean_mm, 2.0 / 20, 1e-9);
  EXPECT_TRUE(report.regions.empty());
  const auto too_few = ComparePositions(predicted, Zeros(4, 7), nullptr, EdgeSkipped(7, 4), "p");
  ASSERT_FALSE(too_few.ok());
  EXPECT_THAT(too_few.status().message(), HasSubstr("7 frames"));
}

TEST(ComparePositions, MismatchesNameWhatDiffers) {
  const auto vertices = ComparePositions(Zeros(5, 3), Zeros(6, 3), nullptr, EdgeSkipped(3, 0), "p");
  ASSERT_FALSE(vertices.ok());
  EXPECT_THAT(vertices.status().message(), HasSubstr("vertex count differs: prediction has 5, truth has 6"));
  const auto frames = ComparePositions(Zeros(5, 3), Zeros(5, 4), nullptr, EdgeSkipped(4, 0), "p");
  ASSERT_FALSE(frames.ok());
  EXPECT_THAT(frames.status().message(), HasSubstr("frame count differs: prediction has 3, truth has 4"));
  const FaceRig rig = RigWithRegions(50);
  const auto rig_mismatch = ComparePositions(Zeros(5, 3), Zeros(5, 3), &rig, EdgeSkipped(3, 0), "p");
  ASSERT_FALSE(rig_mismatch.ok());
  EXPECT_THAT(rig_mismatch.status().message(), HasSubstr("50 vertices"));
}

Take TakeOf(const PointCache& positions, double fps) {
  Take take;
  take.info.fps = fps;
  take.topology.positions_mm = Eigen::Matrix3Xd::Zero(3, positions.vertex_count);
  take.positions = positions;
  take.world_from_skull.assign(positions.frame_count(), Rigid3::Identity());
  take.SetUniformTimes();
  return take;
}

TEST(Evaluate, TruthChannelBaselinesAndJson) {
  Take truth = TakeOf(KnownErrors(20, 30), 128.0);
  truth.channels["quasistatic"] = Zeros(20, 30);
  const Take predicted = TakeOf(Zeros(20, 30), 128.0);
  EvaluateOptions options;  // window = round(0.08 * 128) = 10
  const Evaluation evaluation = Evaluate(predicted, truth, &truth, nullptr, options).value();
  EXPECT_EQ(evaluation.skip_edge_frames, 10);
  // Windows inside the take and from frame 1: frames 11..19.
  EXPECT_EQ(evaluation.scored.begin, 11);
  EXPECT_EQ(evaluation.scored.end, 20);
  ASSERT_EQ(evaluation.reports.size(), 5u);
  EXPECT_EQ(evaluation.reports[4].name, "lowpass_oracle");
  EXPECT_EQ(evaluation.reports[0].name, "prediction");
  EXPECT_NEAR(evaluation.reports[0].face.max_mm, 0.0, 1e-12);
  // The input is static, so every baseline leaves it as it is: errors 1..20 mm.
  for (size_t i = 1; i < 5; ++i) {
    EXPECT_NEAR(evaluation.reports[i].face.mean_mm, 10.5, 1e-4) << evaluation.reports[i].name;
    EXPECT_NEAR(evaluation.reports[i].face.max_mm, 20.0, 1e-4);
  }
  const Json json = EvaluationToJson(evaluation);
  EXPECT_NEAR(json["reports"]["no_removal"]["face"]["mean_mm"].get<double>(), 10.5, 1e-4);
  EXPECT_THAT(EvaluationToText(evaluation), HasSubstr("lowpass"));
  // Against positions instead of a channel.
  options.truth_channel = "positions";
  EXPECT_NEAR(Evaluate(predicted, truth, nullptr, nullptr, options).value().reports[0].face.mean_mm, 10.5, 1e-4);
}

// A held-expression truth is scored only after its hold start plus the window: a baseline that
// smears the onset is not charged for it, and neither is the prediction.
TEST(Evaluate, ScoresOnlyTheHeldPart) {
  // The prediction is 5 mm off before frame 60 and exact after it.
  PointCache predicted = Zeros(10, 200);
  for (int t = 0; t < 60; ++t) predicted.Frame(t).row(0).setConstant(5.0f);
  Take truth = TakeOf(Zeros(10, 200), 128.0);
  truth.channels["quasistatic"] = Zeros(10, 200);
  const Take prediction = TakeOf(predicted, 128.0);
  EXPECT_GT(Evaluate(prediction, truth, nullptr, nullptr, EvaluateOptions()).value()
                .reports[0].face.mean_mm, 1.0);
  truth.info.hold_start_s = 50 / 128.0;  // frame 50: scored from 60 on
  const Evaluation held = Evaluate(prediction, truth, nullptr, nullptr, EvaluateOptions()).value();
  EXPECT_EQ(held.scored.begin, 60);
  EXPECT_EQ(held.scored.end, 190);
  EXPECT_NEAR(held.reports[0].face.max_mm, 0.0, 1e-12);
  // Nothing left to score is an error naming the frames, not a zero.
  truth.info.hold_start_s = 190 / 128.0;
  EXPECT_THAT(Evaluate(prediction, truth, nullptr, nullptr, EvaluateOptions()).status().message(),
              HasSubstr("no frames to score"));
}

TEST(MeanDistanceOverVerticesDeathTest, RefusesCachesOfOtherSizes) {
  EXPECT_DEATH(MeanDistanceOverVertices(Zeros(5, 3), Zeros(6, 3), {0}, EdgeSkipped(3, 0)),
               "5 vs 6 vertices");
  EXPECT_DEATH(MeanDistanceOverVertices(Zeros(5, 3), Zeros(5, 4), {0}, EdgeSkipped(3, 0)),
               "3 vs 4 frames");
}

TEST(Evaluate, MismatchedTakesAndMissingChannels) {
  const Take truth = TakeOf(Zeros(20, 30), 128.0);
  EvaluateOptions options;
  const auto missing = Evaluate(truth, truth, nullptr, nullptr, options);
  ASSERT_FALSE(missing.ok());
  EXPECT_THAT(missing.status().message(), HasSubstr("no channel 'quasistatic'"));
  options.truth_channel = "positions";
  const auto frames = Evaluate(TakeOf(Zeros(20, 29), 128.0), truth, nullptr, nullptr, options);
  ASSERT_FALSE(frames.ok());
  EXPECT_THAT(frames.status().message(), HasSubstr("frame count differs: prediction has 29, truth has 30"));
  const Take other_input = TakeOf(Zeros(21, 30), 128.0);
  const auto vertices = Evaluate(truth, truth, &other_input, nullptr, options);
  ASSERT_FALSE(vertices.ok());
  EXPECT_THAT(vertices.status().message(), HasSubstr("vertex count differs: input has 21, truth has 20"));
  const auto fps = Evaluate(TakeOf(Zeros(20, 30), 96.0), truth, nullptr, nullptr, options);
  ASSERT_FALSE(fps.ok());
  EXPECT_THAT(fps.status().message(), HasSubstr("fps differs"));
}

TEST(JigglingVertices, KeepsVerticesAboveAFifthOfTheLargestAndAveragesOverThem) {
  PointCache offsets;
  offsets.vertex_count = 4;
  offsets.positions = Eigen::MatrixXf::Zero(12, 5);
  for (int t = 0; t < 5; ++t) {
    offsets.Frame(t).col(0) << 1.0f, 0, 0;   // the largest
    offsets.Frame(t).col(1) << 0, 0.5f, 0;   // half of it: kept
    offsets.Frame(t).col(2) << 0, 0, 0.1f;   // a tenth: left out
  }                                          // vertex 3 never moves: left out
  const std::vector<int> vertices = JigglingVertices(offsets, EdgeSkipped(5, 1));
  EXPECT_EQ(vertices, (std::vector<int>{0, 1}));
  PointCache zero = offsets;
  zero.positions.setZero();
  EXPECT_NEAR(MeanDistanceOverVertices(offsets, zero, vertices, EdgeSkipped(5, 1)), 0.75, 1e-6);
  EXPECT_EQ(MeanDistanceOverVertices(offsets, zero, {}, EdgeSkipped(5, 1)), 0.0);
}

// The removal figure of a simulated take: over its jiggling vertices (here 0 and 1, vertex 2's
// offset is below a fifth of the largest) and its scored frames (the window margin, from frame 1
// on); a take without its channels or a prediction of another size is a named error.
TEST(JiggleMeanErrorMm, ScoresTheJigglingVerticesOverTheScoredFrames) {
  Take simulated = TakeOf(Zeros(3, 20), 128.0);
  simulated.channels["quasistatic"] = Zeros(3, 20);
  EXPECT_THAT(JiggleMeanErrorMm(Zeros(3, 20), simulated, 2).status().message(),
              HasSubstr("no \"dynamic_offset\" channel"));
  PointCache offsets = Zeros(3, 20);
  for (int t = 0; t < 20; ++t) {
    offsets.Frame(t).col(0) << 1.0f, 0, 0;
    offsets.Frame(t).col(1) << 0, 1.0f, 0;
    offsets.Frame(t).col(2) << 0, 0, 0.1f;
  }
  simulated.channels["dynamic_offset"] = offsets;
  PointCache predicted = KnownErrors(3, 20);  // vertex v is v + 1 mm off
  predicted.Frame(0).setConstant(100.0f);     // frame 0 is never scored (a window from frame 1)
  predicted.Frame(19).setConstant(100.0f);    // nor the end's margin
  EXPECT_NEAR(JiggleMeanErrorMm(predicted, simulated, 2).value(), 1.5, 1e-6);
  EXPECT_THAT(JiggleMeanErrorMm(Zeros(3, 19), simulated, 2).status().message(),
              HasSubstr("19 frames"));
}

// Fine detail's score: two frames of four vertices with known errors; vertex 3 is the lips.
TEST(ScoreDetail, MeansAndPercentilesOverTheFaceAndTheLips) {
  std::vector<Eigen::Matrix3Xd> truth(2, Eigen::Matrix3Xd::Zero(3, 4)), result = truth;
  // Errors (mm): frame 0: 1, 0, 0, 2; frame 1: 0, 3, 0, 4 (along x, y and z).
  result[0](0, 0) = 1;
  result[0](2, 3) = -2;
  result[1](1, 1) = 3;
  result[1](0, 3) = 4;
  const DetailErrors errors = ScoreDetail(result, truth, {3});
  EXPECT_DOUBLE_EQ(errors.face_mean_mm, 10.0 / 8);
  EXPECT_DOUBLE_EQ(errors.face_p95_mm, 4.0);  // ceil(0.95 * 8) = 8th smallest
  EXPECT_DOUBLE_EQ(errors.lips_mean_mm, 3.0);
  EXPECT_DOUBLE_EQ(errors.lips_p95_mm, 4.0);
  const Json json = DetailErrorsJson(errors);
  EXPECT_DOUBLE_EQ(json["lips_mean_mm"].get<double>(), 3.0);
  EXPECT_DOUBLE_EQ(Percentile95({}), 0.0);
  std::vector<double> hundred;
  for (int i = 1; i <= 100; ++i) hundred.push_back(101 - i);
  EXPECT_DOUBLE_EQ(Percentile95(hundred), 95.0);
}

}  // namespace
}  // namespace facedyn::eval
