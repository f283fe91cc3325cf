// F and H trained together with the cycle of Zoss et al. 2020, section 8.1
// (dynamics/joint_training.h).

#include "dynamics/joint_training.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "dynamics/features.h"
#include "dynamics/quasistatic.h"
#include "sim/procedural_face.h"

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

// x(t) = T(t) (rest + e(t) + dx(t)): dx(t) = 0.004 s * (velocity of landmark b1, Eq. 2), the
// same at every vertex, is the dynamics; e(t), a uniform shift of the skin in the skull frame
// at `expression_hz` (0: none), stands for an expression that changes (it moves the skin
// without stretching it, so H's stretch input stays the one it was trained on). Channel
// "quasistatic" = T(t) (rest + e(t)), so the exact offsets are dx.
Take Performance(const FaceRig& rig, int frames, double phase, double expression_hz) {
  const double fps = 128;
  Take take;
  take.info.fps = fps;
  take.topology = rig.neutral;
  take.world_from_skull = WobblingPoses(frames, fps, phase);
  const Eigen::MatrixXd velocity = SkullLandmarkVelocities(
      take.world_from_skull, {rig.skull_landmarks[0].position_in_skull}, fps);
  take.positions.vertex_count = rig.vertex_count();
  take.positions.positions.resize(3 * rig.vertex_count(), frames);
  PointCache quasistatic = take.positions;
  for (int t = 0; t < frames; ++t) {
    const double s = t / fps + phase;
    const Eigen::Vector3d expression =
        expression_hz > 0 ? Eigen::Vector3d(0.0, 1.5 * std::sin(2 * M_PI * expression_hz * s),
                                            1.0 * std::cos(2 * M_PI * expression_hz * s))
                          : Eigen::Vector3d::Zero();
    const Eigen::Matrix3Xd held = rig.neutral.positions_mm.colwise() + expression;
    const Eigen::Vector3d dx = 0.004 * velocity.col(t);
    take.positions.Frame(t) =
        take.world_from_skull[t].Apply(Eigen::Matrix3Xd(held.colwise() + dx)).cast<float>();
    quasistatic.Frame(t) = take.world_from_skull[t].Apply(held).cast<float>();
  }
  take.channels["quasistatic"] = quasistatic;
  take.SetUniformTimes();
  return take;
}

JointTrainOptions QuickOptions() {
  JointTrainOptions options;
  options.removal.targets = RemovalTargets::kExact;
  options.removal.train.epochs = 12;
  options.removal.train.batch_size = 2000;
  options.removal.train.show_progress = false;
  options.removal.validation_fraction = 0;
  options.synthesis.train.epochs = 20;
  options.synthesis.train.batch_size = 16;
  options.synthesis.train.show_progress = false;
  options.synthesis.validation_fraction = 0;
  options.joint.steps = 300;
  options.joint.steps_per_report = 100;
  options.joint.learning_rate = 3e-4;
  options.joint.first_batch = 1000;
  options.joint.second_batch = 16;
  options.joint.pair_batch = 4;
  options.joint.show_progress = false;
  options.performance_validation_fraction = 0.1;
  return options;
}

// RMS over the usable frames and samples of F's sample offsets against the exact dx.
double SampleOffsetError(const RemovalModel& model, const Take& take, const FaceRig& rig) {
  const Eigen::MatrixXf predicted = PredictSampleOffsets(model, take, rig).value();
  const PointCache exact =
      DynamicOffsets(take.positions, take.channels.at("quasistatic"), take.world_from_skull)
          .value();
  const int samples = static_cast<int>(rig.skin_samples.size());
  const int w = model.config().features.window_frames();
  double sum = 0;
  long count = 0;
  for (int t = w + 1; t < take.frame_count() - w; ++t) {
    const auto frame = exact.Frame(t);
    for (int i = 0; i < samples; ++i) {
      const Eigen::Vector3f truth = rig.skin_samples[i].Evaluate(frame).cast<float>();
      sum += (predicted.col(static_cast<Eigen::Index>(t) * samples + i) - truth).squaredNorm();
      ++count;
    }
  }
  return std::sqrt(sum / count);
}

TEST(TrainJoint, TheCycleOnPerformancesTeachesFToIgnoreTheExpressionsMotion) {
  // F trained on held takes alone reads part of an expression's motion as jiggle; H, which
  // sees the head motion and the stretch but not the skin's velocity, cannot. The cycle on
  // performances (no targets) brings F to H's answer.
  const FaceRig& rig = Face();
  const Take held_a = Performance(rig, 192, 0.0, 0.0);
  const Take held_b = Performance(rig, 192, 0.9, 0.0);
  const Take performance = Performance(rig, 192, 1.7, 3.0);
  const Take unseen = Performance(rig, 192, 2.6, 2.5);  // another take, another rate
  const std::vector<TrainingTake> held = {{&held_a, &rig}, {&held_b, &rig}};
  JointTrainOptions options = QuickOptions();
  JointTrainSummary summary;
  const StatusOr<JointModels> joint = TrainJoint(held, {{&performance, &rig}}, options, &summary);
  ASSERT_TRUE(joint.ok()) << joint.status().message();
  // Step 1 alone is TrainRemoval with the same options and seed.
  const RemovalModel alone = TrainRemoval(held, options.removal).value();
  const double alone_mm = SampleOffsetError(alone, unseen, rig);
  const double joint_mm = SampleOffsetError(joint->removal, unseen, rig);
  const double held_alone_mm = SampleOffsetError(alone, held_a, rig);
  const double held_joint_mm = SampleOffsetError(joint->removal, held_a, rig);
  std::printf(
      "F's sample offsets on an unseen performance: alone %.4f mm, joint %.4f mm; "
      "on a held take %.4f, %.4f mm\n",
      alone_mm, joint_mm, held_alone_mm, held_joint_mm);
  EXPECT_LT(joint_mm, 0.7 * alone_mm);
  // ... and keeps its supervised answer on the held takes.
  EXPECT_LT(held_joint_mm, 0.02);  // of offsets of about 0.3 mm
  ASSERT_EQ(summary.joint.pair_loss.size(), 3u);
  EXPECT_LT(summary.joint.pair_loss.back(), summary.joint.pair_loss.front());
  EXPECT_GT(summary.performance_frames, 0);
  EXPECT_GT(summary.performance_validation_frames, 0);
  EXPECT_EQ(summary.joint.pair_validation_loss.size(), 3u);
}

// Step 3 alone on the pair trained separately (TrainRemoval, then TrainSynthesis on its
// decomposition) is TrainJoint: the same networks at the end. Short trainings and takes: what
// is checked is the equality, not what the cycle learns (the test above).
TEST(FineTuneJoint, OnTheSeparatelyTrainedPairIsTrainJoint) {
  const FaceRig& rig = Face();
  const Take held_a = Performance(rig, 64, 0.0, 0.0);
  const Take held_b = Performance(rig, 64, 0.9, 0.0);
  const Take performance = Performance(rig, 64, 1.7, 3.0);
  const std::vector<TrainingTake> held = {{&held_a, &rig}, {&held_b, &rig}};
  JointTrainOptions options = QuickOptions();
  options.removal.train.epochs = 2;
  options.synthesis.train.epochs = 2;
  options.joint.steps = 20;
  options.joint.steps_per_report = 10;
  JointTrainSummary summary;
  const StatusOr<JointModels> joint = TrainJoint(held, {{&performance, &rig}}, options, &summary);
  ASSERT_TRUE(joint.ok()) << joint.status().message();

  const RemovalModel alone = TrainRemoval(held, options.removal).value();
  std::vector<Take> decomposed;
  for (const TrainingTake& take : held) {
    decomposed.push_back(RemoveDynamics(alone, *take.take, rig).value());
  }
  const SynthesisModel h_alone =
      TrainSynthesis({{&decomposed[0], &rig}, {&decomposed[1], &rig}}, options.synthesis).value();
  JointTrainSummary tuned_summary;
  const StatusOr<JointModels> tuned = FineTuneJoint(held, {{&performance, &rig}}, alone.Clone(),
                                                    h_alone.Clone(), options, &tuned_summary);
  ASSERT_TRUE(tuned.ok()) << tuned.status().message();
  for (const auto& [joint_parameters, tuned_parameters] :
       {std::pair{joint->removal.FlatParameters(), tuned->removal.FlatParameters()},
        std::pair{joint->synthesis.FlatParameters(), tuned->synthesis.FlatParameters()}}) {
    ASSERT_EQ(joint_parameters.size(), tuned_parameters.size());
    double largest = 0;
    for (size_t k = 0; k < joint_parameters.size(); ++k) {
      largest = std::max(largest,
                         static_cast<double>(std::abs(joint_parameters[k] - tuned_parameters[k])));
    }
    EXPECT_LT(largest, 1e-6);
  }
  // Fine-tuned: the step moved F away from the pair it started from.
  EXPECT_NE(tuned->removal.FlatParameters(), alone.FlatParameters());
  EXPECT_EQ(tuned_summary.performance_frames, summary.performance_frames);
  EXPECT_EQ(tuned_summary.joint.pair_loss.size(), 2u);
  EXPECT_TRUE(tuned_summary.removal.train_loss.empty());

  // A given F whose inputs are not the rows' layout is refused, naming both.
  RemovalConfig narrow = alone.config();
  narrow.features.window_s = 0.04;
  const RemovalModel other = RemovalModel::Create(narrow, 1).value();
  EXPECT_THAT(FineTuneJoint(held, {{&performance, &rig}}, other.Clone(), h_alone.Clone(), options)
                  .status()
                  .message(),
              HasSubstr("the given F has"));
}

TEST(TrainJoint, RefusesMissingTakesAndPerformancesWithTargetsOrWeights) {
  const FaceRig& rig = Face();
  const Take held = Performance(rig, 64, 0.0, 0.0);
  const Take performance = Performance(rig, 64, 1.0, 3.0);
  const JointTrainOptions options = QuickOptions();
  EXPECT_THAT(TrainJoint({}, {{&performance, &rig}}, options).status().message(),
              HasSubstr("no held-expression takes"));
  EXPECT_THAT(TrainJoint({{&held, &rig}}, {}, options).status().message(),
              HasSubstr("no performance takes"));
  EXPECT_THAT(TrainJoint({{&held, &rig}}, {{&performance, &rig, std::nullopt, 2.0}}, options)
                  .status()
                  .message(),
              HasSubstr("performances"));
  const Take too_short = Performance(rig, 12, 1.0, 3.0);
  JointTrainOptions fast = options;
  fast.removal.train.epochs = 1;
  fast.synthesis.train.epochs = 1;
  EXPECT_THAT(TrainJoint({{&held, &rig}}, {{&too_short, &rig}}, fast).status().message(),
              HasSubstr("performance 0"));
  JointTrainOptions bad = options;
  bad.joint.pair_weight = -1;
  EXPECT_THAT(TrainJoint({{&held, &rig}}, {{&performance, &rig}}, bad).status().message(),
              HasSubstr("joint"));
}

}  // namespace
}  // namespace facedyn::dynamics
