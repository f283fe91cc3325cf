// twin_bench: material identification of issue 23 (the subject's physical twin), printed as JSON.
//
// A subject whose tissue the methods are not told (the procedural face with `--true-hz`
// fundamental and `--true-damping` damping ratio; the twin's prior is the model's defaults,
// 11 Hz and 0.22) stands on the simulated platform holding each of `--expressions` at each of
// `--frequencies` (default 6-10 Hz: the identification never sees the resonance it is asked
// for). Every take is then
//   - "reconstructed": filmed by the simulated 8-camera rig as `facedyn demo` films its takes
//     (eval/simulated_stage.h: the markers' projected centres with 0.2 px noise, calibrated
//     cameras, reconstruct/'s triangulation, labelling, skull pose and dense fit), or
//   - "clean": the simulated skin and skull pose themselves (a perfect capture), to separate the
//     identification's own error from the reconstruction's;
// and the twin is fitted to each set (physics/twin.h FitTwin: markers and skull pose only, never
// the truth channels). Scored against the truth: the twin's neutral cheek mode (continuous
// time, physics::SoftTissueModel::CheekMode) against the subject's configured fundamental and
// damping ratio, which the simulator reproduces in its motion (physics/soft_tissue.h,
// "Material"). Also the fit's seconds and phasor residuals. The twin is given the platform's
// amplitude (the rig's, 2 mm), so it also fits the body between platform and skull
// (physics/body_transmissibility.h), scored against the subject's body (--true-body-hz,
// --true-body-damping, --true-pitch-per-g; the simulator's standing body by default).
//
// "augmentation" (issue 23's "augmentation pays"; needs the reconstructed takes): does training
// data from the twin help F on head motions the session never captured? The subject is also
// filmed nodding and shaking its head (each of --expressions, one nod and one shake whose
// frequency and amplitude no training take has) and on the platform at --held-out-hz, all
// reconstructed the same way and kept out of every training set. Two removal networks F:
//   - "captured": the reconstructed platform takes only, platform-synchronous targets (the
//     session's own estimate, dynamics/quasistatic.h);
//   - "augmented": the same takes plus the twin simulated (as `facedyn twin perform` does, with
//     the fitted material, never the subject's) nodding and shaking at other frequencies and
//     amplitudes, on the twin's own exact quasistatic (dynamics::TrainingTake targets, weight
//     --twin-weight), for the same number of optimiser steps.
// Scored on each held-out take against the subject's exact quasistatic over its jiggling
// vertices (eval/metrics.h), beside doing nothing; the per-seed ratio augmented / captured on
// the nod and shake takes, and on the held-out platform frequency, is summarised over seeds.
//
//   twin_bench [--seeds 1,2,3] [--true-hz 9.0] [--true-damping 0.28] [--true-body-hz 5]
//              [--true-body-damping 0.35] [--true-pitch-per-g 0.013] [--frequencies 6,7,8,9,10]
//              [--expressions neutral,smile] [--seconds 2.5] [--no-reconstruct] [--no-clean]
//              [--no-augmentation] [--held-out-hz 11] [--twin-weight 0.25] [--epochs 40] [--quick]
//              [--no-targeting] [--lie-back-deg 45] [--robust-mm 0.5]
//              [--targeting-expressions neutral,smile,jaw_open,cheek_puff]
//
// --quick: one seed, frequencies 6,8,10, neutral only, 2 s takes.

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "bench/bench_flags.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/progress.h"
#include "dynamics/removal_model.h"
#include "eval/metrics.h"
#include "eval/replicates.h"
#include "eval/simulated_stage.h"
#include "physics/skull_kinematics.h"
#include "physics/twin.h"
#include "physics/twin_targeting.h"
#include "sim/expressions.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"

namespace {

using facedyn::Json;
using Clock = std::chrono::steady_clock;
namespace physics = facedyn::physics;
namespace sim = facedyn::sim;
namespace eval = facedyn::eval;

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

struct Settings {
  std::vector<uint64_t> seeds = {1, 2, 3};
  double true_hz = 9.0;
  double true_damping = 0.28;
  // The subject's body between platform and skull (sim::MotionOptions; the defaults are the
  // simulator's standing body) and the platform's peak displacement, which the fit is given as
  // a studio's rig config gives it.
  double true_body_hz = sim::MotionOptions{}.body_resonance_hz;
  double true_body_damping = sim::MotionOptions{}.body_damping_ratio;
  double true_pitch_per_g = sim::MotionOptions{}.pitch_rad_per_g;
  double platform_amplitude_mm = sim::MotionOptions{}.amplitude_mm;
  std::vector<double> frequencies = {6, 7, 8, 9, 10};
  std::vector<std::string> expressions = {"neutral", "smile"};
  double seconds = 2.5;
  bool reconstruct = true;
  // The simulator's integration step (physics::TissueOptions::max_step_s). At its shipped 1/128 s
  // Newmark's frequency warp makes the forced response at 6-10 Hz look ~6% more damped than
  // the configured damping ratio (which free vibration shows exactly); at 1/512 s the warp is
  // 16 times smaller. See the header.
  double sim_step_s = 1.0 / 512;
  bool clean = true;  // also fit the twin to the clean takes
  bool augmentation = true;
  bool targeting = true;
  double lie_back_deg = 45.0;
  double robust_mm = 0.5;  // Cauchy scale of the targeting's robust modes
  double lie_back_seconds = 3.0;
  std::vector<std::string> targeting_expressions = {"neutral", "smile", "jaw_open", "cheek_puff"};
  double held_out_hz = 11.0;
  double test_seconds = 3.0;
  // Each twin take's weight (dynamics::TrainingTake::weight). 0.25, so the 16 twin takes are
  // about 31% of the rows the augmented F is drawn from: tried on validation seeds 11-13 (the
  // only value tried there), where the held-out platform frequency was a tie with the captured F
  // (augmented / captured 0.98, 1.05, 1.05) and the held-out head motions 0.099 +- 0.018 of it.
  // At 1, on the test seeds before, the twin rows were two thirds and the platform frequency
  // was worse on every seed (README).
  double twin_weight = 0.25;
  int epochs = 40;
  // The held-out head motions of the subject (kind, Hz, degrees peak) and the twin's training
  // motions: every twin motion differs from every test motion in frequency and amplitude.
  struct HeadMotion {
    sim::MotionKind kind;
    double hz, deg;
  };
  std::vector<HeadMotion> test_motions = {{sim::MotionKind::kNod, 2.2, 12.0},
                                          {sim::MotionKind::kShake, 1.8, 16.0}};
  std::vector<HeadMotion> twin_motions = {
      {sim::MotionKind::kNod, 1.4, 8.0},    {sim::MotionKind::kNod, 3.0, 20.0},
      {sim::MotionKind::kNod, 1.4, 20.0},   {sim::MotionKind::kNod, 3.0, 8.0},
      {sim::MotionKind::kShake, 1.2, 10.0}, {sim::MotionKind::kShake, 2.6, 22.0},
      {sim::MotionKind::kShake, 1.2, 22.0}, {sim::MotionKind::kShake, 2.6, 10.0}};
};

[[noreturn]] void Fail(const std::string& message) {
  std::fprintf(stderr, "twin_bench: %s\n", message.c_str());
  std::exit(1);
}

template <typename T>
T Check(facedyn::StatusOr<T> value, const std::string& what) {
  if (!value.ok()) Fail(what + ": " + value.status().message());
  return std::move(*value);
}

Json FitJson(const physics::FittedTwin& twin, const Settings& s) {
  const double hz = twin.cheek_mode.omega_rad_s / (2 * M_PI);
  Json json = physics::TwinToJson(twin);
  json["score"] = {{"true_hz", s.true_hz},
                   {"true_damping_ratio", s.true_damping},
                   {"hz_error_percent", 100.0 * (hz - s.true_hz) / s.true_hz},
                   {"damping_error_percent",
                    100.0 * (twin.cheek_mode.damping_ratio - s.true_damping) / s.true_damping}};
  if (twin.body) {
    json["score"]["true_body_hz"] = s.true_body_hz;
    json["score"]["true_body_damping_ratio"] = s.true_body_damping;
    json["score"]["true_pitch_rad_per_g"] = s.true_pitch_per_g;
    json["score"]["body_hz_error_percent"] =
        100.0 * (twin.body->resonance_hz - s.true_body_hz) / s.true_body_hz;
    json["score"]["body_damping_error_percent"] =
        100.0 * (twin.body->damping_ratio - s.true_body_damping) / s.true_body_damping;
    json["score"]["pitch_error_percent"] =
        100.0 * (twin.body->pitch_rad_per_g - s.true_pitch_per_g) / s.true_pitch_per_g;
  }
  return json;
}

// The subject (its true tissue, which only the simulation and the scoring see) performing
// `expression` for `seconds`; the motion is the caller's.
sim::PerformanceOptions SubjectPerformance(const Settings& s, const std::string& expression,
                                           double seconds, uint64_t seed) {
  sim::PerformanceOptions options;
  options.expression = expression;
  options.seconds = seconds;
  options.seed = seed;
  options.tissue.fundamental_hz = s.true_hz;
  options.tissue.damping_ratio = s.true_damping;
  options.tissue.max_step_s = s.sim_step_s;
  return options;
}

// The platform at `hz` under the subject's true body (between platform and skull).
sim::MotionOptions SubjectOnPlatform(const Settings& s, double hz, uint64_t motion_seed) {
  sim::MotionOptions motion;
  motion.kind = sim::MotionKind::kPlatform;
  motion.platform_hz = hz;
  motion.seed = motion_seed;
  motion.amplitude_mm = s.platform_amplitude_mm;
  motion.body_resonance_hz = s.true_body_hz;
  motion.body_damping_ratio = s.true_body_damping;
  motion.pitch_rad_per_g = s.true_pitch_per_g;
  return motion;
}

const char* MotionName(sim::MotionKind kind) {
  return kind == sim::MotionKind::kNod ? "nod" : "shake";
}

// One held-out take of the subject: the simulation (truth kept, for scoring only) and its
// reconstruction (what the methods get).
struct HeldOutTake {
  std::string name;
  std::string protocol;  // "held-out head motion" or "held-out platform frequency"
  facedyn::Take simulated;
  facedyn::Take reconstructed;
};

// The augmentation study of one seed (see the header). `captured` are the reconstructed
// platform takes the twin was fitted to.
Json RunAugmentation(const facedyn::FaceRig& face, const eval::SimulatedCameraRig& cameras,
                     const Settings& s, uint64_t seed, const std::vector<facedyn::Take>& captured,
                     const physics::FittedTwin& twin, std::vector<double>* motion_ratios,
                     std::vector<double>* platform_ratios) {
  namespace dynamics = facedyn::dynamics;
  const auto start = Clock::now();
  // The subject's held-out takes.
  std::vector<HeldOutTake> tests;
  uint64_t reconstruction_seed = seed * 1000 + 500;
  auto film = [&](const std::string& name, const std::string& protocol,
                  const sim::PerformanceOptions& options) {
    HeldOutTake test{name, protocol, Check(sim::SimulatePerformance(face, options), name), {}};
    test.reconstructed =
        Check(eval::ReconstructSimulatedTake(face, cameras, test.simulated, reconstruction_seed++),
              "reconstruct " + name)
            .take;
    tests.push_back(std::move(test));
  };
  for (const std::string& expression : s.expressions) {
    sim::PerformanceOptions options = SubjectPerformance(s, expression, s.test_seconds, seed + 50);
    for (const Settings::HeadMotion& motion : s.test_motions) {
      options.motion = sim::MotionOptions();
      options.motion.kind = motion.kind;
      options.motion.head_motion_hz = motion.hz;
      options.motion.head_motion_deg = motion.deg;
      options.motion.seed = seed * 100 + 77;
      film(expression + " " + MotionName(motion.kind), "held-out head motion", options);
    }
    options.motion = SubjectOnPlatform(s, s.held_out_hz, seed * 100 + 99);
    film(expression + "@" + std::to_string(s.held_out_hz) + "Hz", "held-out platform frequency",
         options);
  }
  const double test_s = Seconds(start);

  // The twin's training takes: its fitted material, never the subject's.
  auto twin_start = Clock::now();
  std::vector<facedyn::Take> twin_takes;
  for (const std::string& expression : s.expressions) {
    for (size_t m = 0; m < s.twin_motions.size(); ++m) {
      sim::PerformanceOptions options;
      options.expression = expression;
      options.seconds = s.seconds;
      options.seed = seed * 10 + m;
      options.tissue = twin.prior;  // layers, density, muscles; the material is the fitted one
      options.material = twin.material;
      options.motion.kind = s.twin_motions[m].kind;
      options.motion.head_motion_hz = s.twin_motions[m].hz;
      options.motion.head_motion_deg = s.twin_motions[m].deg;
      options.motion.seed = seed * 100 + 10 + m;
      twin_takes.push_back(Check(sim::SimulatePerformance(face, options), "twin perform"));
      twin_takes.back().info.source = "twin perform";
    }
  }
  const double twin_s = Seconds(twin_start);

  // The two networks, the same optimiser budget.
  dynamics::RemovalTrainOptions options;
  options.targets = dynamics::RemovalTargets::kPlatformSynchronous;
  options.train.epochs = s.epochs;
  options.train.final_learning_rate_fraction = 0.05;
  options.train.seed = seed;
  std::vector<dynamics::TrainingTake> training;
  for (const facedyn::Take& take : captured) training.emplace_back(&take, &face);
  facedyn::learn::MlpTrainSummary captured_summary, augmented_summary;
  auto train_start = Clock::now();
  const dynamics::RemovalModel f_captured =
      Check(dynamics::TrainRemoval(training, options, &captured_summary), "train F (captured)");
  for (const facedyn::Take& take : twin_takes) {
    training.emplace_back(&take, &face, dynamics::RemovalTargets::kExact, s.twin_weight);
  }
  options.train.optimizer_steps = captured_summary.optimizer_steps;
  const dynamics::RemovalModel f_augmented =
      Check(dynamics::TrainRemoval(training, options, &augmented_summary), "train F (augmented)");
  const double train_s = Seconds(train_start);

  const int window = f_captured.config().features.window_frames();
  Json takes = Json::array();
  std::vector<double> motion_captured, motion_augmented, platform_captured, platform_augmented;
  for (const HeldOutTake& test : tests) {
    const facedyn::Take by_captured =
        Check(dynamics::RemoveDynamics(f_captured, test.reconstructed, face), "remove");
    const facedyn::Take by_augmented =
        Check(dynamics::RemoveDynamics(f_augmented, test.reconstructed, face), "remove");
    const double none = Check(
        eval::JiggleMeanErrorMm(test.reconstructed.positions, test.simulated, window), test.name);
    const double a =
        Check(eval::JiggleMeanErrorMm(by_captured.positions, test.simulated, window), test.name);
    const double b =
        Check(eval::JiggleMeanErrorMm(by_augmented.positions, test.simulated, window), test.name);
    const bool motion = test.protocol == "held-out head motion";
    (motion ? motion_captured : platform_captured).push_back(a);
    (motion ? motion_augmented : platform_augmented).push_back(b);
    takes.push_back({{"take", test.name},
                     {"protocol", test.protocol},
                     {"methods",
                      {{"no_removal", {{"jiggle_mean_mm", eval::Round4(none)}}},
                       {"F_captured", {{"jiggle_mean_mm", eval::Round4(a)}}},
                       {"F_augmented", {{"jiggle_mean_mm", eval::Round4(b)}}}}}});
  }
  auto mean = [](const std::vector<double>& v) {
    double sum = 0;
    for (double x : v) sum += x;
    return v.empty() ? 0.0 : sum / static_cast<double>(v.size());
  };
  const double motion_ratio = mean(motion_augmented) / mean(motion_captured);
  const double platform_ratio = mean(platform_augmented) / mean(platform_captured);
  motion_ratios->push_back(motion_ratio);
  platform_ratios->push_back(platform_ratio);
  Json twin_motions = Json::array();
  for (const Settings::HeadMotion& motion : s.twin_motions)
    twin_motions.push_back(
        {{"kind", MotionName(motion.kind)}, {"hz", motion.hz}, {"deg", motion.deg}});
  std::fprintf(stderr,
               "twin_bench: seed %llu augmentation: head motion %.3f -> %.3f mm (x%.2f), held-out "
               "platform %.3f -> %.3f mm (x%.2f)\n",
               static_cast<unsigned long long>(seed), mean(motion_captured), mean(motion_augmented),
               motion_ratio, mean(platform_captured), mean(platform_augmented), platform_ratio);
  return {{"takes", takes},
          {"twin_takes", twin_takes.size()},
          {"twin_motions", twin_motions},
          {"training_rows",
           {{"F_captured", captured_summary.training_rows},
            {"F_augmented", augmented_summary.training_rows}}},
          {"optimizer_steps",
           {{"F_captured", captured_summary.optimizer_steps},
            {"F_augmented", augmented_summary.optimizer_steps}}},
          {"head_motion_mean_mm",
           {{"F_captured", mean(motion_captured)}, {"F_augmented", mean(motion_augmented)}}},
          {"held_out_platform_mean_mm",
           {{"F_captured", mean(platform_captured)}, {"F_augmented", mean(platform_augmented)}}},
          {"augmented_over_captured",
           {{"head_motion", motion_ratio}, {"held_out_platform", platform_ratio}}},
          {"seconds", {{"held_out_takes", test_s}, {"twin_takes", twin_s}, {"train", train_s}}}};
}

// Issue 23's targeting study of one seed: each held frame (the mean over the held frames of a
// reconstructed take, in the skull frame, at the twin's marker vertices; gravity from the
// estimated skull pose) is fitted by the blendshapes and by the twin (physics/twin_targeting.h,
// the fitted material). Frames: the reconstructed platform takes the twin was fitted to
// (upright) and the subject filmed lying back by --lie-back-deg holding each of
// --targeting-expressions (the mean from 1 s after the transition ends), each in four modes:
// least squares or a Cauchy loss of scale --robust-mm, without or with the skull alignment
// (physics::TargetingOptions). Scored, truth only
// here: each fit's expression (its weights' upright blendshape skin) against the true
// expression's, RMS over every skin vertex.
Json RunTargeting(const facedyn::FaceRig& face, const eval::SimulatedCameraRig& cameras,
                  const Settings& s, uint64_t seed, const std::vector<facedyn::Take>& captured,
                  const std::vector<std::string>& captured_expressions,
                  const physics::FittedTwin& twin,
                  std::map<std::string, std::vector<double>>* figures) {
  const auto start = Clock::now();
  auto model =
      Check(physics::SoftTissueModel::Create(face, twin.prior, twin.material), "twin model");
  const std::vector<int> vertices = physics::TwinMarkerVertices(face);
  Json frames = Json::array();
  auto target = [&](const std::string& name, const std::string& kind, const facedyn::Take& take,
                    int first, const std::string& expression) {
    const int count = take.frame_count() - first;
    if (count < 1) Fail("targeting: take " + name + " has no held frames");
    const physics::HeldWindow window = Check(
        physics::MeanHeldWindow(take, vertices, first, take.frame_count()), "held window " + name);
    const Eigen::Matrix3Xd& mean = window.positions_in_skull;
    const Eigen::Vector3d& dg = window.gravity_change_in_skull;
    const Eigen::VectorXd truth = Check(sim::ExpressionWeights(face, expression), "expression");
    Json record = {{"take", name},
                   {"kind", kind},
                   {"held_frames", count},
                   {"gravity_change_mm_s2", dg.norm()}};
    for (const bool robust : {false, true})
      for (const bool align : {false, true}) {
        physics::TargetingOptions targeting;
        targeting.align_skull = align;
        targeting.robust_scale_mm = robust ? s.robust_mm : 0.0;
        const physics::ExpressionTargeting fit =
            Check(physics::TargetHeldExpression(*model, face, vertices, mean, dg, targeting),
                  "targeting " + name);
        const double plain_expression =
            eval::ExpressionSkinRmsMm(face, fit.blendshape.weights, truth);
        const double twin_expression = eval::ExpressionSkinRmsMm(face, fit.twin.weights, truth);
        const double ratio = fit.twin.rms_mm / fit.blendshape.rms_mm;
        const std::string mode =
            std::string(robust ? "robust_" : "") + (align ? "aligned" : "unaligned");
        const std::string where = kind == "upright" ? "upright" : "lying_back";
        (*figures)[mode + "_twin_over_blendshape_marker_rms_" + where].push_back(ratio);
        (*figures)[mode + "_twin_over_blendshape_common_inlier_rms_" + where].push_back(
            fit.twin.common_inlier_rms_mm / fit.blendshape.common_inlier_rms_mm);
        (*figures)[mode + "_twin_over_blendshape_expression_rms_" + where].push_back(
            twin_expression / plain_expression);
        (*figures)[mode + "_twin_expression_rms_mm_" + where].push_back(twin_expression);
        (*figures)[mode + "_blendshape_expression_rms_mm_" + where].push_back(plain_expression);
        auto fit_json = [](const physics::ExpressionTargetingFit& f, double expression_mm) {
          return Json{{"marker_rms_mm", f.rms_mm},
                      {"common_inlier_rms_mm", f.common_inlier_rms_mm},
                      {"common_inlier_markers", f.common_inlier_markers},
                      {"expression_rms_mm", expression_mm},
                      {"flesh_volume_change", f.flesh_volume_change},
                      {"skull_rotation_deg", f.skull_rotation_deg},
                      {"skull_translation_mm", f.skull_translation_mm},
                      {"outlier_markers", f.outlier_markers},
                      {"iterations", f.iterations},
                      {"cost_history", f.cost_history},
                      {"termination", f.termination},
                      {"seconds", f.seconds}};
        };
        record[mode] = {{"blendshape", fit_json(fit.blendshape, plain_expression)},
                        {"twin", fit_json(fit.twin, twin_expression)},
                        {"twin_over_blendshape_marker_rms", ratio}};
        std::fprintf(
            stderr,
            "twin_bench: seed %llu targeting %-22s %-9s |dg| %6.0f mm/s^2  markers %.3f -> "
            "%.3f mm  expression %.3f -> %.3f mm  flesh volume %+.4f%% / %+.4f%%  skull "
            "%.3f deg %.3f mm  (%.1f s)\n",
            static_cast<unsigned long long>(seed), name.c_str(), mode.c_str(), dg.norm(),
            fit.blendshape.rms_mm, fit.twin.rms_mm, plain_expression, twin_expression,
            100 * fit.blendshape.flesh_volume_change, 100 * fit.twin.flesh_volume_change,
            fit.twin.skull_rotation_deg, fit.twin.skull_translation_mm, fit.twin.seconds);
      }
    frames.push_back(record);
  };
  for (size_t i = 0; i < captured.size(); ++i) {
    const double hz = captured[i].info.platform_hz.value_or(0.0);
    target(fmt::format("{} at {:g} Hz", captured_expressions[i], hz), "upright", captured[i],
           facedyn::FirstHeldFrame(captured[i]), captured_expressions[i]);
  }
  uint64_t reconstruction_seed = seed * 1000 + 700;
  for (const std::string& expression : s.targeting_expressions) {
    sim::PerformanceOptions options =
        SubjectPerformance(s, expression, s.lie_back_seconds, seed + 60);
    options.motion.kind = sim::MotionKind::kLieBack;
    options.motion.lie_back_deg = s.lie_back_deg;
    options.motion.seed = seed * 100 + 88;
    const facedyn::Take simulated = Check(sim::SimulatePerformance(face, options), "lie back");
    facedyn::Take reconstructed =
        Check(eval::ReconstructSimulatedTake(face, cameras, simulated, reconstruction_seed++),
              "reconstruct lying back " + expression)
            .take;
    const double settled_s = options.motion.lie_back_s + 1.0;
    int first = 0;
    while (first < reconstructed.frame_count() && reconstructed.time_s[first] < settled_s) ++first;
    target(expression + " lying back", "lying back", reconstructed, first, expression);
  }
  return {{"lie_back_deg", s.lie_back_deg},
          {"marker_vertices", vertices.size()},
          {"frames", frames},
          {"seconds", Seconds(start)}};
}

}  // namespace

int main(int argc, char** argv) {
  facedyn::SetDefaultProgressMode(facedyn::ProgressMode::kLines);
  Settings s;
  auto list = [](const std::string& text, const std::string& flag, auto parse) {
    std::stringstream stream(text);
    std::string item;
    using Item = decltype(parse(std::string()));
    std::vector<Item> items;
    while (std::getline(stream, item, ',')) items.push_back(parse(item));
    if (items.empty()) Fail(flag + " needs at least one value");
    return items;
  };
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) Fail(arg + " needs a value");
      return argv[++i];
    };
    if (arg == "--seeds") {
      s.seeds = list(next(), arg, [&](const std::string& t) {
        return static_cast<uint64_t>(facedyn::bench::FlagInteger("twin_bench", arg, t.c_str()));
      });
    } else if (arg == "--true-hz") {
      s.true_hz = facedyn::bench::FlagNumber("twin_bench", arg, next().c_str());
    } else if (arg == "--true-damping") {
      s.true_damping = facedyn::bench::FlagNumber("twin_bench", arg, next().c_str());
    } else if (arg == "--true-body-hz") {
      s.true_body_hz = facedyn::bench::FlagNumber("twin_bench", arg, next().c_str());
    } else if (arg == "--true-body-damping") {
      s.true_body_damping = facedyn::bench::FlagNumber("twin_bench", arg, next().c_str());
    } else if (arg == "--true-pitch-per-g") {
      s.true_pitch_per_g = facedyn::bench::FlagNumber("twin_bench", arg, next().c_str());
    } else if (arg == "--frequencies") {
      s.frequencies = list(next(), arg, [&](const std::string& t) {
        return facedyn::bench::FlagNumber("twin_bench", arg, t.c_str());
      });
    } else if (arg == "--expressions") {
      s.expressions = list(next(), arg, [](const std::string& t) { return t; });
    } else if (arg == "--seconds") {
      s.seconds = facedyn::bench::FlagNumber("twin_bench", arg, next().c_str());
    } else if (arg == "--sim-step-s") {
      s.sim_step_s = facedyn::bench::FlagNumber("twin_bench", arg, next().c_str());
    } else if (arg == "--no-reconstruct") {
      s.reconstruct = false;
    } else if (arg == "--no-clean") {
      s.clean = false;
    } else if (arg == "--no-augmentation") {
      s.augmentation = false;
    } else if (arg == "--no-targeting") {
      s.targeting = false;
    } else if (arg == "--robust-mm") {
      s.robust_mm = facedyn::bench::FlagNumber("twin_bench", arg, next().c_str());
      if (!(s.robust_mm > 0)) Fail("--robust-mm must be > 0");
    } else if (arg == "--lie-back-deg") {
      s.lie_back_deg = facedyn::bench::FlagNumber("twin_bench", arg, next().c_str());
    } else if (arg == "--targeting-expressions") {
      s.targeting_expressions = list(next(), arg, [](const std::string& t) { return t; });
    } else if (arg == "--held-out-hz") {
      s.held_out_hz = facedyn::bench::FlagNumber("twin_bench", arg, next().c_str());
    } else if (arg == "--twin-weight") {
      s.twin_weight = facedyn::bench::FlagNumber("twin_bench", arg, next().c_str());
      if (!(s.twin_weight > 0)) Fail("--twin-weight must be > 0");
    } else if (arg == "--epochs") {
      s.epochs = static_cast<int>(facedyn::bench::FlagInteger("twin_bench", arg, next().c_str()));
      if (s.epochs < 1) Fail("--epochs must be >= 1");
    } else if (arg == "--quick") {
      s.seeds = {1};
      s.frequencies = {6, 8, 10};
      s.expressions = {"neutral"};
      s.seconds = 2.0;
      s.test_seconds = 2.0;
      s.epochs = 10;
    } else {
      Fail("unknown argument '" + arg + "' (see the header of bench/twin_bench.cc)");
    }
  }

  const facedyn::FaceRig face =
      Check(sim::MakeProceduralFace(sim::ProceduralFaceOptions()), "procedural face");
  Json runs = Json::array();
  std::vector<double> clean_hz, clean_damping, rec_hz, rec_damping, fit_seconds;
  std::vector<double> clean_body_hz, clean_body_damping, rec_body_hz, rec_body_damping, rec_pitch;
  std::vector<double> motion_ratios, platform_ratios;  // augmented / captured F, per seed
  // Targeting, per frame and mode: twin / blendshape marker and expression RMS, and each fit's
  // expression RMS (upright, lying back).
  std::map<std::string, std::vector<double>> targeting_figures;
  for (uint64_t seed : s.seeds) {
    const auto seed_start = Clock::now();
    eval::SimulatedCameraRig cameras;
    if (s.reconstruct)
      cameras = Check(eval::CalibrateSimulatedCameraRig(30, 2020 + seed), "calibration");
    std::vector<facedyn::Take> clean, reconstructed;
    double simulate_s = 0, reconstruct_s = 0;
    for (const std::string& expression : s.expressions) {
      for (double hz : s.frequencies) {
        sim::PerformanceOptions options = SubjectPerformance(s, expression, s.seconds, seed);
        options.motion = SubjectOnPlatform(s, hz, seed * 100 + static_cast<uint64_t>(hz));
        auto t0 = Clock::now();
        facedyn::Take take = Check(sim::SimulatePerformance(face, options), "simulate");
        simulate_s += Seconds(t0);
        if (s.reconstruct) {
          t0 = Clock::now();
          auto reconstruction =
              Check(eval::ReconstructSimulatedTake(face, cameras, take, seed * 1000 + clean.size()),
                    "reconstruct " + expression);
          reconstruct_s += Seconds(t0);
          reconstructed.push_back(std::move(reconstruction.take));
        }
        take.channels.clear();  // the truth channels: a method never gets them
        clean.push_back(std::move(take));
      }
    }
    auto named = [&](const std::vector<facedyn::Take>& takes) {
      std::vector<std::pair<std::string, const facedyn::Take*>> pairs;
      size_t i = 0;
      for (const std::string& expression : s.expressions) {
        for (double hz : s.frequencies)
          pairs.push_back({expression + "@" + std::to_string(hz) + "Hz", &takes[i++]});
      }
      return pairs;
    };
    Json run = {{"seed", seed}};
    physics::TwinFitOptions fit_options;
    fit_options.platform_amplitude_mm = s.platform_amplitude_mm;  // the rig's, not the body's
    if (s.clean) {
      const physics::FittedTwin clean_twin =
          Check(physics::FitTwin(face, named(clean), fit_options), "clean fit");
      run["clean"] = FitJson(clean_twin, s);
      clean_hz.push_back(run["clean"]["score"]["hz_error_percent"].get<double>());
      clean_damping.push_back(run["clean"]["score"]["damping_error_percent"].get<double>());
      if (clean_twin.body) {
        clean_body_hz.push_back(run["clean"]["score"]["body_hz_error_percent"].get<double>());
        clean_body_damping.push_back(
            run["clean"]["score"]["body_damping_error_percent"].get<double>());
      }
    }
    if (s.reconstruct) {
      const physics::FittedTwin rec_twin =
          Check(physics::FitTwin(face, named(reconstructed), fit_options), "reconstructed fit");
      run["reconstructed"] = FitJson(rec_twin, s);
      rec_hz.push_back(run["reconstructed"]["score"]["hz_error_percent"].get<double>());
      rec_damping.push_back(run["reconstructed"]["score"]["damping_error_percent"].get<double>());
      if (rec_twin.body) {
        const Json& score = run["reconstructed"]["score"];
        rec_body_hz.push_back(score["body_hz_error_percent"].get<double>());
        rec_body_damping.push_back(score["body_damping_error_percent"].get<double>());
        rec_pitch.push_back(score["pitch_error_percent"].get<double>());
      }
      fit_seconds.push_back(rec_twin.seconds);
      if (s.targeting) {
        std::vector<std::string> captured_expressions;
        for (const std::string& expression : s.expressions)
          captured_expressions.insert(captured_expressions.end(), s.frequencies.size(), expression);
        run["targeting"] = RunTargeting(face, cameras, s, seed, reconstructed, captured_expressions,
                                        rec_twin, &targeting_figures);
      }
      if (s.augmentation) {
        run["augmentation"] = RunAugmentation(face, cameras, s, seed, reconstructed, rec_twin,
                                              &motion_ratios, &platform_ratios);
      }
    }
    run["seconds"] = {
        {"simulate", simulate_s}, {"reconstruct", reconstruct_s}, {"total", Seconds(seed_start)}};
    runs.push_back(run);
    std::fprintf(stderr, "twin_bench: seed %llu done in %.0f s\n",
                 static_cast<unsigned long long>(seed), Seconds(seed_start));
  }
  auto spread = [](const std::vector<double>& values) {
    const eval::Spread sp = eval::SpreadOf(values);
    return Json{
        {"mean", sp.mean}, {"sd", sp.sd}, {"min", sp.min}, {"max", sp.max}, {"count", sp.count}};
  };
  Json summary = Json::object();
  if (s.clean) {
    summary["clean_hz_error_percent"] = spread(clean_hz);
    summary["clean_damping_error_percent"] = spread(clean_damping);
    if (!clean_body_hz.empty()) {
      summary["clean_body_hz_error_percent"] = spread(clean_body_hz);
      summary["clean_body_damping_error_percent"] = spread(clean_body_damping);
    }
  }
  if (s.reconstruct) {
    summary["reconstructed_hz_error_percent"] = spread(rec_hz);
    summary["reconstructed_damping_error_percent"] = spread(rec_damping);
    summary["reconstructed_fit_seconds"] = spread(fit_seconds);
    if (!rec_body_hz.empty()) {
      summary["reconstructed_body_hz_error_percent"] = spread(rec_body_hz);
      summary["reconstructed_body_damping_error_percent"] = spread(rec_body_damping);
      summary["reconstructed_pitch_error_percent"] = spread(rec_pitch);
    }
    if (s.targeting) {
      for (const auto& [name, values] : targeting_figures)
        summary["targeting_" + name] = spread(values);
    }
    if (s.augmentation) {
      summary["augmented_over_captured_head_motion"] = spread(motion_ratios);
      summary["augmented_over_captured_held_out_platform"] = spread(platform_ratios);
    }
  }
  Json frequencies = Json::array();
  for (double hz : s.frequencies) frequencies.push_back(hz);
  const Json out = {{"bench", "twin"},
                    {"subject",
                     {{"true_hz", s.true_hz},
                      {"true_damping_ratio", s.true_damping},
                      {"true_body_hz", s.true_body_hz},
                      {"true_body_damping_ratio", s.true_body_damping},
                      {"true_pitch_rad_per_g", s.true_pitch_per_g},
                      {"platform_amplitude_mm", s.platform_amplitude_mm}}},
                    {"frequencies_hz", frequencies},
                    {"expressions", s.expressions},
                    {"seconds_per_take", s.seconds},
                    {"sim_step_s", s.sim_step_s},
                    {"runs", runs},
                    {"summary", summary}};
  std::printf("%s\n", out.dump(2).c_str());
  return 0;
}
