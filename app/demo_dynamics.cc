#include "app/demo_dynamics.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <future>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>

#include "report/face_render.h"
#include "report/take_viewer.h"
#include "core/file_util.h"
#include "core/parallel_for.h"
#include "dynamics/baselines.h"
#include "dynamics/features.h"
#include "dynamics/joint_training.h"
#include "dynamics/modal_synthesis.h"
#include "dynamics/quasistatic.h"
#include "learn/mlp.h"
#include "dynamics/synthesis_model.h"
#include "eval/dynamics_study.h"
#include "eval/metrics.h"
#include "eval/removal_comparison.h"
#include "eval/synthesis_scoring.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"
#include "sim/skull_motion.h"

namespace facedyn::app {
namespace {

using Clock = std::chrono::steady_clock;
using eval::Round4;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}


std::string TakeName(const std::string& expression, double hz) {
  return fmt::format("{}@{:g}Hz", expression, hz);
}

// One subject's takes: simulated (with the exact channels) and reconstructed.
struct SubjectTakes {
  std::vector<std::string> names;
  std::vector<double> hz;
  std::vector<Take> simulated;
  std::vector<Take> reconstructed;
  Json reconstruction = Json::array();  // per take: errors of the reconstruction
};

sim::MotionOptions PlatformMotion(double hz, uint64_t seed) {
  sim::MotionOptions motion;
  motion.kind = sim::MotionKind::kPlatform;
  motion.platform_hz = hz;
  motion.seed = seed;
  return motion;
}

StatusOr<Take> Simulate(const FaceRig& face, const std::string& expression,
                        const sim::MotionOptions& motion, double seconds,
                        const physics::TissueOptions& tissue, uint64_t seed) {
  sim::PerformanceOptions perform;
  perform.expression = expression;
  perform.motion = motion;
  perform.seconds = seconds;
  perform.seed = seed;
  perform.tissue = tissue;
  return sim::SimulatePerformance(face, perform);
}

// RMS distance (mm) of the reconstructed skin samples from the simulated dynamic ones, after
// the motion's fade-in (first 0.5 s).
double SampleRmsMm(const FaceRig& face, const Take& reconstructed, const Take& simulated) {
  const int skip = std::min(simulated.frame_count() - 1,
                            static_cast<int>(std::lround(0.5 * simulated.info.fps)));
  double sum_sq = 0.0;
  long count = 0;
  for (int f = skip; f < simulated.frame_count(); ++f) {
    const Eigen::Matrix3Xd fitted = face.SamplePositions(reconstructed.FramePositions(f));
    const Eigen::Matrix3Xd truth = face.SamplePositions(simulated.FramePositions(f));
    sum_sq += (fitted - truth).colwise().squaredNorm().sum();
    count += fitted.cols();
  }
  return count > 0 ? std::sqrt(sum_sq / count) : 0.0;
}

// One take to simulate: an expression held under a head motion.
struct TakeSpec {
  std::string name;
  std::string expression;
  sim::MotionOptions motion;
  double platform_hz = 0.0;  // 0 for motions other than the platform
  double seconds = 0.0;      // 0: the length SimulateAndReconstruct is given
};

// A walk in place (sim/skull_motion.h kWalk with no forward speed): walking at constant speed
// is the same to the tissue (an inertial frame), but the skull descriptor B(t) holds
// velocities, and 1.3 m/s of forward speed would put every walk far outside the platform takes.
sim::MotionOptions WalkInPlace(double step_hz, uint64_t seed) {
  sim::MotionOptions motion;
  motion.kind = sim::MotionKind::kWalk;
  motion.walk_step_hz = step_hz;
  motion.walk_speed_mm_per_s = 0;
  motion.seed = seed;
  return motion;
}

// Every expression at every frequency on the platform, then a neutral walk in place at each
// training step rate.
std::vector<TakeSpec> TrainingSpecs(const std::vector<double>& hz_list,
                                    const std::vector<std::string>& expressions,
                                    const std::vector<double>& walk_step_hz, uint64_t* seed) {
  std::vector<TakeSpec> specs;
  for (double hz : hz_list) {
    for (const std::string& expression : expressions) {
      specs.push_back({TakeName(expression, hz), expression, PlatformMotion(hz, ++*seed), hz});
    }
  }
  for (double step_hz : walk_step_hz) {
    specs.push_back({fmt::format("neutral walk {:g} steps/s", step_hz), "neutral",
                     WalkInPlace(step_hz, ++*seed), 0.0});
  }
  return specs;
}

// Simulates every take of `specs` on `face` and reconstructs it through the demo's cameras.
// *done counts takes across subjects for the progress lines. Simulation and reconstruction of
// one take run on one core, so takes run two at a time (one per core of the 2-core machines the
// demo targets): each take has its own seeds, so the results do not depend on the order.
Status SimulateAndReconstruct(const FaceRig& face, const eval::SimulatedCameraRig& cameras,
                              const std::vector<TakeSpec>& specs, double seconds,
                              const physics::TissueOptions& tissue, const std::string& subject,
                              int* done, int total, SubjectTakes* takes) {
  struct Result {
    Status status = Status::Ok();
    Take simulated;
    Take reconstructed;
    Json reconstruction;
  };
  std::vector<Result> results(specs.size());
  auto seconds_of = [&](const TakeSpec& spec) { return spec.seconds > 0 ? spec.seconds : seconds; };
  std::mutex mutex;  // guards next, failed, *done and stdout
  size_t next = 0;
  bool failed = false;
  const unsigned workers = static_cast<unsigned>(
      std::min<size_t>(specs.size(), std::clamp(std::thread::hardware_concurrency(), 1u, 2u)));
  auto work = [&]() {
    for (;;) {
      size_t i = 0;
      {
        std::lock_guard<std::mutex> lock(mutex);
        if (failed || next == specs.size()) return;
        i = next++;
        ++*done;
        std::printf(
            "  [%d/%d] subject %s, %s: simulating %.1f s, filming it with 8 cameras (rendered, "
            "dots detected), reconstructing\n",
            *done, total, subject.c_str(), specs[i].name.c_str(), seconds_of(specs[i]));
        std::fflush(stdout);
      }
      const TakeSpec& spec = specs[i];
      Result& result = results[i];
      StatusOr<Take> simulated =
          Simulate(face, spec.expression, spec.motion, seconds_of(spec), tissue, spec.motion.seed);
      // Two takes run at once, one per core: a filmed take renders and detects on its own. The
      // last two film on every core: whichever ends later would otherwise run alone on one
      // (subject B's odd count of takes left 25 s of the default demo on one core). The images
      // do not depend on the thread count (each camera's noise is seeded by camera and frame).
      eval::FilmOptions film;
      film.threads = i + workers >= specs.size() ? 0 : 1;
      StatusOr<reconstruct::Reconstruction> reconstruction =
          !simulated.ok()
              ? StatusOr<reconstruct::Reconstruction>(simulated.status())
              : eval::FilmSimulatedTake(face, cameras, *simulated, 7000 + spec.motion.seed, film);
      if (!reconstruction.ok()) {
        result.status =
            reconstruction.status().WithContext(fmt::format("subject {}, {}", subject, spec.name));
        std::lock_guard<std::mutex> lock(mutex);
        failed = true;
        return;
      }
      const double frames = simulated->frame_count();
      result.reconstruction = {
          {"subject", subject},
          {"take", spec.name},
          {"frames", simulated->frame_count()},
          {"reconstructed_from", "filmed (rendered, dots detected)"},
          {"sample_rms_mm", Round4(SampleRmsMm(face, reconstruction->take, *simulated))},
          {"dense_fit_fps", Round4(frames / std::max(1e-9, reconstruction->timings.dense_s))}};
      result.simulated = std::move(*simulated);
      result.reconstructed = std::move(reconstruction->take);
    }
  };
  std::vector<std::thread> threads;
  for (unsigned w = 1; w < workers; ++w) threads.emplace_back(work);
  work();
  for (std::thread& thread : threads) thread.join();
  for (size_t i = 0; i < specs.size(); ++i) {
    if (!results[i].status.ok()) return results[i].status;
  }
  for (size_t i = 0; i < specs.size(); ++i) {
    takes->reconstruction.push_back(std::move(results[i].reconstruction));
    takes->names.push_back(specs[i].name);
    takes->hz.push_back(specs[i].platform_hz);
    takes->simulated.push_back(std::move(results[i].simulated));
    takes->reconstructed.push_back(std::move(results[i].reconstructed));
  }
  return Status::Ok();
}

Json TrainingJson(const learn::MlpTrainSummary& summary, int epochs) {
  return {{"epochs", epochs},
          {"training_rows", summary.training_rows},
          {"validation_rows", summary.validation_rows},
          {"final_train_loss", summary.train_loss.empty() ? 0.0 : summary.train_loss.back()},
          {"final_validation_loss",
           summary.validation_loss.empty() ? 0.0 : summary.validation_loss.back()},
          {"optimizer_steps", summary.optimizer_steps},
          {"train_s", Round4(summary.train_s)},
          {"rows_per_s", std::round(summary.rows_per_s)}};
}

// One line for a network trained without a progress bar (beside another that has one).
void LogTrained(const std::string& label, const learn::MlpTrainSummary& summary) {
  spdlog::info("trained {}: {} epochs, {} steps in {:.1f} s, loss {:.4g}{}", label, summary.epochs,
               summary.optimizer_steps, summary.train_s,
               summary.train_loss.empty() ? 0.0 : summary.train_loss.back(),
               summary.validation_loss.empty()
                   ? std::string()
                   : fmt::format(" val {:.4g}", summary.validation_loss.back()));
}

// Independent jobs (network trainings, each on one core: LibTorch does not spread these small
// networks' batches over threads) run two at a time on the machine's cores, in list order as
// workers free up. The first failure is returned (the lowest failing job's).
Status RunSideBySide(const std::vector<std::function<Status()>>& jobs) {
  return ParallelFor(static_cast<int>(jobs.size()), ParallelThreadCount(0, 2),
                     [&](int index) { return jobs[index](); });
}

// F's options in the demo (TrainF's, and the joint training's rows of F).
dynamics::RemovalTrainOptions FOptions(dynamics::RemovalTargets targets, int epochs, int batch,
                                       uint64_t seed, const std::string& label,
                                       bool show_progress, long optimizer_steps = 0) {
  dynamics::RemovalTrainOptions options;
  options.targets = targets;
  options.train.epochs = epochs;
  options.train.optimizer_steps = optimizer_steps;
  options.train.batch_size = batch;
  options.train.seed = seed;
  options.train.final_learning_rate_fraction = 0.05;
  options.train.progress_label = label;
  options.train.show_progress = show_progress;
  return options;
}

// H's options in the demo (TrainH's, and the joint training's rows of H).
dynamics::SynthesisTrainOptions HOptions(int epochs, uint64_t seed, const std::string& label,
                                         bool show_progress) {
  dynamics::SynthesisTrainOptions options;
  options.train.epochs = epochs;
  options.train.seed = seed;
  options.train.final_learning_rate_fraction = 0.05;
  options.train.progress_label = label;
  options.train.show_progress = show_progress;
  return options;
}

// What F's targets are on the demo's reconstructed takes (metrics.json setup.targets_note).
std::string TargetsNote(dynamics::RemovalTargets targets) {
  using dynamics::RemovalTargets;
  const char* prefix = "reconstructed takes have no exact channel; ";
  switch (targets) {
    case RemovalTargets::kPlatformSynchronousWhereKnown:
      return std::string(prefix) +
             "platform takes: the fit at the take's recorded platform frequency (quasistatic.h); "
             "walks: the moving average (Eq. 5-6)";
    case RemovalTargets::kPlatformSynchronousElseHeldMean:
      return std::string(prefix) +
             "platform takes: the fit at the take's recorded platform frequency (quasistatic.h); "
             "walks: the take's mean shape in the skull frame over its held frames";
    case RemovalTargets::kHeldMean:
      return std::string(prefix) +
             "every take: its mean shape in the skull frame over its held frames";
    case RemovalTargets::kMovingAverage:
      return std::string(prefix) + "every take: the moving average (Eq. 5-6)";
    default:  // exact (refused by Check) and platform-synchronous alone (refused by the CLI)
      return std::string(prefix) + dynamics::RemovalTargetsName(targets);
  }
}

// F on reconstructed takes, with targets a capture has (moving average, platform-synchronous).
StatusOr<dynamics::RemovalModel> TrainF(const std::vector<Take>& takes, const FaceRig& face,
                                        dynamics::RemovalTargets targets, int epochs, int batch,
                                        uint64_t seed, const std::string& label,
                                        learn::MlpTrainSummary* summary, bool show_progress,
                                        long optimizer_steps = 0) {
  std::vector<dynamics::TrainingTake> training;
  for (const Take& take : takes) training.push_back({&take, &face});
  dynamics::RemovalTrainOptions options =
      FOptions(targets, epochs, batch, seed, label, show_progress, optimizer_steps);
  spdlog::info("training {} on {} reconstructed takes ({} epochs, {} targets)", label, takes.size(),
               epochs, dynamics::RemovalTargetsName(targets));
  StatusOr<dynamics::RemovalModel> model = dynamics::TrainRemoval(training, options, summary);
  if (model.ok() && !show_progress && summary != nullptr) LogTrained(label, *summary);
  return model;
}

// H on takes decomposed by F (positions = F's quasistatic, channel dynamic_offset = F's dx).
StatusOr<dynamics::SynthesisModel> TrainH(const std::vector<Take>& decomposed, const FaceRig& face,
                                          int epochs, uint64_t seed, const std::string& label,
                                          learn::MlpTrainSummary* summary,
                                          bool show_progress) {
  std::vector<dynamics::TrainingTake> training;
  for (const Take& take : decomposed) training.push_back({&take, &face});
  const dynamics::SynthesisTrainOptions options = HOptions(epochs, seed, label, show_progress);
  spdlog::info("training {} on {} takes decomposed by F ({} epochs)", label, decomposed.size(),
               epochs);
  StatusOr<dynamics::SynthesisModel> model = dynamics::TrainSynthesis(training, options, summary);
  if (model.ok() && !show_progress && summary != nullptr) LogTrained(label, *summary);
  return model;
}

// The modal synthesis (dynamics/modal_synthesis.h) on a subject's reconstructed held takes,
// each decomposed by its held mean (quasistatic.h): no network and no ground truth.
StatusOr<dynamics::ModalSynthesisModel> TrainModal(const std::vector<Take>& reconstructed,
                                                   const FaceRig& face, uint64_t seed,
                                                   dynamics::RidgeRule ridge_rule,
                                                   const std::string& label, Json* fit_json) {
  dynamics::QuasistaticOptions held;
  held.method = dynamics::QuasistaticMethod::kHeldMean;
  std::vector<Take> decomposed;
  for (const Take& take : reconstructed) {
    FACEDYN_ASSIGN_OR_RETURN(Take one, dynamics::ExtractQuasistatic(take, held));
    decomposed.push_back(std::move(one));
  }
  std::vector<dynamics::TrainingTake> training;
  for (const Take& take : decomposed) training.push_back({&take, &face});
  dynamics::ModalSynthesisOptions options;
  options.seed = seed;
  options.ridge_rule = ridge_rule;
  dynamics::ModalSynthesisFit fit;
  FACEDYN_ASSIGN_OR_RETURN(dynamics::ModalSynthesisModel model,
                           dynamics::ModalSynthesisModel::Train(training, options, &fit));
  spdlog::info(
      "{}: modal synthesis on {} held takes, ridge {:g} chosen ({}) on {} validation frames "
      "(expected residual {:.3f} of a new motion's offsets)",
      label, reconstructed.size(), fit.chosen_ridge, dynamics::RidgeRuleName(ridge_rule),
      fit.validation_frames,
      model.validation_residual());
  *fit_json = {{"decomposition", "held mean (quasistatic.h), reconstructed takes"},
               {"takes", reconstructed.size()},
               {"resonator_hz", options.resonator_hz},
               {"resonator_damping", options.resonator_damping},
               {"validation", fit.validation},
               {"ridge_tried", options.ridge},
               {"validation_rms_mm", fit.validation_rms_mm},
               {"validation_relative", fit.validation_relative},
               {"validation_standard_error", fit.validation_standard_error},
               {"ridge_rule", dynamics::RidgeRuleName(ridge_rule)},
               {"chosen_ridge", fit.chosen_ridge},
               {"validation_residual", model.validation_residual()},
               {"training_frames", fit.training_frames},
               {"validation_frames", fit.validation_frames}};
  return model;
}

}  // namespace

DemoDynamicsOptions DemoDynamicsOptions::ForDemo(bool quick) {
  DemoDynamicsOptions options;
  if (quick) {
    options.train_hz = {8, 10};
    options.expressions = {"neutral"};
    options.second_subject_hz = {9};
    options.second_subject_expressions = {"neutral"};
    options.training_walk_step_hz = {1.5};
    options.seconds = 1.25;
    options.walk_seconds = 1.5;
    options.removal_epochs = 8;
    options.second_subject_removal_epochs = 8;
    options.synthesis_epochs = 30;
    options.subset_epochs = 6;
  }
  return options;
}

Status DemoDynamicsOptions::Check() const {
  auto hz_ok = [](double hz) { return hz >= 0.5 && hz <= 30; };
  if (train_hz.size() < 2) return InvalidArgumentError("train_hz: at least two frequencies");
  for (double hz : train_hz) {
    if (!hz_ok(hz)) return InvalidArgumentError(fmt::format("train_hz: {} not in 0.5..30", hz));
  }
  if (second_subject_hz.empty()) {
    return InvalidArgumentError("second_subject_hz: at least one frequency");
  }
  for (double hz : second_subject_hz) {
    if (!hz_ok(hz)) {
      return InvalidArgumentError(fmt::format("second_subject_hz: {} not in 0.5..30", hz));
    }
  }
  if (expressions.empty()) return InvalidArgumentError("expressions: at least one");
  for (double step_hz : training_walk_step_hz) {
    if (!(step_hz >= 0.5 && step_hz <= 4)) {
      return InvalidArgumentError(fmt::format("training_walk_step_hz: {} not in 0.5..4", step_hz));
    }
    if (std::abs(step_hz - test_walk_step_hz) < 1e-9) {
      return InvalidArgumentError(fmt::format(
          "training_walk_step_hz: {} is the test walk's step rate (it must be new)", step_hz));
    }
  }
  if (!(test_walk_step_hz >= 0.5 && test_walk_step_hz <= 4)) {
    return InvalidArgumentError("test_walk_step_hz must be in 0.5..4");
  }
  if (second_subject_expressions.empty() || second_subject_expressions.front() != "neutral") {
    return InvalidArgumentError("second_subject_expressions: must start with \"neutral\"");
  }
  if (!(seconds >= 1.0)) return InvalidArgumentError("seconds must be >= 1");
  if (!(walk_seconds >= 1.0)) return InvalidArgumentError("walk_seconds must be >= 1");
  if (removal_targets == dynamics::RemovalTargets::kExact) {
    return InvalidArgumentError(
        "removal_targets: exact targets need a simulated take's quasistatic; the demo trains on "
        "reconstructed takes");
  }
  if (removal_epochs < 1) return InvalidArgumentError("removal_epochs must be >= 1");
  if (second_subject_removal_epochs < 1) {
    return InvalidArgumentError("second_subject_removal_epochs must be >= 1");
  }
  if (removal_batch < 1) return InvalidArgumentError("removal_batch must be >= 1");
  if (synthesis_epochs < 1) return InvalidArgumentError("synthesis_epochs must be >= 1");
  if (subset_epochs < 0) return InvalidArgumentError("subset_epochs must be >= 0");
  for (double s : {second_subject_scale_x, second_subject_scale_y, second_subject_scale_z}) {
    if (!(s >= 0.7 && s <= 1.3)) {
      return InvalidArgumentError(fmt::format("second_subject_scale: {} not in 0.7..1.3", s));
    }
  }
  if (!(second_subject_fundamental_hz >= 3 && second_subject_fundamental_hz <= 30)) {
    return InvalidArgumentError("second_subject_fundamental_hz must be in 3..30");
  }
  if (!(second_subject_damping_ratio > 0 && second_subject_damping_ratio <= 1)) {
    return InvalidArgumentError("second_subject_damping_ratio must be in (0, 1]");
  }
  for (double hz : training_performance_hz) {
    if (std::none_of(train_hz.begin(), train_hz.end(),
                     [&](double train) { return std::abs(train - hz) < 1e-9; })) {
      return InvalidArgumentError(fmt::format(
          "training_performance_hz: {} Hz is not a training frequency (train_hz); a performance "
          "at another frequency would show the cycle a platform motion F never trained on",
          hz));
    }
  }
  if (!training_performance_hz.empty() && training_performance_expression.empty()) {
    return InvalidArgumentError("training_performance_expression: empty");
  }
  if (joint_steps < 1) return InvalidArgumentError("joint_steps must be >= 1");
  if (!(std::isfinite(joint_cycle_weight) && joint_cycle_weight >= 0)) {
    return InvalidArgumentError("joint_cycle_weight must be finite and >= 0");
  }
  return Status::Ok();
}

Status RunDemoDynamicsStage(const FaceRig& face, const eval::SimulatedCameraRig& cameras,
                            const Take& test_simulated, const Take& test_reconstructed,
                            const DemoDynamicsOptions& options, const std::string& out_dir,
                            const dynamics::RemovalModel* reference_removal, Json* metrics,
                            DemoDynamicsArtifacts* artifacts) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  const double test_hz = test_simulated.info.platform_hz.value_or(0.0);
  for (double hz : options.train_hz) {
    if (std::abs(hz - test_hz) < 1e-9) {
      return InvalidArgumentError(
          fmt::format("train_hz: {} Hz is the held-out take's frequency", hz));
    }
  }
  for (const char* channel : {"quasistatic", "dynamic_offset"}) {
    if (test_simulated.channels.count(channel) == 0) {
      return FailedPreconditionError(
          fmt::format("the held-out simulated take has no \"{}\" channel", channel));
    }
  }
  if (test_reconstructed.frame_count() != test_simulated.frame_count() ||
      test_reconstructed.vertex_count() != test_simulated.vertex_count()) {
    return FailedPreconditionError(fmt::format(
        "the held-out reconstructed take ({} frames, {} vertices) does not match its simulation "
        "({} frames, {} vertices)",
        test_reconstructed.frame_count(), test_reconstructed.vertex_count(),
        test_simulated.frame_count(), test_simulated.vertex_count()));
  }
  const auto stage_start = Clock::now();
  const std::string models_dir = JoinPath(out_dir, "models");
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(models_dir));
  const double fps = test_simulated.info.fps;
  const int skip = dynamics::WindowFrames(0.08, fps);
  Json result;
  Json training = Json::object();

  // Subject B: another shape and another tissue.
  FACEDYN_ASSIGN_OR_RETURN(
      const FaceRig face_b,
      sim::ScaledFaceRig(face,
                    Eigen::Vector3d(options.second_subject_scale_x, options.second_subject_scale_y,
                                    options.second_subject_scale_z),
                    face.name + "-b"));
  physics::TissueOptions tissue_a;
  physics::TissueOptions tissue_b;
  tissue_b.fundamental_hz = options.second_subject_fundamental_hz;
  tissue_b.damping_ratio = options.second_subject_damping_ratio;

  // --- 1. data: simulate, film, reconstruct ---
  const auto data_start = Clock::now();
  uint64_t seed = options.seed + 100;
  const std::vector<TakeSpec> specs_a =
      TrainingSpecs(options.train_hz, options.expressions, options.training_walk_step_hz, &seed);
  const std::vector<TakeSpec> specs_b =
      TrainingSpecs(options.second_subject_hz, options.second_subject_expressions,
                    options.training_walk_step_hz, &seed);
  // A's training performances for the joint training: seeds after B's, so the other takes are
  // those of a run without them.
  std::vector<TakeSpec> specs_performances;
  for (double hz : options.training_performance_hz) {
    specs_performances.push_back({TakeName(options.training_performance_expression, hz),
                                  options.training_performance_expression,
                                  PlatformMotion(hz, ++seed), hz});
  }
  const int total =
      static_cast<int>(specs_a.size() + specs_b.size() + specs_performances.size());
  std::printf("\nDynamics on reconstructed takes: %d takes to simulate and reconstruct\n", total);
  int done = 0;
  SubjectTakes a, b, a_performances;
  FACEDYN_RETURN_IF_ERROR(SimulateAndReconstruct(face, cameras, specs_a, options.seconds, tissue_a,
                                                 "A", &done, total, &a));
  FACEDYN_RETURN_IF_ERROR(SimulateAndReconstruct(face_b, cameras, specs_b, options.seconds,
                                                 tissue_b, "B", &done, total, &b));
  if (!specs_performances.empty()) {
    FACEDYN_RETURN_IF_ERROR(SimulateAndReconstruct(face, cameras, specs_performances,
                                                   options.seconds, tissue_a, "A", &done, total,
                                                   &a_performances));
  }
  Json reconstruction = a.reconstruction;
  for (const Json& entry : b.reconstruction) reconstruction.push_back(entry);
  for (const Json& entry : a_performances.reconstruction) reconstruction.push_back(entry);
  const double data_s = SecondsSince(data_start);

  // The held-out walk: section 2 films subject A walking it, section 4 has subject B walk it for
  // the retargeting truth (simulated beside F's training below).
  const sim::MotionOptions walk = WalkInPlace(options.test_walk_step_hz, options.seed + 50);
  const std::string test_name = TakeName(test_simulated.info.expression, test_hz);
  const dynamics::FrameRange test_scored = dynamics::ScoredFrames(test_simulated, skip);
  const std::vector<int> jiggle =
      eval::JigglingVertices(test_simulated.channels.at("dynamic_offset"), test_scored);
  const double test_offset_mm =
      eval::MeanOffsetNorm(test_simulated.channels.at("dynamic_offset"), jiggle, test_scored);
  const PointCache& test_truth = test_simulated.channels.at("quasistatic");

  // Paper Fig. 5: F trained on the slowest 1 .. n frequencies. Every bar, the full set included,
  // is trained with the same options and exactly the same number of Adam steps
  // (learn::MlpTrainOptions::optimizer_steps): the full set trains subset_epochs first, and each
  // subset trains that many steps on its own rows, so the bars differ only in their
  // frequencies. Round 1 took the last bar from F at removal_epochs and the others at
  // subset_epochs.
  const size_t n_hz = options.train_hz.size();
  std::vector<Json> bars(n_hz);
  // The full set's step count, for the subsets: they may start before the full set is done
  // (they run side by side with other networks below), so they wait for it. Always set, -1 when
  // the full set failed, so no subset waits forever.
  std::promise<long> budget_promise;
  std::shared_future<long> budget_steps = budget_promise.get_future().share();
  auto train_bar = [&](size_t k) -> Status {
    long budget = 0;
    if (k < n_hz) {
      budget = budget_steps.get();
      if (budget < 1) {
        return FailedPreconditionError(fmt::format(
            "Fig. 5's subset of {} frequencies: the full set's training failed", k));
      }
    }
    const size_t per_frequency = options.expressions.size();
    std::vector<Take> subset(a.reconstructed.begin(), a.reconstructed.begin() + k * per_frequency);
    subset.insert(subset.end(), a.reconstructed.begin() + n_hz * per_frequency,
                  a.reconstructed.end());
    learn::MlpTrainSummary subset_summary;
    FACEDYN_ASSIGN_OR_RETURN(
        const dynamics::RemovalModel model,
        TrainF(subset, face, options.removal_targets, options.subset_epochs, options.removal_batch,
               options.seed, fmt::format("F on {} frequencies", k), &subset_summary,
               /*show_progress=*/false, budget));
    FACEDYN_ASSIGN_OR_RETURN(const Take subset_removed,
                             dynamics::RemoveDynamics(model, test_reconstructed, face));
    const double error_mm =
        eval::MeanDistanceOverVertices(subset_removed.positions, test_truth, jiggle, test_scored);
    bars[k - 1] = {
        {"train_hz", std::vector<double>(options.train_hz.begin(), options.train_hz.begin() + k)},
        {"training_walk_step_hz", options.training_walk_step_hz},
        {"epochs", subset_summary.epochs},
        {"training_rows", subset_summary.training_rows},
        {"optimizer_steps", subset_summary.optimizer_steps},
        {"jiggle_mean_mm", Round4(error_mm)},
        {"relative_to_offset", Round4(test_offset_mm > 0 ? error_mm / test_offset_mm : 0)}};
    return Status::Ok();
  };

  // --- 2. the networks that need only the data, two at a time ---
  // A's removal F; Fig. 5's bars (the full set first); subject B's chain (F_B, B's takes
  // decomposed by it, H_B, B's modal model, and B walking the held-out walk for the retargeting
  // truth). LibTorch trains these small networks on one core (the default demo's CPU, sampled
  // every 2 s, read 1.00 through F's 90 s), so two at once take about the time of one. The
  // results are those of training one after the other (learn/mlp.h, Determinism): only F shows
  // a progress bar, the others log a line when done.
  const auto networks_start = Clock::now();
  std::optional<dynamics::RemovalModel> f_trained;
  learn::MlpTrainSummary f_summary;
  struct SubjectBModels {
    std::optional<dynamics::RemovalModel> f;
    std::optional<dynamics::SynthesisModel> h;
    std::optional<dynamics::ModalSynthesisModel> modal;
    learn::MlpTrainSummary f_summary, h_summary;
    Json modal_fit;
    Eigen::Matrix3Xd shape;  // the quasistatic: mean shape of F_B's removal of B's neutral take
    std::optional<Take> walk_truth;
  } b_models;
  auto train_b_chain = [&]() -> Status {
    FACEDYN_ASSIGN_OR_RETURN(
        b_models.f, TrainF(b.reconstructed, face_b, options.removal_targets,
                           options.second_subject_removal_epochs, options.removal_batch,
                           options.seed, "F_B", &b_models.f_summary, /*show_progress=*/false));
    std::vector<Take> decomposed_b;
    for (const Take& take : b.reconstructed) {
      FACEDYN_ASSIGN_OR_RETURN(Take decomposed,
                               dynamics::RemoveDynamics(*b_models.f, take, face_b));
      decomposed_b.push_back(std::move(decomposed));
    }
    FACEDYN_ASSIGN_OR_RETURN(b_models.h, TrainH(decomposed_b, face_b, options.synthesis_epochs,
                                                options.seed, "H_B", &b_models.h_summary,
                                                /*show_progress=*/false));
    FACEDYN_RETURN_IF_ERROR(b_models.h->Save(JoinPath(models_dir, "H_B.pt")));
    b_models.shape = dynamics::MeanShapeInSkull(decomposed_b.front(), skip);
    decomposed_b.clear();
    FACEDYN_ASSIGN_OR_RETURN(b_models.modal, TrainModal(b.reconstructed, face_b, options.seed,
                                                        options.modal_ridge_rule, "modal_B",
                                                        &b_models.modal_fit));
    spdlog::info("simulating subject B walking subject A's walk ({:.1f} s) for the truth",
                 options.walk_seconds);
    FACEDYN_ASSIGN_OR_RETURN(b_models.walk_truth,
                             Simulate(face_b, "neutral", walk, options.walk_seconds, tissue_b,
                                      options.seed + 50));
    return Status::Ok();
  };
  std::vector<std::function<Status()>> first_networks = {
      [&]() -> Status {
        FACEDYN_ASSIGN_OR_RETURN(
            f_trained, TrainF(a.reconstructed, face, options.removal_targets,
                              options.removal_epochs, options.removal_batch, options.seed, "F",
                              &f_summary, /*show_progress=*/true));
        return f_trained->Save(JoinPath(models_dir, "F.pt"));
      },
      train_b_chain};
  if (options.subset_epochs > 0) {
    // The full set right after F, so it is running or done before any subset starts waiting.
    first_networks.insert(first_networks.begin() + 1, [&]() -> Status {
      const Status status = train_bar(n_hz);
      budget_promise.set_value(status.ok() ? bars[n_hz - 1]["optimizer_steps"].get<long>() : -1);
      return status;
    });
    for (size_t k = 1; k < n_hz; ++k) first_networks.push_back([&, k] { return train_bar(k); });
  }
  FACEDYN_RETURN_IF_ERROR(RunSideBySide(first_networks));
  const dynamics::RemovalModel& f_model = *f_trained;
  training["F"] = TrainingJson(f_summary, options.removal_epochs);
  const double networks_s = SecondsSince(networks_start);

  // The modal model (dynamics/modal_synthesis.h) on the same held takes, decomposed by their held
  // mean: a removal by synthesis from the skull's motion beside F, and A's synthesis in section 3.
  // Fitted (one core) beside the filming of the held-out takes below, as is F's scoring on the
  // held-out take.
  std::optional<dynamics::ModalSynthesisModel> modal_trained;
  // The modal model's removals of `reconstructed`, named as the comparison reports them: alone,
  // and followed by the low-pass its own validation error calls for (cutoff in *cutoff_hz).
  auto modal_removals = [&](const Take& reconstructed, std::vector<Take>* storage,
                            double* cutoff_hz) -> StatusOr<std::vector<eval::NamedRemoval>> {
    storage->clear();
    FACEDYN_ASSIGN_OR_RETURN(Take modal, modal_trained->Remove(reconstructed, face));
    FACEDYN_ASSIGN_OR_RETURN(Take filtered,
                             modal_trained->RemoveThenLowPass(reconstructed, face, cutoff_hz));
    storage->push_back(std::move(modal));
    storage->push_back(std::move(filtered));
    return std::vector<eval::NamedRemoval>{{"modal", &(*storage)[0]},
                                           {"modal_lowpass", &(*storage)[1]}};
  };

  Take removed;
  std::vector<Take> modal_storage;
  std::vector<eval::NamedRemoval> test_others;  // the modal removals of the held-out take
  double test_cutoff_hz = 0.0;
  // The modal model's fit and its removals of the held-out take (F's scoring follows once the
  // joint training, when there is one, has F_joint to score beside it).
  auto score_test_take = [&]() -> Status {
    FACEDYN_ASSIGN_OR_RETURN(
        modal_trained,
        TrainModal(a.reconstructed, face, options.seed, options.modal_ridge_rule, "modal_A",
                   &training["modal_A"]));
    FACEDYN_ASSIGN_OR_RETURN(test_others,
                             modal_removals(test_reconstructed, &modal_storage, &test_cutoff_hz));
    return Status::Ok();
  };

  // Two more takes of subject A, never trained on, simulated and filmed (rendered by the 8
  // cameras, dots detected), two at a time as the training takes:
  // - a performance on the held-out frequency: the expression changes (speech), which is what F
  //   is for and where a temporal low-pass smears the performance with the dynamics. F never
  //   saw a changing expression: a capture has targets for held expressions only.
  // - a new head motion: A walking in place at a step rate and with a seed no training walk
  //   has, holding the held-out take's expression. Here a temporal low-pass cannot help: a
  //   walk's dynamics are at the step rate and its first harmonics (2-6 Hz), in the band a
  //   low-pass must pass to keep a performance, where the platform's 6-11 Hz are above it. The
  //   simulation is also the truth for H's synthesis of the walk (section 3).
  const auto held_out_start = Clock::now();
  std::vector<TakeSpec> extra_specs = {
      {fmt::format("{} walk {:g} steps/s", test_simulated.info.expression,
                   options.test_walk_step_hz),
       test_simulated.info.expression, walk, 0.0, options.walk_seconds}};
  std::vector<std::string> extra_sections = {"removal_walk"};  // per extra take, its metrics
  // The held-out performance's index among the extra takes (Fig. 7 resynthesises it below).
  std::optional<size_t> performance_index;
  if (options.performance_expression != "") {
    performance_index = extra_specs.size();
    extra_sections.push_back("removal_performance");
    extra_specs.push_back({TakeName(options.performance_expression, test_hz),
                           options.performance_expression,
                           PlatformMotion(test_hz, options.seed + 70), test_hz, options.seconds});
  }
  // H (section 3) needs only F and the training takes: it trains on one core beside the filming,
  // as do the modal fit and F's scoring on the held-out take.
  std::optional<dynamics::SynthesisModel> h_trained;
  learn::MlpTrainSummary h_summary;
  auto train_h = [&]() -> Status {
    std::vector<Take> decomposed_a;
    for (const Take& take : a.reconstructed) {
      FACEDYN_ASSIGN_OR_RETURN(Take decomposed, dynamics::RemoveDynamics(f_model, take, face));
      decomposed_a.push_back(std::move(decomposed));
    }
    FACEDYN_ASSIGN_OR_RETURN(h_trained, TrainH(decomposed_a, face, options.synthesis_epochs,
                                               options.seed, "H", &h_summary,
                                               /*show_progress=*/false));
    return h_trained->Save(JoinPath(models_dir, "H.pt"));
  };
  SubjectTakes extra;
  int extra_done = 0;
  FACEDYN_RETURN_IF_ERROR(RunSideBySide(
      {[&] {
         return SimulateAndReconstruct(face, cameras, extra_specs, options.seconds, tissue_a, "A",
                                       &extra_done, static_cast<int>(extra_specs.size()), &extra);
       },
       train_h, score_test_take}));
  const dynamics::ModalSynthesisModel& modal_a = *modal_trained;
  const dynamics::SynthesisModel& h_model = *h_trained;
  training["H"] = TrainingJson(h_summary, options.synthesis_epochs);

  // F and H fine-tuned together with the cycle on A's training performances (no target read),
  // from the F and H above, which stay as they are for comparison.
  std::optional<dynamics::JointModels> joint;
  if (!a_performances.reconstructed.empty()) {
    std::vector<dynamics::TrainingTake> held, performances;
    for (const Take& take : a.reconstructed) held.push_back({&take, &face});
    for (const Take& take : a_performances.reconstructed) performances.push_back({&take, &face});
    dynamics::JointTrainOptions joint_options;
    joint_options.removal = FOptions(options.removal_targets, options.removal_epochs,
                                     options.removal_batch, options.seed, "F", false);
    joint_options.synthesis = HOptions(options.synthesis_epochs, options.seed, "H", false);
    joint_options.joint.steps = options.joint_steps;
    joint_options.joint.pair_weight = options.joint_cycle_weight;
    joint_options.joint.keep_least_validation = options.joint_early_stopping;
    joint_options.joint.pair_trains_second = !options.joint_cycle_trains_f_only;
    joint_options.joint.first_batch = options.removal_batch;
    joint_options.joint.second_batch = joint_options.synthesis.train.batch_size;
    joint_options.joint.seed = options.seed;
    joint_options.joint.progress_label = "F+H joint";
    spdlog::info(
        "training F_joint and H_joint: F and H fine-tuned together, the cycle on {} training "
        "performances ({} steps, cycle weight {:g})",
        performances.size(), options.joint_steps, options.joint_cycle_weight);
    dynamics::JointTrainSummary joint_summary;
    FACEDYN_ASSIGN_OR_RETURN(joint, dynamics::FineTuneJoint(held, performances, f_model.Clone(),
                                                            h_model.Clone(), joint_options,
                                                            &joint_summary));
    FACEDYN_RETURN_IF_ERROR(joint->removal.Save(JoinPath(models_dir, "F_joint.pt")));
    FACEDYN_RETURN_IF_ERROR(joint->synthesis.Save(JoinPath(models_dir, "H_joint.pt")));
    const learn::MlpPairTrainSummary& pair = joint_summary.joint;
    auto last = [](const std::vector<double>& v) { return v.empty() ? 0.0 : v.back(); };
    training["joint"] = {
        {"from", "F and H above, fine-tuned together (dynamics::FineTuneJoint)"},
        {"performances", a_performances.names},
        {"performance_frames", joint_summary.performance_frames},
        {"performance_validation_frames", joint_summary.performance_validation_frames},
        {"steps", options.joint_steps},
        {"cycle_weight", options.joint_cycle_weight},
        {"learning_rate", joint_options.joint.learning_rate},
        {"early_stopping", options.joint_early_stopping},
        {"cycle_trains_h", !options.joint_cycle_trains_f_only},
        {"kept_report", pair.kept_report},
        {"reports", static_cast<long>(pair.pair_loss.size())},
        {"final_f_loss", last(pair.first_loss)},
        {"final_h_loss", last(pair.second_loss)},
        {"final_cycle_loss", last(pair.pair_loss)},
        {"final_f_validation_loss", last(pair.first_validation_loss)},
        {"final_h_validation_loss", last(pair.second_validation_loss)},
        {"final_cycle_validation_loss", last(pair.pair_validation_loss)},
        {"f_validation_loss", pair.first_validation_loss},
        {"h_validation_loss", pair.second_validation_loss},
        {"cycle_validation_loss", pair.pair_validation_loss},
        {"train_s", Round4(pair.train_s)}};
  }
  // F_joint's removal of a take, appended to `others` (its take kept in *storage).
  auto add_joint_removal = [&](const Take& reconstructed, Take* storage,
                               std::vector<eval::NamedRemoval>* others) -> Status {
    if (!joint) return Status::Ok();
    FACEDYN_ASSIGN_OR_RETURN(*storage,
                             dynamics::RemoveDynamics(joint->removal, reconstructed, face));
    others->push_back({"F_joint", storage});
    return Status::Ok();
  };
  // After the loop below joint_removed_performance holds the performance's removal by F_joint,
  // and performance_removed its removal by F (both kept for Fig. 7 rather than computed again).
  Take joint_removed_test, joint_removed_extra, joint_removed_performance, performance_removed;
  FACEDYN_RETURN_IF_ERROR(add_joint_removal(test_reconstructed, &joint_removed_test, &test_others));
  FACEDYN_ASSIGN_OR_RETURN(Json test_removal,
                           eval::CompareRemovalOnReconstruction(
                               f_model, reference_removal, test_name, test_simulated,
                               test_reconstructed, face, skip, &removed, test_others));
  test_removal["methods"]["modal_lowpass"]["cutoff_hz"] = Round4(test_cutoff_hz);
  result["removal"] = std::move(test_removal);
  result["removal"]["F_targets"] = dynamics::RemovalTargetsName(options.removal_targets);
  // A copy: Json is an ordered_json, whose objects are vectors that move on insertion.
  const Json methods = result["removal"]["methods"];
  for (size_t i = 0; i < extra_specs.size(); ++i) {
    reconstruction.push_back(extra.reconstruction[i]);
    double cutoff_hz = 0.0;
    FACEDYN_ASSIGN_OR_RETURN(std::vector<eval::NamedRemoval> others,
                             modal_removals(extra.reconstructed[i], &modal_storage, &cutoff_hz));
    const bool is_performance = performance_index == i;
    FACEDYN_RETURN_IF_ERROR(add_joint_removal(
        extra.reconstructed[i], is_performance ? &joint_removed_performance : &joint_removed_extra,
        &others));
    FACEDYN_ASSIGN_OR_RETURN(
        result[extra_sections[i]],
        eval::CompareRemovalOnReconstruction(f_model, reference_removal, extra_specs[i].name,
                                             extra.simulated[i], extra.reconstructed[i], face,
                                             skip, is_performance ? &performance_removed : nullptr,
                                             others));
    result[extra_sections[i]]["methods"]["modal_lowpass"]["cutoff_hz"] = Round4(cutoff_hz);
  }
  // Fig. 7: remove with F, then resynthesise with the take's own head motion, by H and by the
  // modal model (F's quasistatic plus the offsets A's skull motion predicts; not the identity
  // that the modal model's own removal undone by its own synthesis would be).
  // With the joint training, also F_joint's removal resynthesised by H_joint: the pair trained
  // for exactly this agreement.
  // joint_removed: F_joint's removal of the take, scored above (used when there is a joint).
  auto resynthesise = [&](const std::string& name, const Take& simulated,
                          const Take& reconstructed, const Take& removed_take,
                          const Take& joint_removed,
                          Take* by_h) -> StatusOr<Json> {  // by_h: H's take, when wanted
    Take h_take;
    FACEDYN_ASSIGN_OR_RETURN(
        h_take, dynamics::SynthesizeDynamics(h_model, removed_take, reconstructed.world_from_skull,
                                             reconstructed.info.motion, face));
    FACEDYN_ASSIGN_OR_RETURN(Json figures, eval::ResynthesisFigures(name, simulated, reconstructed,
                                                                    removed_take, h_take, skip));
    if (by_h != nullptr) *by_h = std::move(h_take);
    FACEDYN_ASSIGN_OR_RETURN(const Take by_modal,
                             modal_a.Synthesize(removed_take, reconstructed.world_from_skull,
                                                reconstructed.info.motion, face));
    FACEDYN_ASSIGN_OR_RETURN(const Json modal, eval::ResynthesisFigures(name, simulated,
                                                                        reconstructed,
                                                                        removed_take, by_modal,
                                                                        skip));
    figures["modal_resynthesis_residual_mm"] = modal["resynthesis_residual_mm"];
    figures["modal_relative_to_offset"] = modal["relative_to_offset"];
    if (joint) {
      FACEDYN_ASSIGN_OR_RETURN(
          const Take joint_take,
          dynamics::SynthesizeDynamics(joint->synthesis, joint_removed,
                                       reconstructed.world_from_skull, reconstructed.info.motion,
                                       face));
      FACEDYN_ASSIGN_OR_RETURN(const Json by_joint,
                               eval::ResynthesisFigures(name, simulated, reconstructed,
                                                        joint_removed, joint_take, skip));
      figures["H_joint_resynthesis_residual_mm"] = by_joint["resynthesis_residual_mm"];
      figures["H_joint_relative_to_offset"] = by_joint["relative_to_offset"];
      figures["F_joint_removed_without_synthesis_mm"] = by_joint["removed_without_synthesis_mm"];
      // The cross pairings separate what the joint phase did to each network: F_joint's removal
      // resynthesised by the H trained before it, and F's removal by H_joint.
      auto cross = [&](const dynamics::SynthesisModel& synthesis, const Take& removed_by,
                       const char* key) -> Status {
        FACEDYN_ASSIGN_OR_RETURN(
            const Take take,
            dynamics::SynthesizeDynamics(synthesis, removed_by, reconstructed.world_from_skull,
                                         reconstructed.info.motion, face));
        FACEDYN_ASSIGN_OR_RETURN(const Json scored,
                                 eval::ResynthesisFigures(name, simulated, reconstructed,
                                                          removed_by, take, skip));
        figures[key] = scored["resynthesis_residual_mm"];
        return Status::Ok();
      };
      FACEDYN_RETURN_IF_ERROR(
          cross(h_model, joint_removed, "F_joint_then_H_resynthesis_residual_mm"));
      FACEDYN_RETURN_IF_ERROR(
          cross(joint->synthesis, removed_take, "F_then_H_joint_resynthesis_residual_mm"));
    }
    return figures;
  };
  auto print_resynthesis = [](const Json& figures) {
    const std::string take = figures["take"].get<std::string>();
    const double offset_mm = figures["mean_dynamic_offset_mm"].get<double>();
    for (const auto& [label, key] :
         {std::pair<const char*, const char*>{"remove+resynthesise by H, residual",
                                              "resynthesis_residual_mm"},
          {"remove+resynthesise by the modal model, residual", "modal_resynthesis_residual_mm"},
          {"removed, not resynthesised", "removed_without_synthesis_mm"},
          {"F_joint removes, H_joint resynthesises, residual",
           "H_joint_resynthesis_residual_mm"},
          {"F_joint removes, H resynthesises, residual", "F_joint_then_H_resynthesis_residual_mm"},
          {"F removes, H_joint resynthesises, residual", "F_then_H_joint_resynthesis_residual_mm"}}) {
      if (!figures.contains(key)) continue;
      const double mm = figures[key].get<double>();
      eval::PrintMethodRow(take, label, mm, offset_mm > 0 ? mm / offset_mm : 0.0);
    }
  };
  // The held-out performance (speech at the held-out frequency), what the Fig. 7 target
  // is set on: a take where the expression moves, unlike the held one below.
  Json performance_resynthesis;
  if (performance_index) {
    const size_t p = *performance_index;
    FACEDYN_ASSIGN_OR_RETURN(
        performance_resynthesis,
        resynthesise(extra_specs[p].name + " reconstructed", extra.simulated[p],
                     extra.reconstructed[p], performance_removed, joint_removed_performance,
                     nullptr));
    if (artifacts != nullptr) {
      artifacts->performance_simulated = extra.simulated[p];
      artifacts->performance_reconstructed = extra.reconstructed[p];
      artifacts->performance_removed = std::move(performance_removed);
    }
  }
  result["removal_walk"]["step_hz"] = options.test_walk_step_hz;
  result["removal_walk"]["training_walk_step_hz"] = options.training_walk_step_hz;
  Take walk_truth = std::move(extra.simulated.front());
  extra = SubjectTakes();
  const double held_out_s = SecondsSince(held_out_start);

  if (options.subset_epochs > 0) {
    Json subsets = Json::array();
    for (Json& bar : bars) subsets.push_back(std::move(bar));
    result["removal_by_training_frequencies"] = {
        {"take", test_name + " reconstructed"},
        {"mean_dynamic_offset_mm", Round4(test_offset_mm)},
        {"subsets", subsets},
        {"baselines",
         {{"lowpass", methods["lowpass"]["jiggle_mean_mm"]},
          {"lowpass_oracle", methods["lowpass_oracle"]["jiggle_mean_mm"]},
          {"moving_average", methods["moving_average"]["jiggle_mean_mm"]},
          {"no_removal", methods["no_removal"]["jiggle_mean_mm"]}}}};
  }

  // --- 3. synthesis H on A's takes decomposed by F (trained beside the held-out filming) ---
  // Fig. 7: remove, then resynthesise the held-out take with its own head motion.
  Take resynthesised;
  Json synthesis;
  FACEDYN_ASSIGN_OR_RETURN(synthesis["resynthesis"],
                           resynthesise(test_name + " reconstructed", test_simulated,
                                        test_reconstructed, removed, joint_removed_test,
                                        &resynthesised));
  std::printf("\nSynthesis (H trained on %zu takes decomposed by F):\n", a.reconstructed.size());
  print_resynthesis(synthesis["resynthesis"]);
  if (!performance_resynthesis.is_null()) {
    print_resynthesis(performance_resynthesis);
    synthesis["resynthesis_performance"] = std::move(performance_resynthesis);
  }

  // The new head motion (the walk simulated in section 2) synthesised by H. The quasistatic is
  // F's estimate of the held-out take's shape.
  const Eigen::Matrix3Xd shape_a = dynamics::MeanShapeInSkull(removed, skip);
  const Take walk_quasistatic =
      dynamics::HeldShapeTake(face, shape_a, walk_truth.world_from_skull, fps);
  FACEDYN_ASSIGN_OR_RETURN(Take walk_synthesised,
                           dynamics::SynthesizeDynamics(h_model, walk_quasistatic,
                                                        walk_truth.world_from_skull, "walk", face));
  const dynamics::FrameRange walk_scored = dynamics::ScoredFrames(walk_truth, skip);
  const std::vector<int> walk_jiggle =
      eval::JigglingVertices(walk_truth.channels.at("dynamic_offset"), walk_scored);
  const double walk_offset_mm =
      eval::MeanOffsetNorm(walk_truth.channels.at("dynamic_offset"), walk_jiggle, walk_scored);
  Json walk_methods;
  FACEDYN_ASSIGN_OR_RETURN(walk_methods["H"],
                           eval::SynthesisErrors(walk_synthesised, walk_truth, walk_jiggle, skip));
  FACEDYN_ASSIGN_OR_RETURN(
      const Take walk_modal,
      modal_a.Synthesize(walk_quasistatic, walk_truth.world_from_skull, "walk", face));
  FACEDYN_ASSIGN_OR_RETURN(walk_methods["modal"],
                           eval::SynthesisErrors(walk_modal, walk_truth, walk_jiggle, skip));
  FACEDYN_ASSIGN_OR_RETURN(
      walk_methods["no_dynamics"],
      eval::NoDynamicsErrors(walk_quasistatic, walk_truth, walk_jiggle, skip));
  synthesis["walk"] = {{"take", test_simulated.info.expression + " walking, subject A"},
                       {"truth", "subject A simulated walking"},
                       {"quasistatic", "mean shape of F's removal of the held-out take"},
                       {"jiggle_vertices", walk_jiggle.size()},
                       {"mean_dynamic_offset_mm", Round4(walk_offset_mm)},
                       {"methods", walk_methods}};
  for (const auto& [name, figures] : walk_methods.items()) {
    eval::PrintMethodRow("walk (new head motion)", name + ": offset error",
             figures["offset_mean_mm"].get<double>(),
             walk_offset_mm > 0 ? figures["offset_mean_mm"].get<double>() / walk_offset_mm : 0);
  }
  result["synthesis"] = synthesis;

  // --- 4. retargeting to subject B: B's own F and H (trained in section 2), A's walk ---
  dynamics::RemovalModel fb_model = std::move(*b_models.f);
  const dynamics::SynthesisModel& hb_model = *b_models.h;
  const dynamics::ModalSynthesisModel& modal_b = *b_models.modal;
  training["F_B"] = TrainingJson(b_models.f_summary, options.second_subject_removal_epochs);
  training["H_B"] = TrainingJson(b_models.h_summary, options.synthesis_epochs);
  training["modal_B"] = std::move(b_models.modal_fit);
  Take retarget_truth = std::move(*b_models.walk_truth);
  const Take b_quasistatic =
      dynamics::HeldShapeTake(face_b, b_models.shape, walk_truth.world_from_skull, fps);
  FACEDYN_ASSIGN_OR_RETURN(eval::RetargetingResult retargeting,
                           eval::ScoreRetargeting(hb_model, walk_truth, face, retarget_truth,
                                                  face_b, b_quasistatic, skip, &modal_b));
  const Json retarget_methods = retargeting.figures["methods"];
  const double b_offset_mm = retargeting.figures["mean_dynamic_offset_mm"].get<double>();
  Take retargeted = std::move(retargeting.retargeted);
  Take naive = std::move(retargeting.naive);
  Take retargeted_modal = std::move(retargeting.modal);
  result["retarget"] = {
      {"source", "subject A walking (head motion)"},
      {"target",
       fmt::format("subject B: procedural face scaled {:g} x {:g} x {:g}, tissue "
                   "{:g} Hz, damping {:g} (A: {:g} Hz, {:g})",
                   options.second_subject_scale_x, options.second_subject_scale_y,
                   options.second_subject_scale_z, tissue_b.fundamental_hz, tissue_b.damping_ratio,
                   tissue_a.fundamental_hz, tissue_a.damping_ratio)},
      {"truth", "subject B simulated walking the same walk"},
      {"training_takes", b.reconstructed.size()},
      {"jiggle_vertices", retargeting.figures["jiggle_vertices"]},
      {"mean_dynamic_offset_mm", retargeting.figures["mean_dynamic_offset_mm"]},
      {"methods", retarget_methods}};
  std::printf("\nRetargeting A's walk to subject B (mean true offset %.3f mm):\n", b_offset_mm);
  for (const auto& [name, figures] : retarget_methods.items()) {
    eval::PrintMethodRow("B walking", name + ": offset error", figures["offset_mean_mm"].get<double>(),
             b_offset_mm > 0 ? figures["offset_mean_mm"].get<double>() / b_offset_mm : 0);
  }

  Json train_hz_json = options.train_hz;
  result["setup"] = {
      {"data",
       "every take filmed (rendered by the 8 simulated cameras, dots detected, "
       "eval::FilmSimulatedTake) and reconstructed: the training takes and walks, the held-out "
       "take (app/reconstruct_demo.cc), the test walk and the speech performance"},
      {"targets", dynamics::RemovalTargetsName(options.removal_targets)},
      {"targets_note", TargetsNote(options.removal_targets)},
      {"train_hz", train_hz_json},
      {"expressions", options.expressions},
      {"training_walk_step_hz", options.training_walk_step_hz},
      {"test_walk_step_hz", options.test_walk_step_hz},
      {"test_take", test_name},
      {"test_hz", test_hz},
      {"seconds_per_take", options.seconds},
      {"subset_epochs", options.subset_epochs},
      {"training_takes", a.reconstructed.size()},
      {"training_performances", a_performances.names},
      {"second_subject_hz", options.second_subject_hz},
      {"second_subject_expressions", options.second_subject_expressions},
      {"removal_epochs", options.removal_epochs},
      {"second_subject_removal_epochs", options.second_subject_removal_epochs},
      {"removal_batch", options.removal_batch},
      {"synthesis_epochs", options.synthesis_epochs},
      {"subset_epochs", options.subset_epochs},
      {"data_s", Round4(data_s)},
      {"steps_s",
       {{"data", Round4(data_s)},
        {"F_beside_B_networks_and_subset_bars", Round4(networks_s)},
        {"held_out_takes_beside_H", Round4(held_out_s)}}},
      {"error_metric",
       "per-vertex |prediction - truth| in mm over frames away from the feature window at the "
       "ends; jiggle_mean_mm over vertices whose mean true offset is >= 20% of the largest"}};
  result["reconstruction"] = reconstruction;
  result["training"] = training;
  result["total_s"] = Round4(SecondsSince(stage_start));
  if (metrics != nullptr) *metrics = result;
  if (artifacts != nullptr) {
    artifacts->test_simulated = test_simulated;
    artifacts->test_reconstructed = test_reconstructed;
    artifacts->test_removed = std::move(removed);
    artifacts->test_resynthesised = std::move(resynthesised);
    artifacts->walk_truth = std::move(walk_truth);
    artifacts->walk_step_hz = options.test_walk_step_hz;
    artifacts->walk_synthesised = std::move(walk_synthesised);
    artifacts->second_face = face_b;
    artifacts->second_subject_tissue = tissue_b;
    artifacts->second_subject_reconstructed = std::move(b.reconstructed);
    artifacts->second_subject_removal = std::move(fb_model);
    artifacts->second_subject_removal_targets = options.removal_targets;
    artifacts->second_subject_removal_steps = b_models.f_summary.optimizer_steps;
    artifacts->second_subject_removal_batch = options.removal_batch;
    artifacts->retarget_truth = std::move(retarget_truth);
    artifacts->retargeted = std::move(retargeted);
    artifacts->naive = std::move(naive);
    artifacts->retargeted_modal = std::move(retargeted_modal);
  }
  return Status::Ok();
}

namespace {

// Positions of frame t in the skull frame (3 x V): T(t)^-1 x(t).
Eigen::Matrix3Xf InSkull(const Take& take, const PointCache& cache, int t) {
  return take.world_from_skull[t].Inverse().Apply(cache.Frame(t).cast<double>()).cast<float>();
}

// The frame of largest mean |offset| in the second half (away from the end window), and one
// `period_frames` / 2 later: two opposite extremes of an oscillation.
std::vector<int> ExtremalFrames(const PointCache& offsets, int skip, int period_frames) {
  const int frames = offsets.frame_count();
  int peak = frames / 2;
  double best = -1.0;
  for (int t = frames / 2; t < frames - skip; ++t) {
    const double mean = offsets.Frame(t).colwise().norm().mean();
    if (mean > best) best = mean, peak = t;
  }
  const int later = peak + std::max(1, period_frames / 2);
  return {peak, later < frames ? later : std::max(0, peak - std::max(1, period_frames / 2))};
}

Status WriteBytes(const std::string& path, const std::vector<unsigned char>& bytes) {
  FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) return UnavailableError(path + ": cannot open for writing");
  const size_t written = std::fwrite(bytes.data(), 1, bytes.size(), file);
  const bool closed = std::fclose(file) == 0;
  if (written != bytes.size() || !closed) return UnavailableError(path + ": write failed");
  return Status::Ok();
}

}  // namespace

StatusOr<Json> RenderDemoDynamics(const FaceRig& face, const DemoDynamicsArtifacts& artifacts,
                                  const std::string& out_dir) {
  const std::string dir = JoinPath(out_dir, "renders");
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(dir));
  struct View {
    std::string name;
    Eigen::Matrix3Xf positions_in_skull, offsets_in_skull;
  };
  Json images = Json::array();
  Json groups = Json::array();
  int image_index = 0;
  // Small enough that 16 renders keep the self-contained report near 1 MB.
  report::OffsetRenderOptions render_options;
  render_options.width_px = 240;
  render_options.height_px = 293;
  // Colour ranges as in the paper's figures: +-5 mm for the platform (Fig. 3), +-2 mm for the
  // walk (Figs. 8d, 9), whose dynamics are smaller.
  auto render_group = [&](const std::string& group, double range_mm, const Mesh& topology,
                          const std::vector<int>& frames,
                          const std::function<std::vector<View>(int)>& views_at) -> Status {
    groups.push_back({{"group", group}, {"range_mm", range_mm}});
    render_options.range_mm = range_mm;
    for (int t : frames) {
      for (const View& view : views_at(t)) {
        // Relative to the output folder, so metrics.json and the report survive a move.
        const std::string path =
            JoinPath("renders", fmt::format("{:02d}_frame{:04d}.png", image_index++, t));
        FACEDYN_RETURN_IF_ERROR(WriteBytes(
            JoinPath(out_dir, path), report::RenderSignedOffsetPng(topology, view.positions_in_skull,
                                                           view.offsets_in_skull, render_options)));
        images.push_back(
            {{"group", group},
             {"range_mm", range_mm},
             {"frame", t},
             {"view", view.name},
             {"path", path},
             {"max_abs_offset_mm", Round4(view.offsets_in_skull.colwise().norm().maxCoeff())}});
      }
    }
    return Status::Ok();
  };

  const Take& simulated = artifacts.test_simulated;
  const int skip = dynamics::WindowFrames(0.08, simulated.info.fps);
  const double hz = simulated.info.platform_hz.value_or(11.0);
  const std::string test_name = TakeName(simulated.info.expression, hz);
  const std::vector<int> test_frames =
      ExtremalFrames(simulated.channels.at("dynamic_offset"), skip,
                     static_cast<int>(std::lround(simulated.info.fps / hz)));
  FACEDYN_RETURN_IF_ERROR(render_group(
      "held-out " + test_name + ", reconstructed", 5.0, face.neutral, test_frames, [&](int t) {
        const Eigen::Matrix3Xf truth = InSkull(simulated, simulated.channels.at("quasistatic"), t);
        const Eigen::Matrix3Xf captured =
            InSkull(artifacts.test_reconstructed, artifacts.test_reconstructed.positions, t);
        const Eigen::Matrix3Xf removed =
            InSkull(artifacts.test_removed, artifacts.test_removed.positions, t);
        const Eigen::Matrix3Xf resynthesised =
            InSkull(artifacts.test_resynthesised, artifacts.test_resynthesised.positions, t);
        return std::vector<View>{
            {"reconstructed - exact quasistatic", captured, captured - truth},
            {"after removal by F - exact quasistatic", removed, removed - truth},
            {"resynthesised by H - removed", resynthesised, resynthesised - removed}};
      }));

  // Walk: half a stride (one step) apart.
  const double step_hz = artifacts.walk_step_hz > 0 ? artifacts.walk_step_hz : 1.9;
  const int step_frames = static_cast<int>(std::lround(simulated.info.fps / step_hz));
  auto offset_view = [](const std::string& name, const Take& take, int t) {
    return View{name, InSkull(take, take.positions, t),
                take.channels.at("dynamic_offset").Frame(t)};
  };
  const std::vector<int> walk_frames =
      ExtremalFrames(artifacts.walk_truth.channels.at("dynamic_offset"), skip, step_frames);
  FACEDYN_RETURN_IF_ERROR(
      render_group("walk (new head motion), subject A", 2.0, face.neutral, walk_frames, [&](int t) {
        return std::vector<View>{
            offset_view("synthesised by H (dynamic offset)", artifacts.walk_synthesised, t),
            offset_view("simulated truth (dynamic offset)", artifacts.walk_truth, t)};
      }));
  const std::vector<int> retarget_frames =
      ExtremalFrames(artifacts.retarget_truth.channels.at("dynamic_offset"), skip, step_frames);
  FACEDYN_RETURN_IF_ERROR(
      render_group("A's walk retargeted to subject B", 2.0, artifacts.second_face.neutral,
                   retarget_frames, [&](int t) {
                     return std::vector<View>{
                         offset_view("B's H (dynamic offset)", artifacts.retargeted, t),
                         offset_view("B's modal synthesis", artifacts.retargeted_modal, t),
                         offset_view("naive transfer of A's offsets", artifacts.naive, t),
                         offset_view("B simulated walking (truth)", artifacts.retarget_truth, t)};
                   }));

  // The same takes as browser pages (report/take_viewer.h), one second from the first scored
  // frame: about 9.3 bytes a vertex a frame, so three 1 s takes are ~18 MB a page.
  Json viewers = Json::array();
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(JoinPath(out_dir, "viewers")));
  auto write_viewer = [&](const std::string& file, const std::string& title,
                          const std::vector<report::ViewerTake>& takes) -> Status {
    report::ViewerOptions options;
    options.title = title;
    options.first_frame = skip;
    options.max_frames = static_cast<int>(std::lround(takes.front().take.info.fps));
    const std::string path = JoinPath("viewers", file);
    FACEDYN_ASSIGN_OR_RETURN(const report::ViewerSummary summary,
                             report::WriteTakeViewer(takes, options, JoinPath(out_dir, path)));
    viewers.push_back({{"title", title}, {"path", path}, {"megabytes", Round4(summary.bytes / 1e6)}});
    return Status::Ok();
  };
  FACEDYN_RETURN_IF_ERROR(write_viewer(
      "held_out_removal.html", "held-out " + test_name + ": reconstructed, after removal by F, simulated",
      {{"reconstructed (F's input)", artifacts.test_reconstructed},
       {"after removal by F", artifacts.test_removed},
       {"simulated (truth, with its exact quasistatic)", artifacts.test_simulated}}));
  FACEDYN_RETURN_IF_ERROR(write_viewer("retargeting.html", "A's walk retargeted to subject B",
                                       {{"B's H", artifacts.retargeted},
                                        {"B's modal synthesis", artifacts.retargeted_modal},
                                        {"naive transfer of A's offsets", artifacts.naive},
                                        {"B simulated walking (truth)", artifacts.retarget_truth}}));
  return Json{{"range_mm", 5.0}, {"groups", groups}, {"images", images}, {"viewers", viewers}};
}

}  // namespace facedyn::app
