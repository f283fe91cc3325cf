// The synthesis network H of Zoss et al. 2020, section 6 (dynamics/synthesis_model.h).

#include "dynamics/synthesis_model.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "sim/procedural_face.h"
#include "tests/support/test_support.h"

namespace facedyn::dynamics {
namespace {

using ::testing::HasSubstr;

const FaceRig& Face() {
  static const FaceRig* rig = [] {
    sim::ProceduralFaceOptions options;
    options.target_vertex_count = 4000;
    return new FaceRig(sim::MakeProceduralFace(options).value());
  }();
  return *rig;
}

std::vector<Rigid3> WobblingPoses(int frames, double fps, double phase) {
  std::vector<Rigid3> poses;
  for (int t = 0; t < frames; ++t) {
    const double s = t / fps + phase;
    const Eigen::Vector3d axis = Eigen::Vector3d(std::sin(3 * s), 1.0, 0.4).normalized();
    poses.push_back(Rigid3::FromAxisAngle(axis, 0.2 * std::sin(7 * s),
                                          {10 * std::sin(11 * s), 5 * s, 3 * std::cos(9 * s)}));
  }
  return poses;
}

// A decomposed take: the neutral held under wobbling poses, with dynamic offsets (every vertex
// the same) dx(t) = 0.004 s * velocity of landmark b1 (Eq. 2) — a known function of B(t).
Take DecomposedTake(const FaceRig& rig, int frames, double phase) {
  const double fps = 128;
  Take take = HeldShapeTake(rig, rig.neutral.positions_mm, WobblingPoses(frames, fps, phase), fps);
  const Eigen::MatrixXd velocity = SkullLandmarkVelocities(
      take.world_from_skull, {rig.skull_landmarks[0].position_in_skull}, fps);
  PointCache offsets = take.positions;
  for (int t = 0; t < frames; ++t) {
    offsets.Frame(t).colwise() = (0.004 * velocity.col(t)).cast<float>();
  }
  take.channels["dynamic_offset"] = offsets;
  return take;
}

TEST(SynthesisTrainOptions, DefaultsAreThePapersAndCheckNamesTheField) {
  SynthesisTrainOptions options;
  EXPECT_EQ(options.train.batch_size, 50);
  EXPECT_EQ(options.train.epochs, 30);
  EXPECT_EQ(options.hidden_units, 256);
  EXPECT_TRUE(options.Check().ok());
  options.stretch_step_mm = 0;
  EXPECT_THAT(options.Check().message(), HasSubstr("stretch_step_mm"));
}

TEST(SynthesisModel, SaveLoadIdenticalAndRefusesARemovalModel) {
  const FaceRig& rig = Face();
  const SynthesisModel model = SynthesisModel::Create(SynthesisConfig::ForRig(rig, 128), 2).value();
  EXPECT_EQ(model.config().output_size(), 3 * static_cast<int>(rig.skin_samples.size()));
  testing::TempDir dir;
  ASSERT_TRUE(model.Save(dir.Join("H.pt")).ok());
  const auto loaded = SynthesisModel::Load(dir.Join("H.pt"));
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  const Eigen::MatrixXf x = Eigen::MatrixXf::Random(model.config().input_size(), 7);
  const Eigen::MatrixXf a = model.Predict(x), b = loaded->Predict(x);
  EXPECT_EQ(std::memcmp(a.data(), b.data(), sizeof(float) * a.size()), 0);

  const RemovalModel removal = RemovalModel::Create(RemovalConfig::ForRig(rig, 128), 1).value();
  ASSERT_TRUE(removal.Save(dir.Join("F.pt")).ok());
  EXPECT_THAT(SynthesisModel::Load(dir.Join("F.pt")).status().message(),
              HasSubstr("is a removal model, expected a synthesis model"));
  EXPECT_THAT(RemovalModel::Load(dir.Join("H.pt")).status().message(),
              HasSubstr("is a synthesis model, expected a removal model"));
}

TEST(SynthesizeDynamics, ComposesPropagatedOffsetsUnderTheNewMotion) {
  const FaceRig& rig = Face();
  SynthesisModel model = SynthesisModel::Create(SynthesisConfig::ForRig(rig, 128), 2).value();
  // Output normalisation with a tiny std and a mean of (0.5, 1, 0) per sample: H ~ constant.
  const int n_in = model.config().input_size(), n_out = model.config().output_size();
  Eigen::VectorXf out_mean(n_out);
  for (int i = 0; i < n_out / 3; ++i)
    out_mean.segment<3>(3 * i) = Eigen::Vector3f(0.5f, 1.0f, 0.0f);
  model.mutable_mlp()->SetNormalisation(Eigen::VectorXf::Zero(n_in), Eigen::VectorXf::Ones(n_in),
                                        out_mean, Eigen::VectorXf::Constant(n_out, 1e-7f));
  const Take quasistatic =
      HeldShapeTake(rig, rig.neutral.positions_mm, WobblingPoses(40, 128, 0), 128);
  const std::vector<Rigid3> motion = WobblingPoses(40, 128, 2.0);
  const auto result = SynthesizeDynamics(model, quasistatic, motion, "wobble", rig);
  ASSERT_TRUE(result.ok()) << result.status().message();
  EXPECT_EQ(result->info.source, "dynamics synthesize");
  EXPECT_EQ(result->info.motion, "wobble");
  ASSERT_EQ(result->channels.count("quasistatic"), 1u);
  const PointCache& reposed = result->channels.at("quasistatic");
  for (int t = 0; t < 40; t += 13) {
    const Eigen::Matrix3Xf expected_reposed =
        motion[t].Apply(rig.neutral.positions_mm).cast<float>();
    EXPECT_LT((reposed.Frame(t) - expected_reposed).cwiseAbs().maxCoeff(), 1e-3);
    const Eigen::Vector3f expected_offset =
        (motion[t].RotationMatrix() * Eigen::Vector3d(0.5, 1.0, 0.0)).cast<float>();
    const Eigen::Matrix3Xf offset = result->positions.Frame(t) - reposed.Frame(t);
    EXPECT_LT((offset.colwise() - expected_offset).cwiseAbs().maxCoeff(), 5e-3) << "frame " << t;
  }
}

TEST(SynthesizeDynamics, RefusesAMotionOfAnotherLengthOrFps) {
  const FaceRig& rig = Face();
  const SynthesisModel model = SynthesisModel::Create(SynthesisConfig::ForRig(rig, 128), 2).value();
  const Take quasistatic =
      HeldShapeTake(rig, rig.neutral.positions_mm, WobblingPoses(40, 128, 0), 128);
  EXPECT_THAT(SynthesizeDynamics(model, quasistatic, WobblingPoses(39, 128, 0), "m", rig)
                  .status()
                  .message(),
              HasSubstr("39 poses"));
  const Take at96 = HeldShapeTake(rig, rig.neutral.positions_mm, WobblingPoses(40, 96, 0), 96);
  EXPECT_THAT(
      SynthesizeDynamics(model, at96, WobblingPoses(40, 96, 0), "m", rig).status().message(),
      HasSubstr("fps"));
}

TEST(TrainSynthesis, LearnsAKnownFunctionOfTheSkullMotion) {
  const FaceRig& rig = Face();
  const Take a = DecomposedTake(rig, 256, 0.0);
  const Take b = DecomposedTake(rig, 256, 0.9);
  const Take test = DecomposedTake(rig, 256, 2.1);
  SynthesisTrainOptions options;
  options.train.epochs = 60;
  options.train.show_progress = false;
  // The unseen take is this test's measure; a validation split (blocks plus gaps,
  // training_frames.h) would only take frames away from two short training takes.
  options.validation_fraction = 0;
  learn::MlpTrainSummary summary;
  const auto model = TrainSynthesis({{&a, &rig}, {&b, &rig}}, options, &summary);
  ASSERT_TRUE(model.ok()) << model.status().message();
  EXPECT_LT(summary.train_loss.back(), summary.train_loss.front() / 10);
  const auto result = SynthesizeDynamics(*model, test, test.world_from_skull, "wobble", rig);
  ASSERT_TRUE(result.ok()) << result.status().message();
  const PointCache& truth = test.channels.at("dynamic_offset");
  const PointCache& predicted = result->channels.at("dynamic_offset");
  double error = 0, magnitude = 0;
  for (int t = 10; t < 246; ++t) {
    error += (predicted.Frame(t) - truth.Frame(t)).colwise().norm().mean();
    magnitude += truth.Frame(t).colwise().norm().mean();
  }
  std::printf("synthesis on an unseen motion: mean error %.4f mm of %.4f mm\n", error / 236,
              magnitude / 236);
  EXPECT_LT(error, 0.3 * magnitude);
}

TEST(TrainSynthesis, KeepsTheStretchRangeAndClampsAnUnknownExpressionToIt) {
  // Trained on a held neutral face, H has seen one expression: a stretch far outside it (a
  // talking mouth) is predicted as the nearest stretch it knows, not extrapolated, and the
  // range survives a round trip. The skull descriptor is left as it is.
  const FaceRig& rig = Face();
  const Take a = DecomposedTake(rig, 96, 0.0);
  SynthesisTrainOptions options;
  options.train.epochs = 2;
  options.train.show_progress = false;
  options.validation_fraction = 0;
  auto model = TrainSynthesis({{&a, &rig}}, options);
  ASSERT_TRUE(model.ok()) << model.status().message();
  const int first = model->config().skull_descriptor_size();
  const int count = model->config().input_size() - first;
  const Eigen::MatrixXf range = model->stretch_range();
  ASSERT_EQ(range.rows(), 2);
  ASSERT_EQ(range.cols(), count);
  EXPECT_TRUE((range.row(0).array() <= range.row(1).array()).all());
  EXPECT_TRUE(range.allFinite());

  Eigen::MatrixXf inside = Eigen::MatrixXf::Random(model->config().input_size(), 3);
  Eigen::MatrixXf outside = inside;
  inside.middleRows(first, count) = range.row(1).transpose().replicate(1, 3);
  outside.middleRows(first, count) =
      (range.row(1).array() + 50.0f).matrix().transpose().replicate(1, 3);
  const Eigen::MatrixXf at_max = model->Predict(inside);
  EXPECT_EQ((model->Predict(outside) - at_max).cwiseAbs().maxCoeff(), 0.0f);
  // The unclamped network does extrapolate there: the clamp is what holds it.
  ASSERT_TRUE(model->set_stretch_range(Eigen::MatrixXf()).ok());
  EXPECT_GT((model->Predict(outside) - at_max).cwiseAbs().maxCoeff(), 1e-3f);
  ASSERT_TRUE(model->set_stretch_range(range).ok());
  // The skull descriptor rows are not clamped.
  Eigen::MatrixXf moved = inside;
  moved.topRows(first).array() += 50.0f;
  EXPECT_GT((model->Predict(moved) - at_max).cwiseAbs().maxCoeff(), 1e-3f);

  testing::TempDir dir;
  ASSERT_TRUE(model->Save(dir.Join("H.pt")).ok());
  const auto loaded = SynthesisModel::Load(dir.Join("H.pt"));
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  EXPECT_EQ(loaded->stretch_range(), range);
  EXPECT_EQ((loaded->Predict(outside) - at_max).cwiseAbs().maxCoeff(), 0.0f);

  EXPECT_THAT(model->set_stretch_range(Eigen::MatrixXf::Zero(2, count - 1)).message(),
              HasSubstr("expected 2 x"));
  Eigen::MatrixXf inverted = range;
  inverted(0, 4) = inverted(1, 4) + 1.0f;
  EXPECT_THAT(model->set_stretch_range(inverted).message(),
              HasSubstr("stretch feature 4 has minimum"));
  EXPECT_EQ(model->stretch_range(), range);  // a refused range leaves the model's
}

TEST(TrainSynthesis, RefusesATakeWithoutOffsets) {
  const FaceRig& rig = Face();
  Take take = DecomposedTake(rig, 40, 0.0);
  take.channels.clear();
  EXPECT_THAT(TrainSynthesis({{&take, &rig}}, SynthesisTrainOptions()).status().message(),
              HasSubstr("no dynamic_offset channel"));
  // Per-take targets and weights are F's (TrainRemoval); H refuses them instead of ignoring them.
  const Take decomposed = DecomposedTake(rig, 40, 0.0);
  EXPECT_THAT(TrainSynthesis({{&decomposed, &rig}, {&decomposed, &rig, std::nullopt, 2.0}},
                             SynthesisTrainOptions())
                  .status()
                  .message(),
              HasSubstr("training take 1 sets its own targets or a weight"));
}

TEST(NaiveDeltaTransfer, CopiesPerSampleOffsetsOntoTheTarget) {
  const FaceRig& rig = Face();
  const Take source = DecomposedTake(rig, 30, 0.0);
  const Take target =
      HeldShapeTake(rig, rig.neutral.positions_mm, WobblingPoses(30, 128, 1.0), 128);
  const auto result = NaiveDeltaTransfer(source, rig, target, rig);
  ASSERT_TRUE(result.ok()) << result.status().message();
  EXPECT_EQ(result->world_from_skull.size(), 30u);
  const PointCache& offsets = result->channels.at("dynamic_offset");
  for (int t = 5; t < 30; t += 7) {
    const Eigen::Vector3f expected = source.channels.at("dynamic_offset").Frame(t).col(0);
    EXPECT_LT((offsets.Frame(t).colwise() - expected).cwiseAbs().maxCoeff(),
              0.01 * expected.norm() + 1e-4);
  }
  const Take short_target =
      HeldShapeTake(rig, rig.neutral.positions_mm, WobblingPoses(20, 128, 1.0), 128);
  EXPECT_FALSE(NaiveDeltaTransfer(source, rig, short_target, rig).ok());
}

}  // namespace
}  // namespace facedyn::dynamics
