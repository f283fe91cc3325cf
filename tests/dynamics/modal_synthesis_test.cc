// Modal synthesis (dynamics/modal_synthesis.h): the skull's inertial inputs against analytic
// motions, and the fitted model against an exactly known linear tissue, a damped oscillator of
// another frequency and damping than any resonator of the bank, on a head motion it never saw.

#include "dynamics/modal_synthesis.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>

#include "core/file_util.h"
#include "dynamics/baselines.h"
#include "dynamics/quasistatic.h"
#include "dynamics/synthesis_model.h"
#include "sim/procedural_face.h"

namespace facedyn::dynamics {
namespace {

using ::testing::HasSubstr;

constexpr double kFps = 128.0;

const FaceRig& Face() {
  static const FaceRig* rig = [] {
    sim::ProceduralFaceOptions options;
    options.target_vertex_count = 4000;
    return new FaceRig(sim::MakeProceduralFace(options).value());
  }();
  return *rig;
}

struct Sine {
  double amplitude_mm, hz, phase;
};

// A translation-only head motion: per axis a sum of sines (mm), with its analytic acceleration.
struct MultiSine {
  std::vector<Sine> axes[3];
  Eigen::Vector3d Position(double t) const {
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int a = 0; a < 3; ++a) {
      for (const Sine& s : axes[a])
        p(a) += s.amplitude_mm * std::sin(2 * M_PI * s.hz * t + s.phase);
    }
    return p;
  }
  Eigen::Vector3d Acceleration(double t) const {
    Eigen::Vector3d acc = Eigen::Vector3d::Zero();
    for (int a = 0; a < 3; ++a) {
      for (const Sine& s : axes[a]) {
        const double w = 2 * M_PI * s.hz;
        acc(a) -= s.amplitude_mm * w * w * std::sin(w * t + s.phase);
      }
    }
    return acc;
  }
};

// The exact tissue: every vertex's offset d (skull frame, mm) obeys
// d'' + 2 z w d' + w^2 d = -a(t), from rest, integrated by RK4 at 20 substeps per frame.
PointCache OscillatorOffsets(const MultiSine& motion, int frames, int vertices, double hz,
                             double damping) {
  const double w = 2 * M_PI * hz;
  Eigen::Vector3d d = Eigen::Vector3d::Zero(), v = Eigen::Vector3d::Zero();
  auto accel = [&](double t, const Eigen::Vector3d& x, const Eigen::Vector3d& xv) {
    return Eigen::Vector3d(-motion.Acceleration(t) - 2 * damping * w * xv - w * w * x);
  };
  PointCache out;
  out.vertex_count = vertices;
  out.positions.resize(3 * static_cast<Eigen::Index>(vertices), frames);
  const int substeps = 20;
  const double h = 1.0 / (kFps * substeps);
  for (int f = 0; f < frames; ++f) {
    out.Frame(f).colwise() = d.cast<float>();
    for (int s = 0; s < substeps; ++s) {
      const double t = f / kFps + s * h;
      const Eigen::Vector3d k1x = v, k1v = accel(t, d, v);
      const Eigen::Vector3d k2x = v + 0.5 * h * k1v, k2v = accel(t + h / 2, d + 0.5 * h * k1x, k2x);
      const Eigen::Vector3d k3x = v + 0.5 * h * k2v, k3v = accel(t + h / 2, d + 0.5 * h * k2x, k3x);
      const Eigen::Vector3d k4x = v + h * k3v, k4v = accel(t + h, d + h * k3x, k4x);
      d += h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
      v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
    }
  }
  return out;
}

std::vector<Rigid3> Poses(const MultiSine& motion, int frames) {
  std::vector<Rigid3> poses;
  for (int f = 0; f < frames; ++f)
    poses.push_back(Rigid3::FromTranslation(motion.Position(f / kFps)));
  return poses;
}

// A decomposed take of the neutral under `motion` with the oscillator's exact offsets.
Take OscillatorTake(const MultiSine& motion, int frames) {
  const FaceRig& rig = Face();
  Take take = HeldShapeTake(rig, rig.neutral.positions_mm, Poses(motion, frames), kFps);
  take.channels["dynamic_offset"] =
      OscillatorOffsets(motion, frames, rig.vertex_count(), 8.5, 0.17);
  return take;
}

// Per axis, sines every 0.5 Hz from `first_hz` to 16 Hz, amplitude 1.5 mm (vertical) or 0.6 mm
// at 1 Hz falling as 1 / f^2 (a flat acceleration spectrum), phases drawn from `seed`: a
// broadband excitation like a walk's, so the response is identified across the band.
MultiSine Broadband(double first_hz, unsigned seed) {
  MultiSine m;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> phase(0, 2 * M_PI);
  for (int a = 0; a < 3; ++a) {
    for (double hz = first_hz; hz <= 16.0; hz += 0.5) {
      m.axes[a].push_back({(a == 1 ? 1.5 : 0.6) / (hz * hz), hz, phase(rng)});
    }
  }
  return m;
}

// Training on one grid, the held-out motion on frequencies between its lines.
MultiSine TrainingMotion() { return Broadband(1.0, 1); }
MultiSine HeldOutMotion() { return Broadband(1.25, 2); }

TEST(SkullInertialInputs, MatchAnalyticTranslationAndRotationAccelerations) {
  // Translation 2 sin(2 pi 6 t) along world y with the skull turned 90 degrees about z: in the
  // skull frame the acceleration lies along -x.
  const double w = 2 * M_PI * 6.0;
  std::vector<Rigid3> poses;
  const Rigid3 turned = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitZ(), M_PI / 2);
  for (int f = 0; f < 128; ++f) {
    poses.push_back(Rigid3(turned.rotation(), Eigen::Vector3d(0, 2 * std::sin(w * f / kFps), 0)));
  }
  const Eigen::MatrixXd in = SkullInertialInputs(poses, kFps).value();
  ASSERT_EQ(in.rows(), 6);
  ASSERT_EQ(in.cols(), 128);
  for (int f = 10; f < 118; ++f) {
    const double expected = -2 * w * w * std::sin(w * f / kFps);
    // Central differences at 21 frames per period: within 1% of the peak.
    EXPECT_NEAR(in(0, f), expected, 0.01 * 2 * w * w) << f;
    EXPECT_NEAR(in(1, f), 0.0, 1e-6) << f;
    EXPECT_NEAR(in.block(3, f, 3, 1).norm(), 0.0, 1e-6) << f;
  }
  // Pitch 0.01 sin(2 pi 4 t) about x: angular acceleration -0.01 w^2 sin, about x.
  const double w2 = 2 * M_PI * 4.0;
  poses.clear();
  for (int f = 0; f < 128; ++f) {
    poses.push_back(
        Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), 0.01 * std::sin(w2 * f / kFps)));
  }
  const Eigen::MatrixXd pitch = SkullInertialInputs(poses, kFps).value();
  for (int f = 10; f < 118; ++f) {
    EXPECT_NEAR(pitch(3, f), -0.01 * w2 * w2 * std::sin(w2 * f / kFps), 0.01 * 0.01 * w2 * w2);
    EXPECT_NEAR(pitch(4, f), 0.0, 1e-6);
    EXPECT_NEAR(pitch.block(0, f, 3, 1).norm(), 0.0, 1e-6);
  }
  EXPECT_FALSE(SkullInertialInputs(poses, 0.0).ok());
}

TEST(ModalSynthesis, ReproducesADampedOscillatorOnAHeadMotionItNeverSaw) {
  const int frames = 384;  // 3 s
  const Take training = OscillatorTake(TrainingMotion(), frames);
  const Take held_out = OscillatorTake(HeldOutMotion(), frames);
  ModalSynthesisFit fit;
  const auto model =
      ModalSynthesisModel::Train({{&training, &Face()}}, ModalSynthesisOptions(), &fit);
  ASSERT_TRUE(model.ok()) << model.status().message();
  EXPECT_EQ(fit.validation_rms_mm.size(), ModalSynthesisOptions().ridge.size());
  EXPECT_GT(fit.validation_frames, 0);

  // Synthesise the held-out motion on the neutral and compare with the oscillator's offsets.
  const Take quasistatic =
      HeldShapeTake(Face(), Face().neutral.positions_mm, std::vector<Rigid3>(frames), kFps);
  const auto synthesised =
      model->Synthesize(quasistatic, held_out.world_from_skull, "held-out", Face());
  ASSERT_TRUE(synthesised.ok()) << synthesised.status().message();
  const PointCache& truth = held_out.channels.at("dynamic_offset");
  const PointCache& offsets = synthesised->channels.at("dynamic_offset");
  double err_sq = 0, truth_sq = 0;
  for (int f = 64; f < frames; ++f) {  // after the first half second
    const int v = Face().skin_samples.front().vertices[0];
    err_sq += (offsets.Frame(f).col(v) - truth.Frame(f).col(v)).cast<double>().squaredNorm();
    truth_sq += truth.Frame(f).col(v).cast<double>().squaredNorm();
  }
  const double relative = std::sqrt(err_sq / truth_sq);
  // Measured 0.042 with the default bank (the oscillator lies between two of its lines).
  EXPECT_LT(relative, 0.06) << "relative RMS error " << relative;
  // The synthesised take is the quasistatic re-posed plus the offsets.
  const Eigen::Matrix3Xf expected =
      synthesised->channels.at("quasistatic").Frame(100) + offsets.Frame(100);
  EXPECT_LT((synthesised->positions.Frame(100) - expected).cwiseAbs().maxCoeff(), 1e-4f);
}

// The ridge rules on three takes (leave one take out, three folds) whose offsets carry
// measurement noise: the minimum picks the least mean validation error; one standard error picks
// the largest ridge within one standard error of it, so never a smaller one.
TEST(ModalSynthesis, OneStandardErrorRulePicksTheLargestRidgeWithinOneErrorOfTheLeast) {
  const int frames = 256;
  std::vector<Take> takes;
  std::mt19937 rng(5);
  std::normal_distribution<float> noise(0.0f, 0.05f);
  for (unsigned seed : {3u, 4u, 6u}) {
    takes.push_back(OscillatorTake(Broadband(1.0 + 0.25 * (seed % 2), seed), frames));
    PointCache& offsets = takes.back().channels.at("dynamic_offset");
    for (Eigen::Index i = 0; i < offsets.positions.size(); ++i)
      offsets.positions.data()[i] += noise(rng);
  }
  std::vector<TrainingTake> training;
  for (const Take& take : takes) training.push_back({&take, &Face()});
  ModalSynthesisOptions options;
  ModalSynthesisFit minimum, one_se;
  ASSERT_TRUE(ModalSynthesisModel::Train(training, options, &minimum).ok());
  options.ridge_rule = RidgeRule::kOneStandardError;
  const auto model = ModalSynthesisModel::Train(training, options, &one_se);
  ASSERT_TRUE(model.ok()) << model.status().message();
  EXPECT_EQ(one_se.validation, "leave one take out");
  ASSERT_EQ(one_se.validation_standard_error.size(), options.ridge.size());
  ASSERT_EQ(one_se.validation_relative, minimum.validation_relative);
  // The minimum's choice, from the reported errors.
  size_t best = 0;
  for (size_t r = 0; r < options.ridge.size(); ++r) {
    EXPECT_GT(one_se.validation_standard_error[r], 0.0);
    if (one_se.validation_relative[r] < one_se.validation_relative[best]) best = r;
  }
  EXPECT_EQ(minimum.chosen_ridge, options.ridge[best]);
  // One standard error: the largest ridge whose mean squared relative error is within the bound.
  const double bound =
      std::pow(one_se.validation_relative[best], 2) + one_se.validation_standard_error[best];
  double expected = options.ridge[best];
  for (size_t r = 0; r < options.ridge.size(); ++r)
    if (std::pow(one_se.validation_relative[r], 2) <= bound)
      expected = std::max(expected, options.ridge[r]);
  EXPECT_EQ(one_se.chosen_ridge, expected);
  // With this much noise the two differ (measured: minimum 0.01, one standard error 0.1).
  EXPECT_GT(one_se.chosen_ridge, minimum.chosen_ridge);
  EXPECT_EQ(one_se.ridge_rule, RidgeRule::kOneStandardError);
  // The model's expected residual is the chosen ridge's.
  const size_t chosen = std::find(options.ridge.begin(), options.ridge.end(), one_se.chosen_ridge) -
                        options.ridge.begin();
  EXPECT_NEAR(model->validation_residual(), one_se.validation_relative[chosen], 1e-12);
  // With a single take (validation blocks, one fold) the rule falls back to the minimum.
  ModalSynthesisFit single_min, single_se;
  options.ridge_rule = RidgeRule::kMinimum;
  ASSERT_TRUE(ModalSynthesisModel::Train({training[0]}, options, &single_min).ok());
  options.ridge_rule = RidgeRule::kOneStandardError;
  ASSERT_TRUE(ModalSynthesisModel::Train({training[0]}, options, &single_se).ok());
  EXPECT_EQ(single_se.chosen_ridge, single_min.chosen_ridge);
  // Names round-trip; an unknown one is refused by name.
  EXPECT_EQ(ParseRidgeRule("one-standard-error").value(), RidgeRule::kOneStandardError);
  EXPECT_EQ(ParseRidgeRule(RidgeRuleName(RidgeRule::kMinimum)).value(), RidgeRule::kMinimum);
  EXPECT_THAT(ParseRidgeRule("median").status().message(), HasSubstr("median"));
}

TEST(ModalSynthesis, ErrorsNameTheProblem) {
  const int frames = 200;
  const Take training = OscillatorTake(TrainingMotion(), frames);
  EXPECT_THAT(ModalSynthesisModel::Train({}, ModalSynthesisOptions()).status().message(),
              HasSubstr("no training takes"));
  Take without = training;
  without.channels.clear();
  EXPECT_THAT(
      ModalSynthesisModel::Train({{&without, &Face()}}, ModalSynthesisOptions()).status().message(),
      HasSubstr("dynamic_offset"));
  Take other_fps = training;
  other_fps.info.fps = 96;
  EXPECT_THAT(ModalSynthesisModel::Train({{&training, &Face()}, {&other_fps, &Face()}},
                                         ModalSynthesisOptions())
                  .status()
                  .message(),
              HasSubstr("fps"));
  EXPECT_THAT(ModalSynthesisModel::Train({{&training, &Face(), RemovalTargets::kExact}},
                                         ModalSynthesisOptions())
                  .status()
                  .message(),
              HasSubstr("training take 0 sets its own targets or a weight"));
  ModalSynthesisOptions high;
  high.resonator_hz = {70.0};  // above 64 Hz, Nyquist at 128 fps
  EXPECT_THAT(ModalSynthesisModel::Train({{&training, &Face()}}, high).status().message(),
              HasSubstr("Nyquist"));
  ModalSynthesisOptions bad;
  bad.ridge = {};
  EXPECT_THAT(bad.Check().message(), HasSubstr("ridge"));
  bad = ModalSynthesisOptions();
  bad.resonator_damping = 0;
  EXPECT_THAT(bad.Check().message(), HasSubstr("resonator_damping"));

  const auto model = ModalSynthesisModel::Train({{&training, &Face()}}, ModalSynthesisOptions());
  ASSERT_TRUE(model.ok()) << model.status().message();
  std::vector<Rigid3> short_motion(frames - 1);
  EXPECT_THAT(model->Synthesize(training, short_motion, "x", Face()).status().message(),
              HasSubstr("poses"));
  sim::ProceduralFaceOptions other_options;
  other_options.target_vertex_count = 5000;
  const FaceRig other = sim::MakeProceduralFace(other_options).value();
  const Take other_take =
      HeldShapeTake(other, other.neutral.positions_mm, training.world_from_skull, kFps);
  EXPECT_THAT(
      model->Synthesize(other_take, training.world_from_skull, "x", other).status().message(),
      HasSubstr("skin samples"));
}

TEST(ModalSynthesis, RemovalTakesAwayExactlyWhatSynthesisAdds) {
  const int frames = 384;
  const Take training = OscillatorTake(TrainingMotion(), frames);
  const auto model = ModalSynthesisModel::Train({{&training, &Face()}}, ModalSynthesisOptions());
  ASSERT_TRUE(model.ok()) << model.status().message();
  // A captured take made by the model itself: removal must give back the quasistatic.
  const Take held_out = OscillatorTake(HeldOutMotion(), frames);
  const Take quasistatic =
      HeldShapeTake(Face(), Face().neutral.positions_mm, held_out.world_from_skull, kFps);
  const Take synthesised =
      model->Synthesize(quasistatic, held_out.world_from_skull, "held-out", Face()).value();
  Take captured = synthesised;
  captured.channels.clear();
  const auto removed = model->Remove(captured, Face());
  ASSERT_TRUE(removed.ok()) << removed.status().message();
  EXPECT_EQ(removed->info.source, "dynamics modal removal");
  EXPECT_LT((removed->positions.positions - quasistatic.positions.positions).cwiseAbs().maxCoeff(),
            1e-3f);
  EXPECT_LT((removed->channels.at("dynamic_offset").positions -
             synthesised.channels.at("dynamic_offset").positions)
                .cwiseAbs()
                .maxCoeff(),
            1e-5f);

  // On the oscillator's own take (a motion the model never saw), removal leaves the neutral to
  // within the synthesis's error, and the low-pass after it no more.
  Take dynamic = held_out;
  for (int f = 0; f < frames; ++f) {
    const Eigen::Matrix3f rotation = dynamic.world_from_skull[f].RotationMatrix().cast<float>();
    dynamic.positions.Frame(f) += rotation * dynamic.channels.at("dynamic_offset").Frame(f);
  }
  dynamic.channels.clear();
  double cutoff = 0;
  const auto filtered = model->RemoveThenLowPass(dynamic, Face(), &cutoff);
  ASSERT_TRUE(filtered.ok()) << filtered.status().message();
  EXPECT_EQ(cutoff, LowPassCutoffAfterRemoval(dynamic, model->validation_residual()));
  EXPECT_GE(cutoff, LowPassCutoffByRule(dynamic));
  EXPECT_DOUBLE_EQ(filtered->info.metadata["removal_lowpass_hz"].get<double>(), cutoff);
  const auto plain = model->Remove(dynamic, Face()).value();
  double plain_sq = 0, filtered_sq = 0, offset_sq = 0;
  for (int f = 64; f < frames - 64; ++f) {
    plain_sq += (plain.positions.Frame(f) - quasistatic.positions.Frame(f)).squaredNorm();
    filtered_sq += (filtered->positions.Frame(f) - quasistatic.positions.Frame(f)).squaredNorm();
    offset_sq += held_out.channels.at("dynamic_offset").Frame(f).squaredNorm();
  }
  EXPECT_LT(std::sqrt(plain_sq / offset_sq), 0.06);
  EXPECT_LE(filtered_sq, plain_sq * 1.0001);
  // What was taken away in all is the offset channel: positions + offsets = the capture.
  const Eigen::Matrix3Xf back = dynamic.world_from_skull[100].RotationMatrix().cast<float>() *
                                filtered->channels.at("dynamic_offset").Frame(100);
  EXPECT_LT(
      (filtered->positions.Frame(100) + back - dynamic.positions.Frame(100)).cwiseAbs().maxCoeff(),
      1e-3f);
}

TEST(ModalSynthesis, SavedModelPredictsTheSameAndCorruptFilesAreNamed) {
  const int frames = 256;
  const Take training = OscillatorTake(TrainingMotion(), frames);
  const auto model = ModalSynthesisModel::Train({{&training, &Face()}}, ModalSynthesisOptions());
  ASSERT_TRUE(model.ok()) << model.status().message();
  const std::string dir = testing::TempDir() + "/modal_save";
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/modal.bin";
  ASSERT_TRUE(model->Save(path).ok());
  const auto loaded = ModalSynthesisModel::Load(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  EXPECT_EQ(loaded->rig_name(), Face().name);
  EXPECT_EQ(loaded->validation_residual(), model->validation_residual());
  const std::vector<Rigid3> motion = Poses(HeldOutMotion(), frames);
  EXPECT_EQ(
      (loaded->PredictSampleOffsets(motion).value() - model->PredictSampleOffsets(motion).value())
          .cwiseAbs()
          .maxCoeff(),
      0.0f);
  const Take take = HeldShapeTake(Face(), Face().neutral.positions_mm, motion, kFps);
  EXPECT_EQ((loaded->Remove(take, Face()).value().positions.positions -
             model->Remove(take, Face()).value().positions.positions)
                .cwiseAbs()
                .maxCoeff(),
            0.0f);

  const std::string bytes = ReadFileToString(path).value();
  auto load_bytes = [&](const std::string& content) {
    const std::string bad = dir + "/bad.bin";
    EXPECT_TRUE(WriteFileAtomic(bad, content).ok());
    return ModalSynthesisModel::Load(bad).status();
  };
  EXPECT_THAT(load_bytes("not a model").message(), HasSubstr("FDMODAL"));
  for (size_t cut : {size_t{8}, size_t{20}, bytes.size() / 2, bytes.size() - 3}) {
    const Status status = load_bytes(bytes.substr(0, cut));
    EXPECT_EQ(status.code(), StatusCode::kDataLoss) << cut;
    EXPECT_THAT(status.message(), HasSubstr("bad.bin")) << cut;
  }
  EXPECT_THAT(load_bytes(bytes + "x").message(), HasSubstr("after the trailer"));
  std::string version = bytes;
  version[8] = 9;
  EXPECT_THAT(load_bytes(version).message(), HasSubstr("format version 9"));
  EXPECT_FALSE(ModalSynthesisModel::Load(dir + "/missing.bin").ok());
}

TEST(LowPassCutoffAfterRemoval, LeavesTheRulesShareOfTheJiggle) {
  Take take;
  take.info.fps = kFps;
  take.info.platform_hz = 10.0;
  const double f = 10.0;
  EXPECT_DOUBLE_EQ(LowPassCutoffByRule(take), f / 3);
  EXPECT_DOUBLE_EQ(LowPassCutoffAfterRemoval(take, 1.0), f / 3);
  EXPECT_DOUBLE_EQ(LowPassCutoffAfterRemoval(take, 3.0), f / 3);  // never below the rule
  EXPECT_DOUBLE_EQ(LowPassCutoffAfterRemoval(take, 0.0), 0.45 * kFps);
  for (double r : {0.5, 0.3, 0.1, 0.05}) {
    const double fc = LowPassCutoffAfterRemoval(take, r);
    // The forward-backward 2nd-order Butterworth passes 1 / (1 + (f / fc)^4) of a sine at f;
    // times what the removal left, that is the rule's 1 / (1 + 3^4) of the jiggle.
    const double gain = 1.0 / (1.0 + std::pow(f / fc, 4));
    EXPECT_NEAR(r * gain, 1.0 / 82.0, 1e-12) << r;
    EXPECT_GT(fc, f / 3);
  }
  EXPECT_DOUBLE_EQ(LowPassCutoffAfterRemoval(take, std::nan("")), f / 3);
}

}  // namespace
}  // namespace facedyn::dynamics
