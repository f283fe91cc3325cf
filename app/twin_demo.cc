#include "app/twin_demo.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

#include "core/file_util.h"
#include "core/parallel_for.h"
#include "dynamics/features.h"
#include "dynamics/removal_model.h"
#include "eval/metrics.h"
#include "eval/removal_comparison.h"
#include "physics/skull_kinematics.h"
#include "physics/twin.h"
#include "physics/twin_targeting.h"
#include "sim/expressions.h"
#include "sim/performance.h"

namespace facedyn::app {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

std::string MotionLabel(const TwinDemoOptions::HeadMotion& motion) {
  return fmt::format("{} {:g} Hz {:g} deg", sim::MotionKindName(motion.kind), motion.hz,
                     motion.deg);
}

sim::MotionOptions HeadMotionOptions(const TwinDemoOptions::HeadMotion& motion, uint64_t seed) {
  sim::MotionOptions options;
  options.kind = motion.kind;
  options.head_motion_hz = motion.hz;
  options.head_motion_deg = motion.deg;
  options.seed = seed;
  return options;
}

// Section 5 (see the header): both fits of `take`'s frames from `from_s` on.
StatusOr<Json> TargetLyingBack(const FaceRig& subject, const physics::FittedTwin& twin,
                               const Take& take, double from_s, const TwinDemoOptions& options) {
  int first = 0;
  while (first < take.frame_count() && take.time_s[first] < from_s) ++first;
  if (first >= take.frame_count()) {
    return FailedPreconditionError(fmt::format(
        "twin stage: the lying-back take ends at {:.2f} s, before its held window ({:.2f} s)",
        take.time_s.back(), from_s));
  }
  const std::vector<int> vertices = physics::TwinMarkerVertices(subject);
  FACEDYN_ASSIGN_OR_RETURN(const physics::HeldWindow window,
                           physics::MeanHeldWindow(take, vertices, first, take.frame_count()));
  const Eigen::Vector3d& gravity_change = window.gravity_change_in_skull;
  FACEDYN_ASSIGN_OR_RETURN(std::unique_ptr<physics::SoftTissueModel> model,
                           physics::SoftTissueModel::Create(subject, twin.prior, twin.material));
  // The defaults (robust loss, skull alignment) were chosen on validation seeds (README).
  const physics::TargetingOptions targeting;
  FACEDYN_ASSIGN_OR_RETURN(
      const physics::ExpressionTargeting fit,
      physics::TargetHeldExpression(*model, subject, vertices, window.positions_in_skull,
                                    gravity_change, targeting));
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::VectorXd configured,
                           sim::ExpressionWeights(subject, options.targeting_expression));
  const double plain_mm = eval::ExpressionSkinRmsMm(subject, fit.blendshape.weights, configured);
  const double twin_mm = eval::ExpressionSkinRmsMm(subject, fit.twin.weights, configured);
  std::printf(
      "\nTargeting subject %s's %s held lying back %g deg (filmed; gravity in the skull frame "
      "changed by %.0f mm/s^2), %d frames at %zu markers:\n"
      "  marker RMS: blendshape fit %.3f mm, twin %.3f mm (on the %d markers both hold: %.3f mm, "
      "%.3f mm)\n"
      "  expression vs the configured one (RMS over the skin, scoring only): %.3f mm, %.3f mm\n"
      "  flesh volume change: %+.2f%%, %+.2f%%\n"
      "  (both fits: Cauchy loss of %g mm, skull frame corrected by %.3f deg and %.3f mm for the "
      "twin; %d outlier markers)\n",
      subject.name.c_str(), options.targeting_expression.c_str(), options.lie_back_deg,
      gravity_change.norm(), window.frames, vertices.size(), fit.blendshape.rms_mm, fit.twin.rms_mm,
      fit.twin.common_inlier_markers, fit.blendshape.common_inlier_rms_mm,
      fit.twin.common_inlier_rms_mm, plain_mm, twin_mm, 100 * fit.blendshape.flesh_volume_change,
      100 * fit.twin.flesh_volume_change, targeting.robust_scale_mm, fit.twin.skull_rotation_deg,
      fit.twin.skull_translation_mm, fit.twin.outlier_markers);
  std::fflush(stdout);
  auto fit_json = [](const physics::ExpressionTargetingFit& f, double expression_mm) {
    return Json{{"marker_rms_mm", eval::Round4(f.rms_mm)},
                {"common_inlier_rms_mm", eval::Round4(f.common_inlier_rms_mm)},
                {"common_inlier_markers", f.common_inlier_markers},
                {"expression_rms_mm", eval::Round4(expression_mm)},
                {"flesh_volume_change", f.flesh_volume_change},
                {"skull_rotation_deg", eval::Round4(f.skull_rotation_deg)},
                {"skull_translation_mm", eval::Round4(f.skull_translation_mm)},
                {"outlier_markers", f.outlier_markers},
                {"iterations", f.iterations}};
  };
  return Json{{"expression", options.targeting_expression},
              {"lie_back_deg", options.lie_back_deg},
              {"frames", window.frames},
              {"markers", vertices.size()},
              {"gravity_change_mm_s2", eval::Round4(gravity_change.norm())},
              {"blendshape", fit_json(fit.blendshape, plain_mm)},
              {"twin", fit_json(fit.twin, twin_mm)}};
}

}  // namespace

TwinDemoOptions TwinDemoOptions::ForDemo(bool quick, uint64_t seed) {
  TwinDemoOptions options;
  options.seed = seed;
  if (quick) {
    options.twin_motions = {{sim::MotionKind::kNod, 1.4, 20.0},
                            {sim::MotionKind::kShake, 2.6, 22.0}};
    options.twin_seconds = 1.25;
    options.test_seconds = 1.5;
    options.single_group = true;
  }
  return options;
}

StatusOr<Json> RunTwinDemoStage(const FaceRig& subject, const physics::TissueOptions& true_tissue,
                                const std::vector<Take>& captured,
                                const CapturedRemoval& captured_removal,
                                const eval::SimulatedCameraRig& cameras,
                                const TwinDemoOptions& options, const std::string& out_dir) {
  const auto start = Clock::now();
  if (captured_removal.model == nullptr || captured_removal.optimizer_steps < 1 ||
      captured_removal.batch_size < 1) {
    return InvalidArgumentError(fmt::format(
        "twin stage: subject {}'s captured removal network is missing or has no optimiser steps "
        "({}) or batch ({})",
        subject.name, captured_removal.optimizer_steps, captured_removal.batch_size));
  }
  std::vector<std::pair<std::string, const Take*>> platform;
  for (const Take& take : captured) {
    if (take.info.platform_hz) {
      platform.push_back(
          {fmt::format("{} {:g} Hz", take.info.expression, *take.info.platform_hz), &take});
    }
  }
  if (platform.empty()) {
    return FailedPreconditionError("twin stage: none of subject " + subject.name +
                                   "'s reconstructed takes records a platform frequency");
  }
  std::printf(
      "\nThe physical twin of subject %s: material fitted to %zu reconstructed platform "
      "takes\n",
      subject.name.c_str(), platform.size());
  std::fflush(stdout);

  // Section 4's held-out takes need nothing fitted or trained: they are simulated and filmed
  // (on every core) from here on, beside the twin's fit (Ceres on one core) and F's training.
  const double fps = captured.front().info.fps;
  const int test_count = static_cast<int>(options.test_motions.size());
  std::vector<std::optional<Take>> test_simulated(test_count);
  std::vector<std::optional<Take>> test_reconstructed(test_count);
  std::optional<Take> lying_back;  // section 5's take, reconstructed
  double lie_back_s = 0.0;
  Status filming_status;
  std::atomic<bool> stop_filming{false};
  std::thread filming([&] {
    for (int m = 0; m < test_count && !stop_filming; ++m) {
      sim::PerformanceOptions performance;
      performance.expression = "neutral";
      performance.seconds = options.test_seconds;
      performance.fps = fps;
      performance.seed = options.seed + 50 + m;
      performance.tissue = true_tissue;
      performance.motion = HeadMotionOptions(options.test_motions[m], options.seed * 100 + 77 + m);
      StatusOr<Take> simulated = sim::SimulatePerformance(subject, performance);
      if (!simulated.ok()) {
        filming_status = simulated.status();
        return;
      }
      StatusOr<reconstruct::Reconstruction> reconstruction = eval::FilmSimulatedTake(
          subject, cameras, *simulated, options.seed * 1000 + 600 + m);
      if (!reconstruction.ok()) {
        filming_status = reconstruction.status();
        return;
      }
      test_simulated[m] = std::move(*simulated);
      test_reconstructed[m] = std::move(reconstruction->take);
    }
    if (stop_filming) return;
    // Section 5's take: the expression held while lying back.
    sim::PerformanceOptions performance;
    performance.expression = options.targeting_expression;
    performance.seconds = options.lie_back_seconds;
    performance.fps = fps;
    performance.seed = options.seed + 60;
    performance.tissue = true_tissue;
    performance.motion.kind = sim::MotionKind::kLieBack;
    performance.motion.lie_back_deg = options.lie_back_deg;
    performance.motion.seed = options.seed * 100 + 88;
    lie_back_s = performance.motion.lie_back_s;
    StatusOr<Take> simulated = sim::SimulatePerformance(subject, performance);
    if (!simulated.ok()) {
      filming_status = simulated.status();
      return;
    }
    StatusOr<reconstruct::Reconstruction> reconstruction =
        eval::FilmSimulatedTake(subject, cameras, *simulated, options.seed * 1000 + 690);
    if (!reconstruction.ok()) {
      filming_status = reconstruction.status();
      return;
    }
    lying_back = std::move(reconstruction->take);
  });
  // Every return below waits for the filming (told to stop after its current take) first.
  struct JoinOnExit {
    std::thread* thread;
    std::atomic<bool>* stop;
    ~JoinOnExit() {
      *stop = true;
      if (thread->joinable()) thread->join();
    }
  } join_filming{&filming, &stop_filming};

  // 1. The twin, from markers and skull pose only.
  physics::TwinFitOptions fit_options;
  if (options.single_group) {
    physics::StiffnessGroup all;
    all.name = "all";
    fit_options.groups = {all};
  }
  fit_options.platform_amplitude_mm = options.platform_amplitude_mm;
  FACEDYN_ASSIGN_OR_RETURN(const physics::FittedTwin twin,
                           physics::FitTwin(subject, platform, fit_options));
  const std::string models_dir = JoinPath(out_dir, "models");
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(models_dir));
  const std::string twin_path = JoinPath(models_dir, "twin_B.json");
  FACEDYN_RETURN_IF_ERROR(WriteJsonFile(twin_path, physics::TwinToJson(twin)));
  const double fitted_hz = twin.cheek_mode.omega_rad_s / (2 * M_PI);
  const double fitted_zeta = twin.cheek_mode.damping_ratio;
  std::printf(
      "  cheek mode: fitted %.3f +- %.3f Hz, damping ratio %.4f +- %.4f; configured "
      "(never told to the fit) %.3f Hz, %.4f; the prior %.3f Hz, %.4f\n",
      fitted_hz, twin.cheek_hz_stddev, fitted_zeta, twin.cheek_damping_ratio_stddev,
      true_tissue.fundamental_hz, true_tissue.damping_ratio,
      twin.prior_cheek_mode.omega_rad_s / (2 * M_PI), twin.prior_cheek_mode.damping_ratio);
  Json result;
  result["fit"] = {
      {"takes", platform.size()},
      {"groups", twin.groups.size()},
      {"fitted_hz", eval::Round4(fitted_hz)},
      {"fitted_hz_sd", eval::Round4(twin.cheek_hz_stddev)},
      {"fitted_damping_ratio", eval::Round4(fitted_zeta)},
      {"fitted_damping_ratio_sd", eval::Round4(twin.cheek_damping_ratio_stddev)},
      {"true_hz", true_tissue.fundamental_hz},
      {"true_damping_ratio", true_tissue.damping_ratio},
      {"hz_error_percent",
       eval::Round4(100 * (fitted_hz - true_tissue.fundamental_hz) / true_tissue.fundamental_hz)},
      {"damping_error_percent",
       eval::Round4(100 * (fitted_zeta - true_tissue.damping_ratio) / true_tissue.damping_ratio)},
      {"prior_hz", eval::Round4(twin.prior_cheek_mode.omega_rad_s / (2 * M_PI))},
      {"prior_damping_ratio", eval::Round4(twin.prior_cheek_mode.damping_ratio)},
      {"fit_s", eval::Round4(twin.seconds)},
      {"twin", twin_path},
      {"note",
       "the simulator integrates the demo's takes with its shipped 1/128 s step, whose frequency "
       "warp makes the forced response look about 6% more damped than configured "
       "(bench/twin_bench.cc); twin_bench simulates at 1/512 s"}};

  const sim::MotionOptions configured_motion;  // B's body: the simulator's standing body
  if (twin.body) {
    std::printf(
        "  body (platform to skull): fitted resonance %.3f +- %.3f Hz, damping ratio %.4f +- "
        "%.4f, pitch %.4f rad/g; configured %.3f Hz, %.4f, %.4f rad/g\n",
        twin.body->resonance_hz, twin.body->resonance_hz_stddev, twin.body->damping_ratio,
        twin.body->damping_ratio_stddev, twin.body->pitch_rad_per_g,
        configured_motion.body_resonance_hz, configured_motion.body_damping_ratio,
        configured_motion.pitch_rad_per_g);
    result["body"] = {{"fitted_hz", eval::Round4(twin.body->resonance_hz)},
                      {"fitted_hz_sd", eval::Round4(twin.body->resonance_hz_stddev)},
                      {"fitted_damping_ratio", eval::Round4(twin.body->damping_ratio)},
                      {"fitted_damping_ratio_sd", eval::Round4(twin.body->damping_ratio_stddev)},
                      {"fitted_pitch_rad_per_g", twin.body->pitch_rad_per_g},
                      {"true_hz", configured_motion.body_resonance_hz},
                      {"true_damping_ratio", configured_motion.body_damping_ratio},
                      {"true_pitch_rad_per_g", configured_motion.pitch_rad_per_g},
                      {"frequencies", twin.body->distinct_frequencies}};
  } else {
    std::printf("  body (platform to skull): %s\n", twin.body_note.c_str());
    result["body"] = {{"note", twin.body_note}};
  }

  // 2. The twin under head motions nobody captured: its fitted material, never the subject's.
  // The takes are independent: simulated two at a time.
  const int twin_count = static_cast<int>(options.twin_motions.size());
  for (const TwinDemoOptions::HeadMotion& motion : options.twin_motions) {
    std::printf("  twin: %s\n", MotionLabel(motion).c_str());
  }
  std::fflush(stdout);
  std::vector<std::optional<Take>> simulated_twin(twin_count);
  FACEDYN_RETURN_IF_ERROR(ParallelFor(twin_count, 0, [&](int m) -> Status {
    sim::PerformanceOptions performance;
    performance.expression = "neutral";
    performance.seconds = options.twin_seconds;
    performance.fps = fps;
    performance.seed = options.seed * 10 + m;
    performance.tissue = twin.prior;  // layers, density, muscles; the material is the fitted one
    performance.material = twin.material;
    performance.motion = HeadMotionOptions(options.twin_motions[m], options.seed * 100 + 10 + m);
    FACEDYN_ASSIGN_OR_RETURN(simulated_twin[m], sim::SimulatePerformance(subject, performance));
    simulated_twin[m]->info.source = "twin perform";
    return Status::Ok();
  }));
  std::vector<Take> twin_takes;
  for (std::optional<Take>& take : simulated_twin) twin_takes.push_back(std::move(*take));
  simulated_twin.clear();

  // 3. F with the twin's takes beside the captured ones, on the captured F's budget and targets
  // (on one core, beside the filming of section 4's takes if it is still running).
  const dynamics::RemovalModel& f_captured = *captured_removal.model;
  dynamics::RemovalTrainOptions train;
  train.targets = captured_removal.targets;
  train.train.optimizer_steps = captured_removal.optimizer_steps;
  train.train.batch_size = captured_removal.batch_size;
  train.train.seed = captured_removal.seed;
  train.train.final_learning_rate_fraction = 0.05;
  train.train.num_threads = 1;
  train.train.show_progress = false;  // the filming beside it shows its progress
  train.train.progress_label = "F_B augmented";
  std::vector<dynamics::TrainingTake> training;
  for (const Take& take : captured) training.emplace_back(&take, &subject);
  for (const Take& take : twin_takes) {
    training.emplace_back(&take, &subject, dynamics::RemovalTargets::kExact, options.twin_weight);
  }
  spdlog::info("training F_B augmented ({} captured, {} twin takes)", captured.size(),
               twin_takes.size());
  learn::MlpTrainSummary augmented_summary;
  FACEDYN_ASSIGN_OR_RETURN(const dynamics::RemovalModel trained_augmented,
                           dynamics::TrainRemoval(training, train, &augmented_summary));
  spdlog::info("trained F_B augmented: {} steps in {:.1f} s", augmented_summary.optimizer_steps,
               augmented_summary.train_s);
  FACEDYN_RETURN_IF_ERROR(trained_augmented.Save(JoinPath(models_dir, "F_B_augmented.pt")));
  filming.join();
  FACEDYN_RETURN_IF_ERROR(filming_status.WithContext("filming the twin stage's held-out takes"));
  const dynamics::RemovalModel& f_augmented = trained_augmented;
  result["training"] = {
      {"captured_takes", captured.size()},
      {"twin_takes", twin_takes.size()},
      {"twin_weight", options.twin_weight},
      {"captured_targets", dynamics::RemovalTargetsName(captured_removal.targets)},
      {"optimizer_steps", augmented_summary.optimizer_steps},
      {"rows_augmented", augmented_summary.training_rows}};
  twin_takes.clear();

  const int window = f_captured.config().features.window_frames();
  Json removal = Json::array();
  std::printf(
      "\nRemoval on subject %s's held-out head motions (filmed: rendered by 8 cameras, dots "
      "detected), error vs the exact quasistatic over the jiggling vertices:\n",
      subject.name.c_str());
  for (int m = 0; m < test_count; ++m) {
    const std::string name = "neutral " + MotionLabel(options.test_motions[m]);
    const Take& simulated = *test_simulated[m];
    const Take& reconstructed = *test_reconstructed[m];
    FACEDYN_ASSIGN_OR_RETURN(const Take by_captured,
                             dynamics::RemoveDynamics(f_captured, reconstructed, subject));
    FACEDYN_ASSIGN_OR_RETURN(const Take by_augmented,
                             dynamics::RemoveDynamics(f_augmented, reconstructed, subject));
    Json methods;
    for (const auto& [method, positions] :
         {std::pair<const char*, const PointCache*>{"no_removal", &reconstructed.positions},
          {"F_captured", &by_captured.positions},
          {"F_augmented", &by_augmented.positions}}) {
      FACEDYN_ASSIGN_OR_RETURN(const double mm,
                               eval::JiggleMeanErrorMm(*positions, simulated, window));
      methods[method] = {{"jiggle_mean_mm", eval::Round4(mm)}};
      eval::PrintMethodRow(name, method, mm,
                           methods["no_removal"]["jiggle_mean_mm"].get<double>() > 0
                               ? mm / methods["no_removal"]["jiggle_mean_mm"].get<double>()
                               : 0.0);
    }
    removal.push_back({{"take", name}, {"protocol", "held-out head motion"}, {"methods", methods}});
  }
  std::printf("  (last column: relative to no removal)\n");
  result["removal"] = removal;

  // 5. Targeting a held frame with the twin: the held window's mean in the skull frame, gravity
  // from the estimated skull pose; the configured expression only scores.
  FACEDYN_ASSIGN_OR_RETURN(result["targeting"],
                           TargetLyingBack(subject, twin, *lying_back, lie_back_s + 1.0, options));
  result["seconds"] = eval::Round4(SecondsSince(start));
  return result;
}

}  // namespace facedyn::app
