// `facedyn dynamics quasistatic` and `facedyn dynamics eval`.

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>

#include "app/command.h"
#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/take.h"
#include "dynamics/quasistatic.h"
#include "eval/metrics.h"

namespace facedyn::app {

void AddDynamicsCommands(CLI::App& app, CommandRunner* selected) {
  auto* dynamics = app.add_subcommand(
      "dynamics",
      "Secondary dynamics (Zoss et al. 2020): quasistatic extraction, removal and synthesis "
      "networks, retargeting, evaluation");
  dynamics->require_subcommand(1);

  struct QuasistaticCommandOptions {
    std::string take_dir;
    std::string out_dir;
    double window_ms = 80.0;
    std::string method = "moving-average";
    double platform_hz = 0.0;
    int trend_degree = 0;
    double min_periods = 1.5;
  };
  auto quasistatic_options = std::make_shared<QuasistaticCommandOptions>();
  auto* quasistatic = dynamics->add_subcommand(
      "quasistatic",
      "Quasistatic estimate of a held-expression take (moving average, Eq. 5, or the "
      "platform-synchronous fit) plus its dynamic offsets (Eq. 6) as channel dynamic_offset");
  quasistatic->add_option("--take", quasistatic_options->take_dir, "Input take folder")->required();
  quasistatic->add_option("--out", quasistatic_options->out_dir, "Output take folder")->required();
  quasistatic->add_option("--window-ms", quasistatic_options->window_ms,
                          "Half-window in milliseconds (frames = round(ms * fps / 1000))")
      ->capture_default_str();
  quasistatic
      ->add_option("--method", quasistatic_options->method,
                   "moving-average (the paper's Eq. 5) or platform-synchronous (least-squares "
                   "fit at the platform frequency; exact for a steady sinusoid) or held-mean "
                   "(the held part's mean shape in the skull frame; held expressions only, any "
                   "head motion)")
      ->check(CLI::IsMember({"moving-average", "platform-synchronous", "held-mean"}))
      ->capture_default_str();
  quasistatic->add_option("--platform-hz", quasistatic_options->platform_hz,
                          "Platform frequency for platform-synchronous (default: the take's own "
                          "platform_hz)");
  quasistatic
      ->add_option("--trend-degree", quasistatic_options->trend_degree,
                   "platform-synchronous: degree of the polynomial fitted with the sinusoids "
                   "(0: a constant; 2 follows an expression that changes, e.g. speech)")
      ->capture_default_str();
  quasistatic
      ->add_option("--min-periods", quasistatic_options->min_periods,
                   "platform-synchronous: shortest window in platform periods (2 with a trend)")
      ->capture_default_str();
  quasistatic->callback([quasistatic_options, selected] {
    *selected = [quasistatic_options]() -> Status {
      dynamics::QuasistaticOptions options;
      options.window_s = quasistatic_options->window_ms * 1e-3;
      if (!options.Check().ok()) {
        return InvalidArgumentError("--window-ms must be in [0, 1000], got " +
                                    std::to_string(quasistatic_options->window_ms));
      }
      if (quasistatic_options->method == "platform-synchronous") {
        options.method = dynamics::QuasistaticMethod::kPlatformSynchronous;
      } else if (quasistatic_options->method == "held-mean") {
        options.method = dynamics::QuasistaticMethod::kHeldMean;
      }
      options.trend_degree = quasistatic_options->trend_degree;
      options.min_periods = quasistatic_options->min_periods;
      if (options.trend_degree < 0 || options.trend_degree > 4) {
        return InvalidArgumentError("--trend-degree must be in 0..4, got " +
                                    std::to_string(options.trend_degree));
      }
      if (!(options.min_periods >= 1 && options.min_periods <= 10)) {
        return InvalidArgumentError("--min-periods must be in [1, 10], got " +
                                    std::to_string(options.min_periods));
      }
      if (quasistatic_options->platform_hz != 0.0) {
        if (!(quasistatic_options->platform_hz > 0)) {
          return InvalidArgumentError("--platform-hz must be > 0, got " +
                                      std::to_string(quasistatic_options->platform_hz));
        }
        options.platform_hz = quasistatic_options->platform_hz;
      }
      FACEDYN_ASSIGN_OR_RETURN(const Take take, LoadTake(quasistatic_options->take_dir));
      FACEDYN_ASSIGN_OR_RETURN(const Take result, dynamics::ExtractQuasistatic(take, options));
      FACEDYN_RETURN_IF_ERROR(SaveTake(result, quasistatic_options->out_dir));
      spdlog::info("wrote quasistatic take ({} frames, window {} frames) to {}",
                   result.frame_count(),
                   result.info.metadata["quasistatic_window_frames"].get<int>(),
                   quasistatic_options->out_dir);
      return Status::Ok();
    };
  });

  struct EvalCommandOptions {
    std::string pred_dir;
    std::string truth_dir;
    std::string input_dir;
    std::string face_dir;
    std::string channel = "quasistatic";
    int skip_frames = -1;
    double window_ms = 80.0;
    double lowpass_hz = 0.0;  // 0: the rule (dynamics/baselines.h LowPassCutoffByRule)
    bool json = false;
  };
  auto eval_options = std::make_shared<EvalCommandOptions>();
  auto* eval = dynamics->add_subcommand(
      "eval",
      "Per-vertex error (mm) of a predicted take against a truth take: mean, p95 and max over "
      "the face and per region, with the no-removal, low-pass and moving-average baselines");
  eval->add_option("--pred", eval_options->pred_dir, "Predicted take (the dynamic input itself "
                                                     "is the no-removal baseline)")
      ->required();
  eval->add_option("--truth", eval_options->truth_dir, "Truth take")->required();
  eval->add_option("--channel", eval_options->channel,
                   "Truth channel, or \"positions\" for the truth take's positions")
      ->capture_default_str();
  eval->add_option("--input", eval_options->input_dir,
                   "Dynamic input take: also report the baselines computed from it");
  eval->add_option("--face", eval_options->face_dir, "FaceRig folder: also report per region");
  eval->add_option("--skip-frames", eval_options->skip_frames,
                   "Frames left out at each end (default: the window, round(window * fps))");
  eval->add_option("--window-ms", eval_options->window_ms,
                   "Moving-average baseline half-window and default skip, milliseconds")
      ->capture_default_str();
  eval->add_option("--lowpass-hz", eval_options->lowpass_hz,
                   "Low-pass baseline cutoff, Hz (0: a third of the head motion's dominant "
                   "frequency, the recorded platform_hz when there is one)")
      ->capture_default_str();
  eval->add_flag("--json", eval_options->json, "Print JSON on stdout");
  eval->callback([eval_options, selected] {
    *selected = [eval_options]() -> Status {
      eval::EvaluateOptions options;
      options.truth_channel = eval_options->channel;
      options.skip_edge_frames = eval_options->skip_frames;
      options.window_s = eval_options->window_ms * 1e-3;
      options.baselines.lowpass_cutoff_hz = eval_options->lowpass_hz;
      options.baselines.window_s = options.window_s;
      FACEDYN_RETURN_IF_ERROR(options.Check());
      FACEDYN_ASSIGN_OR_RETURN(const Take predicted, LoadTake(eval_options->pred_dir));
      FACEDYN_ASSIGN_OR_RETURN(const Take truth, LoadTake(eval_options->truth_dir));
      std::optional<Take> input;
      if (!eval_options->input_dir.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(input, LoadTake(eval_options->input_dir));
      }
      std::optional<FaceRig> rig;
      if (!eval_options->face_dir.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(rig, LoadFaceRig(eval_options->face_dir));
      }
      FACEDYN_ASSIGN_OR_RETURN(
          const eval::Evaluation evaluation,
          eval::Evaluate(predicted, truth, input ? &*input : nullptr, rig ? &*rig : nullptr,
                             options));
      if (eval_options->json) {
        std::printf("%s\n", eval::EvaluationToJson(evaluation)
                                .dump(2, ' ', false, kJsonReplaceInvalidUtf8)
                                .c_str());
      } else {
        std::printf("%s", eval::EvaluationToText(evaluation).c_str());
      }
      return Status::Ok();
    };
  });
  AddDynamicsNetworkCommands(dynamics, selected);
}

}  // namespace facedyn::app
