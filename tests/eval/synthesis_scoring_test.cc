// The synthesis protocols' scoring (eval/synthesis_scoring.h) on hand-built and short simulated
// takes, where the right figure is known without running a network.

#include "eval/synthesis_scoring.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>

#include "dynamics/synthesis_model.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"

namespace facedyn::eval {
namespace {

using ::testing::HasSubstr;

// A take of `vertices` points, `frames` frames, identity skull, whose every vertex carries a
// dynamic offset of `offset_mm` along x: positions = quasistatic + offset.
Take OffsetTake(int vertices, int frames, double offset_mm) {
  Take take;
  take.info.fps = 100;
  take.topology.positions_mm = Eigen::Matrix3Xd::Random(3, vertices) * 40.0;
  take.positions.vertex_count = vertices;
  take.positions.positions.resize(3 * vertices, frames);
  PointCache quasistatic = take.positions, offsets = take.positions;
  for (int t = 0; t < frames; ++t) {
    quasistatic.Frame(t) = take.topology.positions_mm.cast<float>();
    offsets.Frame(t).setZero();
    offsets.Frame(t).row(0).setConstant(static_cast<float>(offset_mm * std::sin(0.5 * t)));
    take.positions.Frame(t) = quasistatic.Frame(t) + offsets.Frame(t);
  }
  take.world_from_skull.assign(frames, Rigid3());
  take.channels["quasistatic"] = quasistatic;
  take.channels["dynamic_offset"] = offsets;
  take.SetUniformTimes();
  return take;
}

Take Quasistatic(const Take& truth) {
  Take take = truth;
  take.positions = truth.channels.at("quasistatic");
  take.channels.clear();
  return take;
}

TEST(SynthesisScoring, ExactSynthesisScoresZeroAndNoDynamicsScoresTheOffset) {
  const Take truth = OffsetTake(5, 60, 2.0);
  const std::vector<int> all = {0, 1, 2, 3, 4};
  auto exact = SynthesisErrors(truth, truth, all, 2);
  ASSERT_TRUE(exact.ok()) << exact.status().message();
  EXPECT_NEAR((*exact)["offset_mean_mm"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR((*exact)["position_mean_mm"].get<double>(), 0.0, 1e-6);
  // Mean of 2 |sin(0.5 t)| over frames 2..57: near 2 * 2/pi.
  auto none = NoDynamicsErrors(Quasistatic(truth), truth, all, 2);
  ASSERT_TRUE(none.ok()) << none.status().message();
  EXPECT_NEAR((*none)["offset_mean_mm"].get<double>(), 4.0 / M_PI, 0.05);
  EXPECT_NEAR((*none)["position_mean_mm"].get<double>(), (*none)["offset_mean_mm"].get<double>(),
              1e-3);
  // A synthesis that got the offsets' sign wrong is twice as far as none.
  Take flipped = truth;
  flipped.channels["dynamic_offset"].positions *= -1.0f;
  auto wrong = SynthesisErrors(flipped, truth, all, 2);
  ASSERT_TRUE(wrong.ok());
  EXPECT_NEAR((*wrong)["offset_mean_mm"].get<double>(),
              2 * (*none)["offset_mean_mm"].get<double>(), 1e-3);
}

TEST(SynthesisScoring, MissingChannelOrCountIsNamed) {
  const Take truth = OffsetTake(5, 60, 2.0);
  auto missing = SynthesisErrors(Quasistatic(truth), truth, {0}, 2);
  ASSERT_FALSE(missing.ok());
  EXPECT_THAT(missing.status().message(), HasSubstr("synthesised take has no \"dynamic_offset\""));
  auto short_take = NoDynamicsErrors(OffsetTake(5, 30, 1.0), truth, {0}, 2);
  ASSERT_FALSE(short_take.ok());
  EXPECT_THAT(short_take.status().message(), HasSubstr("30 frames"));
}

// Fig. 7: a perfect remove-and-resynthesise leaves no residual; removal alone leaves the
// dynamics themselves. Against a reconstruction (another take than the simulation) the
// figures also say how far the resynthesis is from the simulated skin.
TEST(SynthesisScoring, ResynthesisFiguresOfPerfectAndOfRemovalOnly) {
  const Take simulated = OffsetTake(5, 60, 2.0);
  const Take removed = Quasistatic(simulated);
  auto figures = ResynthesisFigures("t", simulated, simulated, removed, simulated, 2);
  ASSERT_TRUE(figures.ok()) << figures.status().message();
  EXPECT_NEAR((*figures)["resynthesis_residual_mm"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR((*figures)["removed_without_synthesis_mm"].get<double>(),
              (*figures)["mean_dynamic_offset_mm"].get<double>(), 1e-3);
  EXPECT_FALSE(figures->contains("resynthesised_vs_simulated_dynamic_mm"));
  Take reconstructed = simulated;
  reconstructed.positions.positions.array() += 0.1f;  // a reconstruction 0.17 mm off
  auto on_reconstruction =
      ResynthesisFigures("t", simulated, reconstructed, removed, reconstructed, 2);
  ASSERT_TRUE(on_reconstruction.ok());
  EXPECT_NEAR((*on_reconstruction)["resynthesis_residual_mm"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR((*on_reconstruction)["resynthesised_vs_simulated_dynamic_mm"].get<double>(),
              0.1 * std::sqrt(3.0), 1e-3);
}

// Retargeting scores the target against a truth simulated under the source's head motion; a
// target truth under another motion is refused, naming the first frame that differs.
TEST(ScoreRetargeting, RefusesTruthsUnderDifferentHeadMotions) {
  sim::ProceduralFaceOptions face_options;
  auto face = sim::MakeProceduralFace(face_options);
  ASSERT_TRUE(face.ok()) << face.status().message();
  sim::PerformanceOptions perform;
  perform.seconds = 0.4;  // shorter than the hold start (0.55 s): nothing to score
  perform.motion.kind = sim::MotionKind::kPlatform;
  perform.motion.platform_hz = 8.0;
  auto source = sim::SimulatePerformance(*face, perform);
  ASSERT_TRUE(source.ok()) << source.status().message();
  perform.motion.platform_hz = 9.0;
  auto other = sim::SimulatePerformance(*face, perform);
  ASSERT_TRUE(other.ok());
  auto model = dynamics::SynthesisModel::Create(
      dynamics::SynthesisConfig::ForRig(*face, source->info.fps), 1);
  ASSERT_TRUE(model.ok()) << model.status().message();
  const Take quasistatic = Quasistatic(*other);
  auto refused = ScoreRetargeting(*model, *source, *face, *other, *face, quasistatic, 2);
  ASSERT_FALSE(refused.ok());
  EXPECT_THAT(refused.status().message(), HasSubstr("differs from the source's at frame"));
  auto too_short =
      ScoreRetargeting(*model, *source, *face, *source, *face, Quasistatic(*source), 2);
  ASSERT_FALSE(too_short.ok());
  EXPECT_THAT(too_short.status().message(), HasSubstr("retargeting: no frame to score"));
  // Without a hold start every frame but the margins counts: no dynamics costs the target's
  // mean true offset.
  source->info.hold_start_s.reset();
  auto scored = ScoreRetargeting(*model, *source, *face, *source, *face, Quasistatic(*source), 2);
  ASSERT_TRUE(scored.ok()) << scored.status().message();
  EXPECT_NEAR(scored->figures["methods"]["no_dynamics"]["offset_mean_mm"].get<double>(),
              scored->figures["mean_dynamic_offset_mm"].get<double>(), 1e-3);
  EXPECT_GT(scored->figures["mean_dynamic_offset_mm"].get<double>(), 0.0);
  EXPECT_EQ(scored->retargeted.frame_count(), source->frame_count());
  EXPECT_EQ(scored->figures["methods"].count("modal_B_retarget"), 0u);
  EXPECT_EQ(scored->modal.frame_count(), 0);
  // With a modal model (trained here on the source's exact decomposition) it is scored too.
  const Take decomposed = dynamics::DecomposeExact(*source).value();
  dynamics::ModalSynthesisOptions modal_options;
  modal_options.margin_s = 0.0;  // a 0.4 s take
  modal_options.resonator_hz = {6.0, 9.0, 13.0};
  modal_options.resonator_damping = 1.0;  // settles in 0.02 s
  auto modal = dynamics::ModalSynthesisModel::Train({{&decomposed, &*face}}, modal_options);
  ASSERT_TRUE(modal.ok()) << modal.status().message();
  auto with_modal = ScoreRetargeting(*model, *source, *face, *source, *face, Quasistatic(*source),
                                     2, &*modal);
  ASSERT_TRUE(with_modal.ok()) << with_modal.status().message();
  EXPECT_EQ(with_modal->modal.frame_count(), source->frame_count());
  // Trained on the very offsets it is scored against: well below no dynamics.
  EXPECT_LT(with_modal->figures["methods"]["modal_B_retarget"]["offset_mean_mm"].get<double>(),
            0.5 * with_modal->figures["mean_dynamic_offset_mm"].get<double>());
}

// The held shape of a constant shape carried by any rigid motion is that shape; the scaled
// rig scales every skull-frame position and refuses a scale that is not positive.
TEST(MeanShapeAndScaledRig, RecoverTheShapeAndScaleThePositions) {
  Take take = OffsetTake(4, 20, 0.0);
  for (int t = 0; t < 20; ++t) {
    take.world_from_skull[t] = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitZ(), 0.1 * t,
                                                     {1.0 * t, -2.0, 3.0});
    take.positions.Frame(t) =
        take.world_from_skull[t].Apply(take.topology.positions_mm).cast<float>();
  }
  EXPECT_TRUE(dynamics::MeanShapeInSkull(take, 3).isApprox(take.topology.positions_mm, 1e-5));
  sim::ProceduralFaceOptions face_options;
  auto face = sim::MakeProceduralFace(face_options);
  ASSERT_TRUE(face.ok());
  auto scaled = sim::ScaledFaceRig(*face, {2.0, 1.0, 0.5}, "b");
  ASSERT_TRUE(scaled.ok()) << scaled.status().message();
  EXPECT_TRUE(scaled->neutral.positions_mm.row(0).isApprox(2.0 * face->neutral.positions_mm.row(0)));
  EXPECT_TRUE(scaled->neutral.positions_mm.row(2).isApprox(0.5 * face->neutral.positions_mm.row(2)));
  EXPECT_EQ(scaled->name, "b");
  auto refused = sim::ScaledFaceRig(*face, {1.0, 0.0, 1.0}, "c");
  ASSERT_FALSE(refused.ok());
  EXPECT_THAT(refused.status().message(), HasSubstr("must be > 0"));
}

}  // namespace
}  // namespace facedyn::eval
