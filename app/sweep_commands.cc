// `facedyn sweep --config SWEEP.yaml --session DIR [--resume]`: a scripted frequency sweep on
// the platform (rig/sweep.h), journalled in DIR/rig_log.jsonl.

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <memory>
#include <string>

#include "app/command.h"
#include "core/json_io.h"
#include "rig/rig_config.h"
#include "rig/stop_signal.h"
#include "rig/sweep.h"

namespace facedyn::app {

void AddSweepCommand(CLI::App& app, CommandRunner* selected) {
  struct Options {
    std::string config;
    std::string rig;
    std::string session;
    bool resume = false;
    bool json = false;
    bool check = false;
  };
  auto options = std::make_shared<Options>();
  auto* command = app.add_subcommand(
      "sweep",
      "Run a scripted frequency sweep (steps of frequency, settle, hold, prompt); "
      "--resume continues an interrupted session from its log");
  command->add_option("--config", options->config, "Sweep script YAML (config/sweeps/*.yaml)")
      ->required();
  command->add_option("--session", options->session,
                      "Session folder (holds rig_log.jsonl, sweep_summary.json)");
  command->add_option("--rig", options->rig, "Rig config YAML (default: the script's rig: field)");
  command->add_flag("--resume", options->resume,
                    "Continue the session in --session, skipping completed steps");
  command->add_flag("--check", options->check,
                    "Only validate the script against the rig and print the plan");
  command->add_flag("--json", options->json, "Print the result as JSON");
  command->callback([options, selected] {
    if (options->session.empty() && !options->check) throw CLI::RequiredError("--session");
    *selected = [options]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(const rig::SweepScript script,
                               rig::LoadSweepScript(options->config));
      const std::string rig_path = options->rig.empty() ? script.rig_path : options->rig;
      if (rig_path.empty()) {
        return InvalidArgumentError(
            fmt::format("{}: no rig: field; pass --rig RIG.yaml", options->config));
      }
      FACEDYN_ASSIGN_OR_RETURN(const rig::RigConfig rig, rig::LoadRigConfig(rig_path));
      FACEDYN_RETURN_IF_ERROR(script.CheckAgainst(rig));
      rig::VibrationExposure planned(rig.amplitude_mm);
      for (const rig::SweepStep& step : script.steps) {
        planned.Add(step.hz, step.repeats * (step.settle_s + step.hold_s));
      }
      spdlog::info(
          "sweep {}: {} step(s) on rig {}, at least {:.0f} s of vibration, A(8) >= {:.2f} m/s^2 "
          "(unweighted)",
          script.name, script.InstanceCount(), rig.name, script.MinimumDurationS(),
          planned.A8_m_s2());
      if (planned.A8_m_s2() > 0.5) {
        spdlog::warn(
            "sweep {}: the planned exposure A(8) {:.2f} m/s^2 is above the daily exposure action "
            "value "
            "0.5 m/s^2 of Directive 2002/44/EC{}",
            script.name, planned.A8_m_s2(),
            planned.A8_m_s2() > 1.15 ? " and above its limit value 1.15 m/s^2" : "");
      }
      if (options->check) {
        if (options->json) {
          Json plan;
          plan["sweep"] = script.name;
          plan["rig"] = rig.name;
          plan["instances"] = script.InstanceCount();
          plan["minimum_duration_s"] = script.MinimumDurationS();
          plan["planned_exposure"] = planned.ToJson();
          std::printf("%s\n", plan.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
        }
        return Status::Ok();
      }
      rig::SweepOptions sweep_options;
      sweep_options.session_dir = options->session;
      sweep_options.resume = options->resume;
      sweep_options.stop_requested = rig::InstallStopSignalHandlers();
      sweep_options.print_prompts = !options->json;
      FACEDYN_ASSIGN_OR_RETURN(const rig::SweepResult result,
                               rig::RunSweep(script, rig, sweep_options));
      if (options->json) {
        std::printf("%s\n", result.ToJson().dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      } else {
        for (const rig::SweepStepResult& step : result.steps) {
          std::printf("step %3d  %6.2f Hz  measured %7.3f Hz  max error %.3f Hz  %s%s\n",
                      step.instance + 1, step.target_hz, step.hold.mean_measured_hz,
                      step.hold.max_abs_error_hz, step.prompt.c_str(),
                      step.this_run ? "" : "  (before resume)");
        }
        std::printf(
            "exposure %.1f s of vibration, A(8) %.3f m/s^2 (unweighted, cumulative over the "
            "session)\n",
            result.exposure.value("vibrating_s", 0.0),
            result.exposure.value("a8_unweighted_m_s2", 0.0));
        std::printf("log %s\n", result.log_path.c_str());
      }
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
