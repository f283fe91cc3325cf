// dynamics_bench: the figures of issue 4, printed as JSON.
//
//   - fidelity (eval/dynamics_study.h): removal trained on platform takes at 6-10 Hz, tested on
//     11 Hz never seen and on a speech take, against the simulator's exact quasistatic, next to
//     the baselines (no removal, zero-phase low-pass, moving average); remove-then-resynthesise
//     residual (paper Fig. 7);
//   - speed: training rows/s of F converted to multiply-adds/s (forward + backward = 3x the
//     forward multiply-adds) next to the machine's own LibTorch GEMM rate measured in the same
//     run (the ratio is the figure; machines are shared and noisy), and removal + propagation
//     frames/s on a 10k-vertex take (median of 3).
//
//   dynamics_bench [--quick] [--threads N] [--epochs N] [--synthesis-epochs N] [--seconds S]
//                  [--hz 6,7,...] [--expressions a,b] [--speech-hz F] [--no-train-speech]
//                  [--lr-final F] [--window-ms MS] [--no-moving-average] [--no-platform-targets]
//                  [--laplacian-removal] [--laplacian-synthesis] [--batch N] [--lr LR]
//                  [--no-synthesis] [--propagation-prior W] [--amplitudes A1,A2,...]
//                  [--test-hz F] [--test-amplitude A] [--hidden-units N] [--weight-decay W]
//                  [--input-noise S] [--no-linear-skip] [--seed N] [--seeds 1,2,3]
//                  [--held-out-expressions a,b|none] [--held-out-expression-hz F]
//                  [--held-out-motions walk,run,jump|none] [--joint] [--joint-steps N]
//                  [--cycle-weight W] [--joint-lr LR] [--joint-early-stopping]
//
// Test takes, one protocol each ("protocol" in every removal entry): every training expression
// at --test-hz (held-out frequency, paper Fig. 5), speech at --speech-hz (held-out performance),
// --held-out-expressions at --held-out-expression-hz (default pucker at 8 Hz, a training
// frequency, so only the expression is new) and --held-out-motions (neutral walk and run in
// place; F trained on the platform only).
//
// --seed: draws every take (expression drift, motion phases) and the networks' initialisation
// from another seed, for a replicate of the whole study (default 1). --seeds 1,2,3 runs one
// study per seed and adds "replicates": each method's mean and spread per test take, and each
// F against each baseline as lower / higher / tie (a difference within the larger standard
// deviation is a tie; eval/replicates.h). "fidelity" is the first seed's study.
// --no-linear-skip: F without the linear map of its inputs (the paper's network alone).
// --amplitudes: platform amplitudes (mm) of the training takes, one take per frequency,
// expression and amplitude. --test-hz with --hz lets a setting be chosen on a frequency held
// out of the training set (e.g. --hz 6,7,8,9 --test-hz 10) without looking at the 11 Hz test.
//
// --joint: also F_joint, F and H trained together with the cycle on the training speech takes,
// which it reads without their targets (eval/dynamics_study.h DynamicsStudyOptions::joint);
// F_platform_targets is the same F without the performances. --joint-steps, --cycle-weight and
// --joint-lr set the joint phase; --joint-early-stopping keeps its report of least validation
// objective (learn::MlpPairTrainOptions::keep_least_validation).
// --no-moving-average / --no-platform-targets skip F trained on the paper's moving-average
// targets / on platform-synchronous targets (each is one more training run).
// --laplacian-removal / --laplacian-synthesis propagate that network's samples with the rig's
// Laplacian instead of the propagation learned from its training offsets (for comparison).

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "bench/bench_flags.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/progress.h"
#include "learn/mlp.h"
#include "dynamics/propagation.h"
#include "dynamics/removal_model.h"
#include "dynamics/synthesis_model.h"
#include "eval/dynamics_study.h"
#include "eval/replicates.h"
#include "sim/procedural_face.h"
#include "sim/skull_motion.h"

namespace {

using facedyn::Json;
using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}

double Number(const char* text, const std::string& flag) {
  return facedyn::bench::FlagNumber("dynamics_bench", flag, text);
}
long long Integer(const char* text, const std::string& flag) {
  return facedyn::bench::FlagInteger("dynamics_bench", flag, text);
}

std::vector<std::string> Split(const std::string& list) {
  std::vector<std::string> items;
  size_t begin = 0;
  while (begin <= list.size()) {
    const size_t end = std::min(list.find(',', begin), list.size());
    if (end > begin) items.push_back(list.substr(begin, end - begin));
    begin = end + 1;
  }
  return items;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// Removal + propagation speed on a procedural face of ~10k vertices: the head moves on the
// platform, the skin holds the neutral (speed does not depend on the skin's motion or on the
// network's weights, which are freshly initialised here).
Json RemovalSpeed(double seconds) {
  facedyn::sim::ProceduralFaceOptions face_options;
  face_options.target_vertex_count = 10000;
  const facedyn::FaceRig rig = facedyn::sim::MakeProceduralFace(face_options).value();
  facedyn::sim::MotionOptions motion;
  motion.platform_hz = 11;
  const auto skull = facedyn::sim::MakeSkullMotion(motion).value();
  const double fps = 128;
  std::vector<facedyn::Rigid3> poses;
  for (int t = 0; t < static_cast<int>(seconds * fps); ++t)
    poses.push_back(skull->WorldFromSkull(t / fps));
  const facedyn::Take take =
      facedyn::dynamics::HeldShapeTake(rig, rig.neutral.positions_mm, poses, fps);
  const auto build_start = Clock::now();
  const auto propagation = facedyn::dynamics::SamplePropagation::Build(rig).value();
  const double build_s = Seconds(build_start);
  const auto model =
      facedyn::dynamics::RemovalModel::Create(facedyn::dynamics::RemovalConfig::ForRig(rig, fps), 1)
          .value();
  std::vector<double> fps_runs, predict, propagate;
  for (int r = 0; r < 3; ++r) {
    facedyn::dynamics::RemovalSummary summary;
    const auto removed =
        facedyn::dynamics::RemoveDynamics(model, take, rig, &propagation, &summary);
    if (!removed.ok()) {
      std::fprintf(stderr, "removal failed: %s\n", removed.status().message().c_str());
      std::exit(1);
    }
    fps_runs.push_back(summary.frames_per_s);
    predict.push_back(summary.predict_s);
    propagate.push_back(summary.propagate_s);
  }
  return {
      {"vertices", rig.vertex_count()},      {"samples", rig.skin_samples.size()},
      {"frames", take.frame_count()},        {"frames_per_s_median", std::round(Median(fps_runs))},
      {"predict_s_median", Median(predict)}, {"propagate_s_median", Median(propagate)},
      {"propagation_build_s", build_s},      {"target_frames_per_s", 200}};
}

}  // namespace

int main(int argc, char** argv) {
  facedyn::eval::DynamicsStudyOptions options;
  // F's batch: 2,000 rather than the paper's 10,000 (the CLI default). With 40 epochs over
  // ~1.5M rows, 10,000 gives only ~5,800 Adam steps and leaves F under-trained (validation loss
  // 0.0010 against 0.0007 at 2,000, the same epochs); --batch 10000 reproduces the paper's.
  options.removal_batch = 2000;
  // Three platform amplitudes per training frequency and expression (the test takes stay at
  // 2 mm), first chosen on 10 Hz held out of 6-9 Hz under round 1's protocol, and re-checked on
  // eval/'s protocol on a validation study that shares no take with a test take (--hz 6,8
  // --test-hz 10 --speech-hz 8 --seeds 101,102,103, README "Evaluation protocol"): at the same
  // number of Adam steps (10 epochs on three amplitudes, 30 on one) F_exact's error was lower
  // with three on every validation take. 13 epochs over the three times as many rows keep the
  // Adam steps of 40 epochs on one amplitude; --amplitudes 2 --epochs 40 is the one-amplitude
  // study. The full configuration has not been re-run on the new protocol.
  options.train_amplitudes_mm = {1.5, 2.0, 2.5};
  options.removal_epochs = 13;
  bool amplitudes_given = false;
  bool epochs_given = false;
  std::vector<uint64_t> seeds;  // --seeds: one whole study per seed, summarised
  bool quick = false;
  int threads = 0;
  for (int k = 1; k < argc; ++k) {
    const std::string arg = argv[k];
    auto next = [&]() -> const char* {
      if (k + 1 >= argc) {
        std::fprintf(stderr, "dynamics_bench: %s needs a value\n", arg.c_str());
        std::exit(2);
      }
      return argv[++k];
    };
    if (arg == "--quick") {
      quick = true;
    } else if (arg == "--threads") {
      threads = static_cast<int>(Integer(next(), arg));
    } else if (arg == "--epochs") {
      options.removal_epochs = static_cast<int>(Integer(next(), arg));
      epochs_given = true;
    } else if (arg == "--hz") {
      options.train_hz.clear();
      for (const std::string& item : Split(next()))
        options.train_hz.push_back(Number(item.c_str(), arg));
    } else if (arg == "--expressions") {
      options.expressions = Split(next());
    } else if (arg == "--speech-hz") {
      options.speech_hz = Number(next(), arg);
    } else if (arg == "--held-out-expressions") {
      const std::string list = next();
      options.held_out_expressions = list == "none" ? std::vector<std::string>() : Split(list);
    } else if (arg == "--held-out-expression-hz") {
      options.held_out_expression_hz = Number(next(), arg);
    } else if (arg == "--held-out-motions") {
      const std::string list = next();
      options.held_out_motions = list == "none" ? std::vector<std::string>() : Split(list);
    } else if (arg == "--no-train-speech") {
      options.train_speech = false;
    } else if (arg == "--window-ms") {
      options.window_s = Number(next(), arg) * 1e-3;
    } else if (arg == "--lr-final") {
      options.final_learning_rate_fraction = Number(next(), arg);
    } else if (arg == "--synthesis-epochs") {
      options.synthesis_epochs = static_cast<int>(Integer(next(), arg));
    } else if (arg == "--no-moving-average") {
      options.moving_average_targets = false;
    } else if (arg == "--no-platform-targets") {
      options.platform_targets = false;
    } else if (arg == "--batch") {
      options.removal_batch = static_cast<int>(Integer(next(), arg));
    } else if (arg == "--lr") {
      options.learning_rate = Number(next(), arg);
    } else if (arg == "--propagation-prior") {
      options.propagation_prior_weight = Number(next(), arg);
    } else if (arg == "--no-synthesis") {
      options.synthesis = false;
    } else if (arg == "--laplacian-removal") {
      options.removal_learned_propagation = false;
    } else if (arg == "--laplacian-synthesis") {
      options.synthesis_learned_propagation = false;
    } else if (arg == "--amplitudes") {
      options.train_amplitudes_mm.clear();
      amplitudes_given = true;
      for (const std::string& item : Split(next()))
        options.train_amplitudes_mm.push_back(Number(item.c_str(), arg));
    } else if (arg == "--test-hz") {
      options.test_hz = Number(next(), arg);
    } else if (arg == "--test-amplitude") {
      options.test_amplitude_mm = Number(next(), arg);
    } else if (arg == "--hidden-units") {
      options.removal_hidden_units = static_cast<int>(Integer(next(), arg));
    } else if (arg == "--weight-decay") {
      options.removal_weight_decay = Number(next(), arg);
    } else if (arg == "--input-noise") {
      options.removal_input_noise_std = Number(next(), arg);
    } else if (arg == "--seed") {
      options.seed = static_cast<uint64_t>(Integer(next(), arg));
    } else if (arg == "--seeds") {
      for (const std::string& item : Split(next()))
        seeds.push_back(static_cast<uint64_t>(Integer(item.c_str(), arg)));
    } else if (arg == "--no-linear-skip") {
      options.removal_linear_skip = false;
    } else if (arg == "--seconds") {
      options.seconds = Number(next(), arg);
    } else if (arg == "--joint") {
      options.joint = true;
    } else if (arg == "--joint-steps") {
      options.joint_steps = Integer(next(), arg);
    } else if (arg == "--cycle-weight") {
      options.joint_cycle_weight = Number(next(), arg);
    } else if (arg == "--joint-lr") {
      options.joint_learning_rate = Number(next(), arg);
    } else if (arg == "--joint-early-stopping") {
      options.joint_keep_least_validation = true;
    } else {
      std::fprintf(
          stderr,
          "usage: dynamics_bench [--quick] [--threads N] [--epochs N] [--synthesis-epochs "
          "N] [--seconds S] [--hz 6,7,...] [--expressions a,b] [--speech-hz F] "
          "[--no-train-speech] [--lr-final F] [--window-ms MS] [--no-moving-average] "
          "[--no-platform-targets] [--laplacian-removal] [--laplacian-synthesis] [--batch N] "
          "[--lr LR] [--no-synthesis] [--propagation-prior W] [--amplitudes A1,A2,...] "
          "[--test-hz F] [--test-amplitude A] [--hidden-units N] [--weight-decay W] "
          "[--input-noise S] [--no-linear-skip] [--seed N] [--seeds 1,2,3] "
          "[--held-out-expressions a,b|none] [--held-out-expression-hz F] "
          "[--held-out-motions walk,run,jump|none] [--joint] [--joint-steps N] "
          "[--cycle-weight W] [--joint-lr LR] [--joint-early-stopping]\n");
      return 2;
    }
  }
  facedyn::InitLogging(facedyn::Verbosity::kNormal);
  if (quick) {
    options.train_hz = {7, 9};
    options.expressions = {"neutral", "smile"};
    options.seconds = 1.5;
    // The validated settings (above): three amplitudes and 20 epochs. On the validation study,
    // 20 epochs tied 10 on the held takes and lowered the speech take's error (0.0168 +- 0.0022
    // -> 0.0136 +- 0.0019 mm); round 1's quick study used one amplitude and 10 epochs.
    if (!amplitudes_given) options.train_amplitudes_mm = {1.5, 2.0, 2.5};
    if (!epochs_given) options.removal_epochs = 20;
    options.synthesis_epochs = 10;
  }
  options.threads = threads;
  if (seeds.empty()) seeds.push_back(options.seed);
  std::vector<Json> studies;
  for (uint64_t seed : seeds) {
    options.seed = seed;
    if (seeds.size() > 1) {
      std::fprintf(stderr, "dynamics_bench: replicate %zu of %zu (seed %llu)\n",
                   studies.size() + 1, seeds.size(), static_cast<unsigned long long>(seed));
    }
    auto result = facedyn::eval::RunDynamicsStudy(options);
    if (!result.ok()) {
      std::fprintf(stderr, "dynamics_bench: %s\n", result.status().message().c_str());
      return 1;
    }
    studies.push_back(std::move(result).value());
  }
  const Json* study = &studies.front();
  Json out;
  out["fidelity"] = *study;
  if (studies.size() > 1) {
    out["replicates"] = facedyn::eval::SummariseRemovalReplicates(studies);
    out["replicates"]["seeds"] = seeds;
  }

  // Speed: F's training throughput against the GEMM rate, measured now, side by side.
  const Json& training = (*study)["training"]["F_exact_targets"];
  const double rows_per_s = training["rows_per_s"].get<double>();
  const double train_macs =
      rows_per_s * 3.0 * training["forward_multiply_adds_per_row"].get<double>();
  const double gemm_square =
      facedyn::learn::MeasureGemmMultiplyAddsPerSecond(1024, 1024, 1024, 2.0);
  const double gemm_layer = facedyn::learn::MeasureGemmMultiplyAddsPerSecond(
      options.removal_batch, training["input_size"].get<int>(), training["hidden_units"].get<int>(),
      2.0);
  out["speed"] = {{"training_rows_per_s", rows_per_s},
                  {"training_multiply_adds_per_s", train_macs},
                  {"gemm_1024_multiply_adds_per_s", gemm_square},
                  {"gemm_first_layer_shape_multiply_adds_per_s", gemm_layer},
                  {"training_over_gemm_1024", train_macs / gemm_square},
                  {"training_over_gemm_first_layer", train_macs / gemm_layer},
                  {"target_ratio", 0.5},
                  {"removal", RemovalSpeed(quick ? 1.0 : 2.0)}};
  std::printf("%s\n", out.dump(2).c_str());
  return 0;
}
