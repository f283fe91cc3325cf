// retarget_bench: why subject B's synthesis network H_B loses to naive transfer of A's offsets
// when A's walk is retargeted to B (issue 20, paper Figs. 9-10), printed as JSON.
//
// Per seed: subject A is the procedural face, subject B the demo's second subject (the face
// scaled 0.92 x 1.06 x 0.96, tissue 8.5 Hz with damping 0.17 against A's 11 Hz and 0.22;
// app/demo_dynamics.h). B's training takes are simulated (neutral on the platform at --b-hz,
// neutral walks in place at --walk-hz); A walks a new walk (--test-walk-hz, its own seed) and B
// is simulated under the same head motion for the truth. No take is filmed: this isolates the
// synthesis from reconstruction error.
//
// H_B is trained on B's takes decomposed in each of these ways:
//   "exact"      the simulator's own quasistatic and offsets (a ceiling only: no capture has it);
//   "targets"    the truth-free targets F is trained on: the platform-synchronous fit on
//                platform takes, the moving average (Eq. 5) on the walks;
//   "targets_lp" as "targets", but the walks decomposed by the zero-phase low-pass with its
//                cutoff by rule (dynamics/baselines.h);
//   "F_B"        F_B's removal, F_B trained on "targets" (the demo's pipeline);
// and, for each, with skull-descriptor half-windows --windows (s). The retargeting is scored by
// eval::ScoreRetargeting against B simulated walking, next to naive transfer of A's exact
// offsets and no dynamics. B's quasistatic for the retargeting is the mean shape of the
// decomposition's first (platform) take. Truth enters only "exact" and the scoring.
//
//   retarget_bench [--seeds 1,2,3] [--b-hz 9] [--walk-hz 1.5] [--test-walk-hz 1.9]
//                  [--seconds 1.25] [--walk-seconds 1.5] [--epochs 30] [--f-epochs 8]
//                  [--windows 0.08] [--linear-skip 0[,1]] [--variants exact,targets,targets_lp,F_B]
//                  [--ridge-sweep]
//
// Beside each H_B, the modal synthesis (dynamics/modal_synthesis.h) trained on the same
// decomposition ("modal <variant>"); variant "held_mean" decomposes each take by its held mean
// (quasistatic.h), the demo's choice for it. --ridge-sweep also prints, per ridge of the grid,
// the validation errors and the test error of a model fitted with that ridge alone: a
// diagnostic of the validation rule, never used to choose.

#include <fmt/format.h>

#include <cstdio>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "bench/bench_flags.h"
#include "core/json_io.h"
#include "core/log.h"
#include "dynamics/baselines.h"
#include "dynamics/modal_synthesis.h"
#include "dynamics/quasistatic.h"
#include "dynamics/removal_model.h"
#include "dynamics/synthesis_model.h"
#include "dynamics/training_frames.h"
#include "eval/metrics.h"
#include "eval/replicates.h"
#include "eval/synthesis_scoring.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"

namespace {

using facedyn::Json;
using facedyn::StatusOr;
using facedyn::Take;
namespace dyn = facedyn::dynamics;
namespace sim = facedyn::sim;
namespace physics = facedyn::physics;

constexpr char kProgram[] = "retarget_bench";

std::vector<double> NumberList(const std::string& flag, const std::string& text) {
  std::vector<double> out;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) {
    out.push_back(facedyn::bench::FlagNumber(kProgram, flag, item.c_str()));
  }
  if (out.empty()) {
    std::fprintf(stderr, "%s: %s: empty list\n", kProgram, flag.c_str());
    std::exit(2);
  }
  return out;
}

std::vector<std::string> NameList(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) out.push_back(item);
  return out;
}

template <typename T>
T OrDie(StatusOr<T> value, const std::string& what) {
  if (!value.ok()) {
    std::fprintf(stderr, "%s: %s: %s\n", kProgram, what.c_str(), value.status().message().c_str());
    std::exit(1);
  }
  return std::move(value).value();
}

sim::MotionOptions Platform(double hz, uint64_t seed) {
  sim::MotionOptions motion;
  motion.kind = sim::MotionKind::kPlatform;
  motion.platform_hz = hz;
  motion.seed = seed;
  return motion;
}

// In place: forward speed changes nothing for the tissue, but B(t) holds velocities.
sim::MotionOptions Walk(double step_hz, uint64_t seed) {
  sim::MotionOptions motion;
  motion.kind = sim::MotionKind::kWalk;
  motion.walk_step_hz = step_hz;
  motion.walk_speed_mm_per_s = 0;
  motion.seed = seed;
  return motion;
}

Take Simulate(const facedyn::FaceRig& face, const sim::MotionOptions& motion, double seconds,
              const physics::TissueOptions& tissue, uint64_t seed, const std::string& what) {
  sim::PerformanceOptions perform;
  perform.expression = "neutral";
  perform.motion = motion;
  perform.seconds = seconds;
  perform.seed = seed;
  perform.tissue = tissue;
  return OrDie(sim::SimulatePerformance(face, perform), "simulating " + what);
}

// The truth-free decomposition of one training take: the platform-synchronous fit where the
// take records its platform frequency, otherwise the moving average or the low-pass by rule.
Take TargetDecomposition(const Take& take, bool low_pass_walks) {
  dyn::QuasistaticOptions options;
  if (take.info.platform_hz > 0) {
    options.method = dyn::QuasistaticMethod::kPlatformSynchronous;
    return OrDie(dyn::ExtractQuasistatic(take, options), "platform-synchronous fit");
  }
  if (!low_pass_walks) return OrDie(dyn::ExtractQuasistatic(take, options), "moving average");
  Take out = take;
  out.channels.clear();
  out.positions =
      OrDie(dyn::LowPassBaseline(take, dyn::LowPassCutoffByRule(take)), "low-pass baseline");
  out.channels["dynamic_offset"] =
      OrDie(dyn::DynamicOffsets(take.positions, out.positions, take.world_from_skull), "offsets");
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace facedyn;
  std::vector<double> seeds = {1, 2, 3}, b_hz = {9}, walk_hz = {1.5}, windows = {0.08};
  double test_walk_hz = 1.9, seconds = 1.25, walk_seconds = 1.5;
  int epochs = 30, f_epochs = 8;
  std::vector<double> linear_skips = {0};
  bool ridge_sweep = false;
  std::vector<std::string> variant_names = {"exact", "targets", "targets_lp", "F_B"};
  for (int k = 1; k < argc; ++k) {
    const std::string arg = argv[k];
    auto next = [&]() -> const char* {
      if (k + 1 >= argc) {
        std::fprintf(stderr, "%s: %s needs a value\n", kProgram, arg.c_str());
        std::exit(2);
      }
      return argv[++k];
    };
    if (arg == "--seeds") {
      seeds = NumberList(arg, next());
    } else if (arg == "--b-hz") {
      b_hz = NumberList(arg, next());
    } else if (arg == "--walk-hz") {
      walk_hz = NumberList(arg, next());
    } else if (arg == "--test-walk-hz") {
      test_walk_hz = bench::FlagNumber(kProgram, arg, next());
    } else if (arg == "--seconds") {
      seconds = bench::FlagNumber(kProgram, arg, next());
    } else if (arg == "--walk-seconds") {
      walk_seconds = bench::FlagNumber(kProgram, arg, next());
    } else if (arg == "--epochs") {
      epochs = static_cast<int>(bench::FlagInteger(kProgram, arg, next()));
    } else if (arg == "--f-epochs") {
      f_epochs = static_cast<int>(bench::FlagInteger(kProgram, arg, next()));
    } else if (arg == "--windows") {
      windows = NumberList(arg, next());
    } else if (arg == "--ridge-sweep") {
      ridge_sweep = true;
    } else if (arg == "--linear-skip") {
      linear_skips = NumberList(arg, next());
    } else if (arg == "--variants") {
      variant_names = NameList(next());
    } else {
      std::fprintf(stderr,
                   "usage: %s [--seeds 1,2,3] [--b-hz 9] [--walk-hz 1.5] [--test-walk-hz 1.9] "
                   "[--seconds 1.25] [--walk-seconds 1.5] [--epochs 30] [--f-epochs 8] "
                   "[--windows 0.08] [--linear-skip 0[,1]] [--variants "
                   "exact,targets,targets_lp,F_B,held_mean] [--ridge-sweep]\n",
                   kProgram);
      return 2;
    }
  }
  for (const std::string& name : variant_names) {
    if (name != "exact" && name != "targets" && name != "targets_lp" && name != "F_B" &&
        name != "held_mean") {
      std::fprintf(stderr, "%s: --variants: unknown '%s' (exact, targets, targets_lp, F_B)\n",
                   kProgram, name.c_str());
      return 2;
    }
  }
  if (!(seconds >= 1) || !(walk_seconds >= 1) || epochs < 1 || f_epochs < 1 ||
      !(test_walk_hz > 0)) {
    std::fprintf(stderr,
                 "%s: need --seconds, --walk-seconds >= 1, epochs >= 1, "
                 "--test-walk-hz > 0\n",
                 kProgram);
    return 2;
  }
  InitLogging(Verbosity::kQuiet);
  const FaceRig face_a = OrDie(sim::MakeProceduralFace(sim::ProceduralFaceOptions()), "face A");
  const FaceRig face_b = OrDie(
      sim::ScaledFaceRig(face_a, Eigen::Vector3d(0.92, 1.06, 0.96), face_a.name + "-b"), "face B");
  const physics::TissueOptions tissue_a;
  physics::TissueOptions tissue_b;
  tissue_b.fundamental_hz = 8.5;
  tissue_b.damping_ratio = 0.17;

  // per "variant window" key: the H_B figures per seed; per method key the baselines.
  std::map<std::string, std::vector<double>> figures;
  Json per_seed = Json::array();
  for (double seed_value : seeds) {
    const uint64_t seed = static_cast<uint64_t>(seed_value);
    std::fprintf(stderr, "%s: seed %llu: simulating\n", kProgram,
                 static_cast<unsigned long long>(seed));
    uint64_t take_seed = 1000 * seed;
    std::vector<Take> b_takes;
    for (double hz : b_hz) {
      ++take_seed;
      b_takes.push_back(Simulate(face_b, Platform(hz, take_seed), seconds, tissue_b, take_seed,
                                 fmt::format("B platform {:g} Hz", hz)));
    }
    for (double hz : walk_hz) {
      ++take_seed;
      b_takes.push_back(Simulate(face_b, Walk(hz, take_seed), walk_seconds, tissue_b, take_seed,
                                 fmt::format("B walk {:g}", hz)));
    }
    const sim::MotionOptions test_walk = Walk(test_walk_hz, 500 * seed + 7);
    const Take a_walk = Simulate(face_a, test_walk, walk_seconds, tissue_a, seed + 50, "A walk");
    const Take b_walk = Simulate(face_b, test_walk, walk_seconds, tissue_b, seed + 50, "B walk");
    const int skip = dyn::WindowFrames(0.08, a_walk.info.fps);

    Json seed_json = {{"seed", seed}};
    for (const std::string& variant : variant_names) {
      std::vector<Take> decomposed;
      if (variant == "exact") {
        for (const Take& take : b_takes) {
          decomposed.push_back(OrDie(dyn::DecomposeExact(take), "exact decomposition"));
        }
      } else if (variant == "held_mean") {
        dyn::QuasistaticOptions options;
        options.method = dyn::QuasistaticMethod::kHeldMean;
        for (const Take& take : b_takes) {
          decomposed.push_back(OrDie(dyn::ExtractQuasistatic(take, options), "held mean"));
        }
      } else if (variant == "targets" || variant == "targets_lp") {
        for (const Take& take : b_takes) {
          decomposed.push_back(TargetDecomposition(take, variant == "targets_lp"));
        }
      } else {
        std::vector<dyn::TrainingTake> training;
        for (const Take& take : b_takes) training.push_back({&take, &face_b});
        dyn::RemovalTrainOptions options;
        options.targets = dyn::RemovalTargets::kPlatformSynchronousWhereKnown;
        options.train.epochs = f_epochs;
        options.train.batch_size = 2000;
        options.train.seed = seed;
        options.train.final_learning_rate_fraction = 0.05;
        options.train.show_progress = false;
        const dyn::RemovalModel f_b = OrDie(dyn::TrainRemoval(training, options), "F_B");
        for (const Take& take : b_takes) {
          decomposed.push_back(OrDie(dyn::RemoveDynamics(f_b, take, face_b), "F_B removal"));
        }
      }
      const Take b_quasistatic =
          dyn::HeldShapeTake(face_b, dyn::MeanShapeInSkull(decomposed.front(), skip),
                             a_walk.world_from_skull, a_walk.info.fps);
      {
        std::vector<dyn::TrainingTake> training;
        for (const Take& take : decomposed) training.push_back({&take, &face_b});
        dyn::ModalSynthesisOptions options;
        options.seed = seed;
        dyn::ModalSynthesisFit fit;
        const dyn::ModalSynthesisModel modal =
            OrDie(dyn::ModalSynthesisModel::Train(training, options, &fit), "modal synthesis");
        const Take synthesised = OrDie(
            modal.Synthesize(b_quasistatic, a_walk.world_from_skull, "walk", face_b), "modal");
        const std::vector<int> jiggle = eval::JigglingVertices(b_walk.channels.at("dynamic_offset"),
                                                               dyn::ScoredFrames(b_walk, skip));
        const Json errors =
            OrDie(eval::SynthesisErrors(synthesised, b_walk, jiggle, skip), "score");
        if (ridge_sweep) {
          for (size_t r = 0; r < options.ridge.size(); ++r) {
            dyn::ModalSynthesisOptions fixed = options;
            fixed.ridge = {options.ridge[r]};
            const dyn::ModalSynthesisModel m =
                OrDie(dyn::ModalSynthesisModel::Train(training, fixed), "modal");
            const Take one =
                OrDie(m.Synthesize(b_quasistatic, a_walk.world_from_skull, "walk", face_b), "m");
            std::fprintf(
                stderr, "  ridge %g: validation %.4f relative %.4f, test %.4f mm\n",
                options.ridge[r], fit.validation_rms_mm[r], fit.validation_relative[r],
                OrDie(eval::SynthesisErrors(one, b_walk, jiggle, skip), "s")["offset_mean_mm"]
                    .get<double>());
          }
        }
        const std::string key = fmt::format("modal {}", variant);
        const double mm = errors["offset_mean_mm"].get<double>();
        figures[key].push_back(mm);
        seed_json[key] = mm;
        seed_json[key + " ridge"] = fit.chosen_ridge;
        std::fprintf(stderr, "%s: seed %llu: %s: %.4f mm (ridge %g)\n", kProgram,
                     static_cast<unsigned long long>(seed), key.c_str(), mm, fit.chosen_ridge);
      }
      for (double window_s : windows)
        for (double linear_skip : linear_skips) {
          std::vector<dyn::TrainingTake> training;
          for (const Take& take : decomposed) training.push_back({&take, &face_b});
          dyn::SynthesisTrainOptions options;
          options.train.epochs = epochs;
          options.train.seed = seed;
          options.train.final_learning_rate_fraction = 0.05;
          options.train.show_progress = false;
          options.window_s = window_s;
          options.linear_skip = linear_skip != 0;
          const dyn::SynthesisModel h_b = OrDie(dyn::TrainSynthesis(training, options), "H_B");
          const eval::RetargetingResult result = OrDie(
              eval::ScoreRetargeting(h_b, a_walk, face_a, b_walk, face_b, b_quasistatic, skip),
              "scoring");
          const Json& methods = result.figures["methods"];
          const std::string key = fmt::format("H_B {} window {:g} s{}", variant, window_s,
                                              linear_skip != 0 ? " linear skip" : "");
          const double h_mm = methods["H_B_retarget"]["offset_mean_mm"].get<double>();
          figures[key].push_back(h_mm);
          seed_json[key] = h_mm;
          if (variant == variant_names.front() && window_s == windows.front() &&
              linear_skip == linear_skips.front()) {
            const double naive = methods["naive_delta_transfer"]["offset_mean_mm"].get<double>();
            const double none = methods["no_dynamics"]["offset_mean_mm"].get<double>();
            figures["naive transfer of A's exact offsets"].push_back(naive);
            figures["no dynamics (mean true offset)"].push_back(none);
            seed_json["naive"] = naive;
            seed_json["no_dynamics"] = none;
          }
          std::fprintf(stderr, "%s: seed %llu: %s: %.4f mm\n", kProgram,
                       static_cast<unsigned long long>(seed), key.c_str(), h_mm);
        }
    }
    per_seed.push_back(seed_json);
  }
  Json summary = Json::object();
  for (const auto& [key, values] : figures) {
    const eval::Spread spread = eval::SpreadOf(values);
    summary[key] = {{"mean_mm", spread.mean}, {"sd_mm", spread.sd}, {"per_seed_mm", values}};
  }
  const Json out = {{"protocol",
                     "A's new walk retargeted to subject B; offset error over B's jiggling "
                     "vertices against B simulated walking, mm"},
                    {"b_platform_hz", b_hz},
                    {"b_walk_step_hz", walk_hz},
                    {"test_walk_step_hz", test_walk_hz},
                    {"seconds", seconds},
                    {"walk_seconds", walk_seconds},
                    {"epochs", epochs},
                    {"f_epochs", f_epochs},
                    {"methods", summary},
                    {"per_seed", per_seed}};
  std::printf("%s\n", out.dump(2).c_str());
  return 0;
}
