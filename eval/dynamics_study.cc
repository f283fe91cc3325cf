#include "eval/dynamics_study.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <optional>
#include <utility>

#include "core/parallel_for.h"
#include "dynamics/baselines.h"
#include "dynamics/joint_training.h"
#include "dynamics/propagation.h"
#include "dynamics/quasistatic.h"
#include "dynamics/removal_model.h"
#include "dynamics/synthesis_model.h"
#include "eval/metrics.h"
#include "eval/synthesis_scoring.h"
#include "learn/mlp.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"
#include "sim/skull_motion.h"

namespace facedyn::eval {
namespace {

using Clock = std::chrono::steady_clock;
double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}


Json StatsJson(const eval::ErrorStats& stats) {
  return {{"mean_mm", Round4(stats.mean_mm)},
          {"p95_mm", Round4(stats.p95_mm)},
          {"max_mm", Round4(stats.max_mm)}};
}

struct SimTake {
  std::string name;
  Take take;
  std::string protocol;  // test takes: which held-out condition they test; else "training"
};

StatusOr<Take> Simulate(const FaceRig& rig, const std::string& expression, double hz,
                        double amplitude_mm, const DynamicsStudyOptions& options, uint64_t seed) {
  sim::PerformanceOptions perform;
  perform.expression = expression;
  perform.motion.kind = sim::MotionKind::kPlatform;
  perform.motion.platform_hz = hz;
  perform.motion.amplitude_mm = amplitude_mm;
  perform.motion.seed = seed;
  perform.seed = seed;
  perform.seconds = options.seconds;
  perform.fps = options.fps;
  return sim::SimulatePerformance(rig, perform);
}

// A neutral take under a head motion no training take has, in place (see held_out_motions).
StatusOr<Take> SimulateMotion(const FaceRig& rig, const std::string& motion,
                              const DynamicsStudyOptions& options, uint64_t seed) {
  sim::PerformanceOptions perform;
  perform.expression = "neutral";
  if (motion == "walk") {
    perform.motion.kind = sim::MotionKind::kWalk;
    perform.motion.walk_speed_mm_per_s = 0;
  } else if (motion == "run") {
    perform.motion.kind = sim::MotionKind::kRun;
    perform.motion.run_speed_mm_per_s = 0;
  } else if (motion == "jump") {
    perform.motion.kind = sim::MotionKind::kJump;
  } else {
    return InvalidArgumentError(
        fmt::format("held_out_motions: \"{}\" is not walk, run or jump", motion));
  }
  perform.motion.seed = seed;
  perform.seed = seed;
  perform.seconds = options.seconds;
  perform.fps = options.fps;
  return sim::SimulatePerformance(rig, perform);
}

}  // namespace

Status DynamicsStudyOptions::Check() const {
  auto hz_ok = [](double hz) { return hz >= 0.5 && hz <= 30; };
  if (train_hz.empty()) return InvalidArgumentError("train_hz: at least one frequency");
  for (double hz : train_hz) {
    if (!hz_ok(hz))
      return InvalidArgumentError("train_hz: " + std::to_string(hz) + " not in 0.5..30");
  }
  if (!hz_ok(test_hz)) return InvalidArgumentError("test_hz must be in 0.5..30");
  if (joint && !train_speech) {
    return InvalidArgumentError("joint: needs the training speech takes (train_speech)");
  }
  if (joint && !(joint_steps >= 1 && std::isfinite(joint_cycle_weight) && joint_cycle_weight >= 0 &&
                 joint_learning_rate > 0)) {
    return InvalidArgumentError(
        "joint: joint_steps >= 1, joint_cycle_weight >= 0 and joint_learning_rate > 0");
  }
  auto amplitude_ok = [](double mm) { return mm > 0 && mm <= 50; };
  if (train_amplitudes_mm.empty())
    return InvalidArgumentError("train_amplitudes_mm: at least one amplitude");
  for (double mm : train_amplitudes_mm) {
    if (!amplitude_ok(mm))
      return InvalidArgumentError("train_amplitudes_mm: " + std::to_string(mm) + " not in (0, 50]");
  }
  if (!amplitude_ok(test_amplitude_mm))
    return InvalidArgumentError("test_amplitude_mm must be in (0, 50]");
  if (expressions.empty()) return InvalidArgumentError("expressions: at least one");
  if (!(seconds >= 0.5)) return InvalidArgumentError("seconds must be >= 0.5");
  if (vertices < 4000 || vertices > 10000)
    return InvalidArgumentError("vertices must be in 4000..10000");
  if (removal_epochs < 1 || synthesis_epochs < 1)
    return InvalidArgumentError("epochs must be >= 1");
  if (!(learning_rate > 0 && learning_rate < 1))
    return InvalidArgumentError("learning_rate must be in (0, 1)");
  if (removal_batch < 1 || synthesis_batch < 1)
    return InvalidArgumentError("batch sizes must be >= 1");
  if (removal_hidden_units < 1) return InvalidArgumentError("removal_hidden_units must be >= 1");
  if (!(removal_weight_decay >= 0))
    return InvalidArgumentError("removal_weight_decay must be >= 0");
  if (!(removal_input_noise_std >= 0))
    return InvalidArgumentError("removal_input_noise_std must be >= 0");
  for (const std::string& expression : held_out_expressions) {
    if (std::find(expressions.begin(), expressions.end(), expression) != expressions.end() ||
        expression == "speech") {
      return InvalidArgumentError(fmt::format(
          "held_out_expressions: \"{}\" is trained on (expressions or speech)", expression));
    }
  }
  if (!held_out_expressions.empty() && !hz_ok(held_out_expression_hz))
    return InvalidArgumentError("held_out_expression_hz must be in 0.5..30");
  for (const std::string& motion : held_out_motions) {
    if (motion != "walk" && motion != "run" && motion != "jump") {
      return InvalidArgumentError(
          fmt::format("held_out_motions: \"{}\" is not walk, run or jump", motion));
    }
  }
  return Status::Ok();
}

namespace {

// F's training options from the study's: one place, so the main models and Fig. 5's subset
// models cannot drift apart in anything but what the caller changes.
dynamics::RemovalTrainOptions RemovalOptionsFor(const DynamicsStudyOptions& options,
                                                dynamics::RemovalTargets targets, int epochs) {
  dynamics::RemovalTrainOptions train_options;
  train_options.train.epochs = epochs;
  train_options.train.batch_size = options.removal_batch;
  train_options.train.learning_rate = options.learning_rate;
  train_options.train.weight_decay = options.removal_weight_decay;
  train_options.train.input_noise_std = options.removal_input_noise_std;
  train_options.train.final_learning_rate_fraction = options.final_learning_rate_fraction;
  train_options.train.seed = options.seed;
  train_options.train.num_threads = options.threads;
  train_options.train.show_progress = options.show_progress;
  train_options.hidden_units = options.removal_hidden_units;
  train_options.linear_skip = options.removal_linear_skip;
  train_options.targets = targets;
  train_options.window_s = options.window_s;
  train_options.learn_propagation = options.removal_learned_propagation;
  train_options.propagation.prior_weight = options.propagation_prior_weight;
  return train_options;
}

dynamics::SynthesisTrainOptions SynthesisOptionsFor(const DynamicsStudyOptions& options) {
  dynamics::SynthesisTrainOptions synthesis_options;
  synthesis_options.train.epochs = options.synthesis_epochs;
  synthesis_options.train.batch_size = options.synthesis_batch;
  synthesis_options.train.seed = options.seed;
  synthesis_options.train.num_threads = options.threads;
  synthesis_options.train.show_progress = options.show_progress;
  synthesis_options.window_s = options.window_s;
  synthesis_options.train.final_learning_rate_fraction = options.final_learning_rate_fraction;
  synthesis_options.learn_propagation = options.synthesis_learned_propagation;
  synthesis_options.propagation.prior_weight = options.propagation_prior_weight;
  return synthesis_options;
}

}  // namespace

StatusOr<Json> RunDynamicsStudy(const DynamicsStudyOptions& options,
                                DynamicsStudyArtifacts* artifacts) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  const auto study_start = Clock::now();
  sim::ProceduralFaceOptions face_options;
  face_options.target_vertex_count = options.vertices;
  FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, sim::MakeProceduralFace(face_options));
  FACEDYN_ASSIGN_OR_RETURN(const dynamics::SamplePropagation propagation,
                           dynamics::SamplePropagation::Build(rig));

  // --- data: held expressions on the platform; the test frequency is never trained on. ---
  const auto simulate_start = Clock::now();
  std::vector<SimTake> train, test;
  // Seeds: the first amplitude's training takes, then the test takes, are numbered exactly as in
  // a one-amplitude study (so its figures do not move when amplitudes are added); the takes at
  // further amplitudes count on from kExtraSeeds apart, clear of them.
  constexpr uint64_t kExtraSeeds = 100000;
  const uint64_t seeds_per_frequency = options.expressions.size() + (options.train_speech ? 1 : 0);
  auto train_seed = [&](size_t hz_index, size_t amplitude_index, size_t take_index) {
    if (amplitude_index == 0) {
      // Held takes frequency-major, then one speech take per frequency (take_index ==
      // expressions.size()), as the one-amplitude study numbered them.
      return take_index < options.expressions.size()
                 ? options.seed + 1 + hz_index * options.expressions.size() + take_index
                 : options.seed + 1 + options.train_hz.size() * options.expressions.size() +
                       hz_index;
    }
    return options.seed + kExtraSeeds * amplitude_index + 1 + hz_index * seeds_per_frequency +
           take_index;
  };
  auto name_of = [](const std::string& expression, double hz, double amplitude_mm,
                    bool show_amplitude) {
    return show_amplitude ? fmt::format("{}@{:g}Hz/{:g}mm", expression, hz, amplitude_mm)
                          : fmt::format("{}@{:g}Hz", expression, hz);
  };
  const bool several_amplitudes = options.train_amplitudes_mm.size() > 1;
  // Every take is listed first (name, seed, list) and then simulated on the machine's cores,
  // each on one thread as the demo's dynamics stage does (one simulation is one core's work):
  // each take has its own seed, so the takes do not depend on the order they run in.
  struct Job {
    std::string name;
    std::string protocol;
    std::vector<SimTake>* list;
    std::function<StatusOr<Take>()> simulate;
  };
  std::vector<Job> jobs;
  std::vector<SimTake> train_speech;
  for (size_t h = 0; h < options.train_hz.size(); ++h) {
    const double hz = options.train_hz[h];
    for (size_t a = 0; a < options.train_amplitudes_mm.size(); ++a) {
      const double amplitude_mm = options.train_amplitudes_mm[a];
      for (size_t e = 0; e < options.expressions.size(); ++e) {
        const std::string& expression = options.expressions[e];
        const uint64_t take_seed = train_seed(h, a, e);
        jobs.push_back({name_of(expression, hz, amplitude_mm, several_amplitudes), "training",
                        &train, [&, expression, hz, amplitude_mm, take_seed] {
                          return Simulate(rig, expression, hz, amplitude_mm, options, take_seed);
                        }});
      }
    }
  }
  if (options.train_speech) {
    for (size_t h = 0; h < options.train_hz.size(); ++h) {
      const double hz = options.train_hz[h];
      for (size_t a = 0; a < options.train_amplitudes_mm.size(); ++a) {
        const double amplitude_mm = options.train_amplitudes_mm[a];
        const uint64_t take_seed = train_seed(h, a, options.expressions.size());
        jobs.push_back({name_of("speech", hz, amplitude_mm, several_amplitudes), "training",
                        &train_speech, [&, hz, amplitude_mm, take_seed] {
                          return Simulate(rig, "speech", hz, amplitude_mm, options, take_seed);
                        }});
      }
    }
  }
  uint64_t seed = options.seed + options.train_hz.size() * seeds_per_frequency;
  for (const std::string& expression : options.expressions) {
    const uint64_t take_seed = ++seed;
    jobs.push_back({expression + "@" + fmt::format("{:g}Hz", options.test_hz), "held-out frequency",
                    &test, [&, expression, take_seed] {
                      return Simulate(rig, expression, options.test_hz, options.test_amplitude_mm,
                                      options, take_seed);
                    }});
  }
  if (options.speech_hz > 0) {
    const uint64_t take_seed = ++seed;
    jobs.push_back({"speech@" + fmt::format("{:g}Hz", options.speech_hz),
                    "held-out performance (speech)", &test, [&, take_seed] {
                      return Simulate(rig, "speech", options.speech_hz, options.test_amplitude_mm,
                                      options, take_seed);
                    }});
  }
  // Seeds of the held-out expression and motion takes count on from here, so adding them does
  // not move the seeds (and figures) of the takes above.
  for (const std::string& expression : options.held_out_expressions) {
    const uint64_t take_seed = ++seed;
    jobs.push_back({fmt::format("{}@{:g}Hz", expression, options.held_out_expression_hz),
                    "held-out expression", &test, [&, expression, take_seed] {
                      return Simulate(rig, expression, options.held_out_expression_hz,
                                      options.test_amplitude_mm, options, take_seed);
                    }});
  }
  for (const std::string& motion : options.held_out_motions) {
    const uint64_t take_seed = ++seed;
    jobs.push_back(
        {"neutral " + motion + " in place", "held-out motion kind", &test,
         [&, motion, take_seed] { return SimulateMotion(rig, motion, options, take_seed); }});
  }
  std::vector<std::optional<Take>> simulated(jobs.size());
  std::atomic<int> finished{0};
  FACEDYN_RETURN_IF_ERROR(ParallelFor(static_cast<int>(jobs.size()), 0, [&](int k) -> Status {
    FACEDYN_ASSIGN_OR_RETURN(Take take, jobs[k].simulate());
    simulated[k] = std::move(take);
    spdlog::info("simulated {} ({}/{})", jobs[k].name, ++finished, jobs.size());
    return Status::Ok();
  }));
  for (size_t k = 0; k < jobs.size(); ++k) {
    jobs[k].list->push_back({jobs[k].name, std::move(*simulated[k]), jobs[k].protocol});
  }
  const double simulate_s = SecondsSince(simulate_start);

  std::vector<dynamics::TrainingTake> held_training, all_training;
  for (const SimTake& t : train) held_training.push_back({&t.take, &rig});
  all_training = held_training;
  for (const SimTake& t : train_speech) all_training.push_back({&t.take, &rig});

  // --- removal networks ---
  struct Trained {
    std::string name;
    dynamics::RemovalModel model;
    learn::MlpTrainSummary summary;
  };
  std::vector<Trained> models;
  auto train_removal = [&](const std::string& name, dynamics::RemovalTargets targets,
                           const std::vector<dynamics::TrainingTake>& training) -> Status {
    const dynamics::RemovalTrainOptions train_options =
        RemovalOptionsFor(options, targets, options.removal_epochs);
    spdlog::info("training removal network {} ({} takes, {} epochs)", name, training.size(),
                 train_options.train.epochs);
    learn::MlpTrainSummary summary;
    FACEDYN_ASSIGN_OR_RETURN(dynamics::RemovalModel model,
                             dynamics::TrainRemoval(training, train_options, &summary));
    models.push_back({name, std::move(model), std::move(summary)});
    return Status::Ok();
  };
  FACEDYN_RETURN_IF_ERROR(
      train_removal("F_exact_targets", dynamics::RemovalTargets::kExact, all_training));
  if (options.moving_average_targets) {
    FACEDYN_RETURN_IF_ERROR(train_removal("F_moving_average_targets",
                                          dynamics::RemovalTargets::kMovingAverage, held_training));
  }
  if (options.platform_targets) {
    FACEDYN_RETURN_IF_ERROR(train_removal(
        "F_platform_targets", dynamics::RemovalTargets::kPlatformSynchronous, held_training));
  }
  Json joint_json;
  if (options.joint) {
    dynamics::JointTrainOptions joint_options;
    joint_options.removal = RemovalOptionsFor(
        options, dynamics::RemovalTargets::kPlatformSynchronous, options.removal_epochs);
    joint_options.synthesis = SynthesisOptionsFor(options);
    joint_options.joint.steps = options.joint_steps;
    joint_options.joint.pair_weight = options.joint_cycle_weight;
    joint_options.joint.learning_rate = options.joint_learning_rate;
    joint_options.joint.keep_least_validation = options.joint_keep_least_validation;
    joint_options.joint.first_batch = options.removal_batch;
    joint_options.joint.second_batch = options.synthesis_batch;
    joint_options.joint.seed = options.seed;
    joint_options.joint.num_threads = options.threads;
    joint_options.joint.show_progress = options.show_progress;
    std::vector<dynamics::TrainingTake> performances;
    for (const SimTake& t : train_speech) performances.push_back({&t.take, &rig});
    spdlog::info(
        "training F and H together (F_joint: {} held takes, {} performances, {} joint "
        "steps)",
        held_training.size(), performances.size(), options.joint_steps);
    dynamics::JointTrainSummary joint_summary;
    FACEDYN_ASSIGN_OR_RETURN(
        dynamics::JointModels joint,
        dynamics::TrainJoint(held_training, performances, joint_options, &joint_summary));
    const learn::MlpPairTrainSummary& pair = joint_summary.joint;
    joint_json = {{"performance_frames", joint_summary.performance_frames},
                  {"performance_validation_frames", joint_summary.performance_validation_frames},
                  {"steps", pair.steps},
                  {"early_stopping", options.joint_keep_least_validation},
                  {"kept_report", pair.kept_report},
                  {"train_s", Round4(pair.train_s)},
                  {"removal_loss_mm2", pair.first_loss},
                  {"synthesis_loss_mm2", pair.second_loss},
                  {"cycle_loss_mm2", pair.pair_loss},
                  {"removal_validation_loss_mm2", pair.first_validation_loss},
                  {"synthesis_validation_loss_mm2", pair.second_validation_loss},
                  {"cycle_validation_loss_mm2", pair.pair_validation_loss}};
    models.push_back({"F_joint", std::move(joint.removal), std::move(joint_summary.removal)});
  }

  // --- removal evaluation against the exact quasistatic ---
  Json removal = Json::array();
  eval::EvaluateOptions evaluate_options;
  const int skip = dynamics::WindowFrames(evaluate_options.window_s, options.fps);
  // F_exact's removal of each test take (for synthesis). The takes are scored independently,
  // two at a time (each removal and baseline runs on one core); the entries keep the takes' order.
  std::vector<Take> removed_by_best(test.size());
  std::vector<Json> entries(test.size());
  FACEDYN_RETURN_IF_ERROR(ParallelFor(static_cast<int>(test.size()), 0, [&](int k) -> Status {
    const SimTake& t = test[k];
    const dynamics::FrameRange scored = dynamics::ScoredFrames(t.take, skip);
    const PointCache& truth = t.take.channels.at("quasistatic");
    const std::vector<int> mask =
        eval::JigglingVertices(t.take.channels.at("dynamic_offset"), scored);
    const double offset_mm =
        eval::MeanDistanceOverVertices(t.take.positions, truth, mask, scored);
    Json entry;
    entry["take"] = t.name;
    entry["protocol"] = t.protocol;
    entry["jiggle_vertices"] = mask.size();
    entry["mean_dynamic_offset_mm"] = Round4(offset_mm);
    Json methods = Json::object();
    auto add_method = [&](const std::string& name, const PointCache& predicted,
                          const eval::ErrorStats& face) {
      const double error_mm = eval::MeanDistanceOverVertices(predicted, truth, mask, scored);
      methods[name] = StatsJson(face);
      methods[name]["jiggle_mean_mm"] = Round4(error_mm);
      methods[name]["relative_to_offset"] = Round4(offset_mm > 0 ? error_mm / offset_mm : 0.0);
    };
    bool baselines_done = false;
    for (const Trained& trained : models) {
      dynamics::RemovalSummary removal_summary;
      FACEDYN_ASSIGN_OR_RETURN(
          Take removed,
          dynamics::RemoveDynamics(trained.model, t.take, rig, &propagation, &removal_summary));
      FACEDYN_ASSIGN_OR_RETURN(
          const eval::Evaluation evaluation,
          eval::Evaluate(removed, t.take, baselines_done ? nullptr : &t.take, &rig,
                             evaluate_options));
      add_method(trained.name, removed.positions, evaluation.reports.front().face);
      if (!baselines_done) {
        for (size_t r = 1; r < evaluation.reports.size(); ++r) {
          const std::string& name = evaluation.reports[r].name;
          FACEDYN_ASSIGN_OR_RETURN(const PointCache baseline,
                                   BaselinePositions(t.take, evaluation, name,
                                                     evaluate_options.baselines));
          add_method(name, baseline, evaluation.reports[r].face);
          if (name == "lowpass") methods[name]["cutoff_hz"] = Round4(evaluation.rule_cutoff_hz);
          if (name == "lowpass_oracle") {
            methods[name]["cutoff_hz"] = evaluation.oracle_cutoff_hz;
            methods[name]["oracle"] = true;
          }
        }
        baselines_done = true;
      }
      if (&trained == &models.front()) removed_by_best[k] = std::move(removed);
    }
    if (options.platform_targets && t.take.info.platform_hz) {
      // The platform-synchronous filter itself (what F_platform_targets learns from).
      dynamics::QuasistaticOptions synchronous;
      synchronous.method = dynamics::QuasistaticMethod::kPlatformSynchronous;
      synchronous.window_s = options.window_s;
      FACEDYN_ASSIGN_OR_RETURN(const Take filtered,
                               dynamics::ExtractQuasistatic(t.take, synchronous));
      FACEDYN_ASSIGN_OR_RETURN(
          const eval::Evaluation evaluation,
          eval::Evaluate(filtered, t.take, nullptr, &rig, evaluate_options));
      add_method("platform_synchronous", filtered.positions, evaluation.reports.front().face);
    }
    entry["methods"] = methods;

    // Diagnostics of F_exact's error: what propagation alone leaves (the exact sample offsets
    // propagated to every vertex, by the rig's Laplacian and by F's learned propagation), and
    // F's error at the samples before propagation.
    {
      const dynamics::RemovalModel& model = models.front().model;
      const PointCache& exact = t.take.channels.at("dynamic_offset");
      const int sample_count = static_cast<int>(rig.skin_samples.size());
      Eigen::MatrixXf exact_samples(3,
                                    static_cast<Eigen::Index>(exact.frame_count()) * sample_count);
      for (int f = 0; f < exact.frame_count(); ++f) {
        for (int i = 0; i < sample_count; ++i) {
          exact_samples.col(static_cast<Eigen::Index>(f) * sample_count + i) =
              rig.skin_samples[i].Evaluate(exact.Frame(f)).cast<float>();
        }
      }
      auto floor_of = [&](const dynamics::SamplePropagation& used) {
        PointCache offsets, positions;
        dynamics::ComposeOffsets(t.take, used, exact_samples, -1.0f, &offsets, &positions);
        return Round4(eval::MeanDistanceOverVertices(positions, truth, mask, scored) / offset_mm);
      };
      Json diagnostics;
      diagnostics["exact_samples_laplacian_relative"] = floor_of(propagation);
      if (model.propagation() != nullptr) {
        diagnostics["exact_samples_learned_relative"] = floor_of(*model.propagation());
      }
      FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXf predicted,
                               dynamics::PredictSampleOffsets(model, t.take, rig));
      double error = 0, magnitude = 0;
      for (int f = scored.begin; f < scored.end; ++f) {
        const auto columns = Eigen::seqN(static_cast<Eigen::Index>(f) * sample_count, sample_count);
        error += (predicted(Eigen::all, columns) - exact_samples(Eigen::all, columns))
                     .colwise()
                     .norm()
                     .sum();
        magnitude += exact_samples(Eigen::all, columns).colwise().norm().sum();
      }
      diagnostics["F_exact_sample_error_relative"] = Round4(magnitude > 0 ? error / magnitude : 0);
      entry["diagnostics"] = diagnostics;
    }
    const double best = methods["F_exact_targets"]["jiggle_mean_mm"].get<double>();
    const double lowpass = methods["lowpass"]["jiggle_mean_mm"].get<double>();
    entry["F_exact_vs_lowpass"] = Round4(best > 0 ? lowpass / best : 0.0);
    entries[k] = std::move(entry);
    spdlog::info("{}: offset {:.3f} mm, F_exact {:.3f} mm, lowpass {:.3f} mm", t.name, offset_mm,
                 best, lowpass);
    return Status::Ok();
  }));
  for (Json& entry : entries) removal.push_back(std::move(entry));

  Json result;
  result["setup"] = {{"vertices", rig.vertex_count()},
                     {"samples", rig.skin_samples.size()},
                     {"fps", options.fps},
                     {"window_s", options.window_s},
                     {"seconds_per_take", options.seconds},
                     {"train_hz", options.train_hz},
                     {"test_hz", options.test_hz},
                     {"speech_hz", options.speech_hz},
                     {"expressions", options.expressions},
                     {"held_out_expressions", options.held_out_expressions},
                     {"held_out_expression_hz", options.held_out_expression_hz},
                     {"held_out_motions", options.held_out_motions},
                     {"train_amplitudes_mm", options.train_amplitudes_mm},
                     {"test_amplitude_mm", options.test_amplitude_mm},
                     {"training_takes", train.size()},
                     {"training_speech_takes", train_speech.size()},
                     {"final_learning_rate_fraction", options.final_learning_rate_fraction},
                     {"removal_epochs", options.removal_epochs},
                     {"removal_batch", options.removal_batch},
                     {"removal_hidden_units", options.removal_hidden_units},
                     {"removal_weight_decay", options.removal_weight_decay},
                     {"removal_input_noise_std", options.removal_input_noise_std},
                     {"removal_linear_skip", options.removal_linear_skip},
                     {"learning_rate", options.learning_rate},
                     {"removal_learned_propagation", options.removal_learned_propagation},
                     {"synthesis_learned_propagation", options.synthesis_learned_propagation},
                     {"propagation_prior_weight", options.propagation_prior_weight},
                     {"simulate_s", Round4(simulate_s)},
                     {"error_metric",
                      "per-vertex |prediction - exact quasistatic| in mm over frames away from "
                      "the feature window at the ends; jiggle_mean_mm over vertices whose mean "
                      "true offset is >= 20% of the largest"}};
  result["removal"] = removal;

  // Paper Fig. 5: removal error on the first test take against the number of training
  // frequencies (held expressions of the slowest k frequencies).
  if (options.frequency_subsets && options.train_hz.size() > 1) {
    const SimTake& probe = test.front();
    const dynamics::FrameRange scored = dynamics::ScoredFrames(probe.take, skip);
    const PointCache& truth = probe.take.channels.at("quasistatic");
    const std::vector<int> mask =
        eval::JigglingVertices(probe.take.channels.at("dynamic_offset"), scored);
    const double offset_mm =
        eval::MeanDistanceOverVertices(probe.take.positions, truth, mask, scored);
    Json subsets = Json::array();
    const size_t per_frequency = options.expressions.size() * options.train_amplitudes_mm.size();
    // Every bar, the full set included, is trained here with the same options and exactly the
    // same number of Adam steps (learn::MlpTrainOptions::optimizer_steps: the full set trains
    // its epochs first, each subset that many steps on its own rows), so the bars differ only
    // in their training frequencies. (Round 1 took the last bar from the main model, which also
    // trained on speech takes, so fewer frequencies and less data were confounded.)
    const size_t n = options.train_hz.size();
    const int full_epochs =
        options.subset_epochs > 0 ? options.subset_epochs : options.removal_epochs;
    std::vector<Json> bars(n);
    long budget_steps = 0;
    std::vector<size_t> order = {n};
    for (size_t k = 1; k < n; ++k) order.push_back(k);
    for (size_t k : order) {
      const std::vector<dynamics::TrainingTake> subset(held_training.begin(),
                                                       held_training.begin() + k * per_frequency);
      // The subset models propagate with the main model's learned propagation (below), so
      // they do not learn one of their own; everything else is the main model's options.
      dynamics::RemovalTrainOptions subset_options =
          RemovalOptionsFor(options, dynamics::RemovalTargets::kExact, full_epochs);
      subset_options.train.optimizer_steps = budget_steps;
      subset_options.learn_propagation = false;
      spdlog::info("training removal network on {} frequencies (paper Fig. 5)", k);
      learn::MlpTrainSummary subset_summary;
      FACEDYN_ASSIGN_OR_RETURN(const dynamics::RemovalModel model,
                               dynamics::TrainRemoval(subset, subset_options, &subset_summary));
      if (k == n) budget_steps = subset_summary.optimizer_steps;
      FACEDYN_ASSIGN_OR_RETURN(const Take removed,
                               dynamics::RemoveDynamics(model, probe.take, rig, &propagation));
      const double error_mm = eval::MeanDistanceOverVertices(removed.positions, truth, mask, scored);
      bars[k - 1] = {{"train_hz", std::vector<double>(options.train_hz.begin(),
                                                      options.train_hz.begin() + k)},
                     {"epochs", subset_summary.epochs},
                     {"training_rows", subset_summary.training_rows},
                     {"optimizer_steps", subset_summary.optimizer_steps},
                     {"jiggle_mean_mm", Round4(error_mm)},
                     {"relative_to_offset", Round4(offset_mm > 0 ? error_mm / offset_mm : 0)}};
    }
    for (Json& bar : bars) subsets.push_back(std::move(bar));
    result["removal_by_training_frequencies"] = {
        {"take", probe.name},
        {"mean_dynamic_offset_mm", Round4(offset_mm)},
        {"subsets", subsets},
        {"baselines",
         {{"lowpass", removal.front()["methods"]["lowpass"]["jiggle_mean_mm"]},
          {"moving_average", removal.front()["methods"]["moving_average"]["jiggle_mean_mm"]},
          {"no_removal", removal.front()["methods"]["no_removal"]["jiggle_mean_mm"]}}}};
  }
  Json training_json = Json::object();
  for (const Trained& trained : models) {
    training_json[trained.name] = {
        {"training_rows", trained.summary.training_rows},
        {"validation_rows", trained.summary.validation_rows},
        {"final_train_loss", trained.summary.train_loss.back()},
        {"final_validation_loss",
         trained.summary.validation_loss.empty() ? 0.0 : trained.summary.validation_loss.back()},
        {"train_s", Round4(trained.summary.train_s)},
        {"rows_per_s", std::round(trained.summary.rows_per_s)},
        {"input_size", trained.model.mlp().shape().input_size},
        {"hidden_units", trained.model.mlp().shape().hidden_units},
        {"forward_multiply_adds_per_row", trained.model.mlp().shape().ForwardMultiplyAdds()}};
  }
  result["training"] = training_json;
  if (options.joint) result["joint_training"] = joint_json;

  // --- synthesis: H trained on F's decomposition of the training takes (as in the paper),
  //     then remove-and-resynthesise the unseen test takes with their own head motion. ---
  if (options.synthesis) {
    std::vector<Take> decomposed(all_training.size());
    FACEDYN_RETURN_IF_ERROR(
        ParallelFor(static_cast<int>(all_training.size()), 0, [&](int k) -> Status {
          FACEDYN_ASSIGN_OR_RETURN(
              decomposed[k], dynamics::RemoveDynamics(models.front().model, *all_training[k].take,
                                                      rig, &propagation));
          return Status::Ok();
        }));
    std::vector<dynamics::TrainingTake> synthesis_training;
    for (const Take& take : decomposed) synthesis_training.push_back({&take, &rig});
    const dynamics::SynthesisTrainOptions synthesis_options = SynthesisOptionsFor(options);
    spdlog::info("training synthesis network ({} takes, {} epochs)", decomposed.size(),
                 synthesis_options.train.epochs);
    learn::MlpTrainSummary synthesis_summary;
    FACEDYN_ASSIGN_OR_RETURN(
        const dynamics::SynthesisModel synthesis,
        dynamics::TrainSynthesis(synthesis_training, synthesis_options, &synthesis_summary));
    Json synthesis_json = Json::array();
    for (size_t k = 0; k < test.size(); ++k) {
      const Take& original = test[k].take;
      FACEDYN_ASSIGN_OR_RETURN(
          const Take resynthesised,
          dynamics::SynthesizeDynamics(synthesis, removed_by_best[k], original.world_from_skull,
                                       original.info.motion, rig, &propagation));
      if (artifacts != nullptr && k == 0) artifacts->resynthesised = resynthesised;
      FACEDYN_ASSIGN_OR_RETURN(Json figures,
                               ResynthesisFigures(test[k].name, original, original,
                                                  removed_by_best[k], resynthesised, skip));
      const double residual_mm = figures["resynthesis_residual_mm"].get<double>();
      const double offset_mm = figures["mean_dynamic_offset_mm"].get<double>();
      synthesis_json.push_back(std::move(figures));
      spdlog::info("{}: resynthesis residual {:.3f} mm of {:.3f} mm offset", test[k].name,
                   residual_mm, offset_mm);
    }
    result["synthesis"] = {
        {"takes", synthesis_json},
        {"training_rows", synthesis_summary.training_rows},
        {"epochs", options.synthesis_epochs},
        {"batch", options.synthesis_batch},
        {"train_s", Round4(synthesis_summary.train_s)},
        {"final_validation_loss", synthesis_summary.validation_loss.empty()
                                      ? 0.0
                                      : synthesis_summary.validation_loss.back()}};
  }
  if (artifacts != nullptr) {
    artifacts->rig = rig;
    artifacts->test_take = test.front().take;
    artifacts->removed = removed_by_best.front();
    artifacts->removal_model = std::move(models.front().model);
  }
  result["total_s"] = Round4(SecondsSince(study_start));
  return result;
}

}  // namespace facedyn::eval
