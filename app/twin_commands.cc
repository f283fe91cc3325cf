// `facedyn twin fit`, `twin perform` and `twin target`: the subject's physical twin identified
// from a session's platform takes (physics/twin.h), the twin simulated under motions nobody
// captured, and a held frame's expression fitted with the twin (physics/twin_targeting.h). app/
// only wires: reconstructed takes and the subject's FaceRig in, the twin's JSON out; `perform` runs
// the face model (through sim/'s performance generator: expression curves, motions) with the twin's
// material instead of a configured one. Nothing here reads a simulator's truth: no option takes a
// ground-truth folder or channel, and the takes' channels are not read by the fit.

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "app/command.h"
#include "app/performance_flags.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "core/take.h"
#include "physics/skull_kinematics.h"
#include "physics/twin.h"
#include "physics/twin_targeting.h"
#include "rig/rig_config.h"
#include "sim/performance.h"
#include "sim/skull_motion.h"

namespace facedyn::app {
namespace {

// "name:region+region;name:region;name" -> groups (a name alone takes the remaining tissue).
StatusOr<std::vector<physics::StiffnessGroup>> ParseGroups(const std::string& spec) {
  std::vector<physics::StiffnessGroup> groups;
  std::stringstream stream(spec);
  std::string item;
  while (std::getline(stream, item, ';')) {
    if (item.empty()) continue;
    physics::StiffnessGroup group;
    const size_t colon = item.find(':');
    group.name = item.substr(0, colon);
    if (group.name.empty())
      return InvalidArgumentError("--groups: a group has no name in '" + spec + "'");
    if (colon != std::string::npos) {
      std::stringstream regions(item.substr(colon + 1));
      std::string region;
      while (std::getline(regions, region, '+')) {
        if (!region.empty()) group.regions.push_back(region);
      }
      if (group.regions.empty()) {
        return InvalidArgumentError("--groups: group '" + group.name +
                                    "' lists no regions after ':'");
      }
    }
    groups.push_back(group);
  }
  if (groups.empty()) return InvalidArgumentError("--groups: no groups in '" + spec + "'");
  return groups;
}

std::string GroupsSpec(const std::vector<physics::StiffnessGroup>& groups) {
  std::string spec;
  for (const physics::StiffnessGroup& group : groups) {
    if (!spec.empty()) spec += ";";
    spec += group.name;
    for (size_t i = 0; i < group.regions.size(); ++i)
      spec += (i == 0 ? ":" : "+") + group.regions[i];
  }
  return spec;
}

}  // namespace

void AddTwinPerformCommand(CLI::App* twin, CommandRunner* selected);
void AddTwinTargetCommand(CLI::App* twin, CommandRunner* selected);

void AddTwinCommands(CLI::App& app, CommandRunner* selected) {
  auto* twin = app.add_subcommand(
      "twin", "The subject's physical twin: the face model fitted to a capture (Bao et al. 2018)");
  twin->require_subcommand(1);

  struct FitOptions {
    std::vector<std::string> takes;
    std::string processed;
    std::string face = "procedural";
    std::string out;
    std::string groups = GroupsSpec(physics::DefaultStiffnessGroups());
    double prior_hz = physics::TissueOptions{}.fundamental_hz;
    double prior_damping = physics::TissueOptions{}.damping_ratio;
    int max_iterations = physics::MaterialFitOptions{}.max_iterations;
    double platform_amplitude_mm = 0.0;
    std::string rig;
    bool json = false;
  };
  auto options = std::make_shared<FitOptions>();
  auto* fit = twin->add_subcommand("fit",
                                   "Identify the twin's tissue (stiffness per region group, "
                                   "damping) from reconstructed platform "
                                   "takes of held expressions");
  fit->add_option("--takes", options->takes,
                  "Reconstructed platform takes (each with its platform frequency and hold time)");
  fit->add_option("--processed", options->processed,
                  "A `facedyn process` output folder: its reconstructed takes that have a platform "
                  "frequency (the others are skipped and listed)");
  fit->add_option("--face", options->face, "The subject's FaceRig folder, or 'procedural'")
      ->capture_default_str();
  fit->add_option("--out", options->out, "Twin JSON file to write")->required();
  fit->add_option("--groups", options->groups,
                  "Stiffness groups: 'name:region+region;...;name' (a name alone takes the rest)")
      ->capture_default_str();
  fit->add_option("--prior-hz", options->prior_hz, "The twin's cheek frequency before the fit (Hz)")
      ->capture_default_str();
  fit->add_option("--prior-damping", options->prior_damping,
                  "The twin's damping ratio before the fit")
      ->capture_default_str();
  fit->add_option("--max-iterations", options->max_iterations,
                  "Levenberg-Marquardt iterations per round")
      ->capture_default_str();
  fit->add_option("--platform-amplitude-mm", options->platform_amplitude_mm,
                  "The platform's peak displacement (mm, the rig config's amplitude_mm): fits the "
                  "body's transmissibility from platform to skull too (needs 3 frequencies)");
  fit->add_option("--rig", options->rig,
                  "The platform's RIG.yaml: its amplitude_mm, as --platform-amplitude-mm");
  fit->add_flag("--json", options->json, "Print the twin's JSON on stdout");
  fit->callback([options, selected] {
    *selected = [options]() -> Status {
      const FitOptions& o = *options;
      if (o.takes.empty() == o.processed.empty()) {
        return InvalidArgumentError("twin fit: give either --takes or --processed (one of them)");
      }
      physics::TwinFitOptions fit_options;
      fit_options.prior.fundamental_hz = o.prior_hz;
      fit_options.prior.damping_ratio = o.prior_damping;
      fit_options.fit.max_iterations = o.max_iterations;
      fit_options.platform_amplitude_mm = o.platform_amplitude_mm;
      if (!o.rig.empty()) {
        if (o.platform_amplitude_mm != 0) {
          return InvalidArgumentError(
              "twin fit: give the platform amplitude once (--rig or --platform-amplitude-mm)");
        }
        FACEDYN_ASSIGN_OR_RETURN(const rig::RigConfig rig_config, rig::LoadRigConfig(o.rig));
        fit_options.platform_amplitude_mm = rig_config.amplitude_mm;
      }
      FACEDYN_ASSIGN_OR_RETURN(fit_options.groups, ParseGroups(o.groups));
      if (Status status = fit_options.Check(); !status.ok()) {
        return InvalidArgumentError("twin fit: " + status.message() +
                                    " (--prior-hz, --prior-damping, --max-iterations, "
                                    "--platform-amplitude-mm)");
      }
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(o.face));

      std::vector<std::string> dirs = o.takes;
      std::vector<std::string> skipped;
      if (!o.processed.empty()) {
        const std::filesystem::path root = std::filesystem::path(o.processed) / "takes";
        std::error_code error;
        if (!std::filesystem::is_directory(root, error)) {
          return NotFoundError("twin fit: " + root.string() +
                               " is not a folder (is --processed a `facedyn process` output?)");
        }
        std::vector<std::string> candidates;
        for (const auto& entry : std::filesystem::directory_iterator(root, error)) {
          const std::filesystem::path take = entry.path() / "reconstructed";
          if (std::filesystem::exists(take / "take.json")) candidates.push_back(take.string());
        }
        std::sort(candidates.begin(), candidates.end());
        for (const std::string& dir : candidates) {
          FACEDYN_ASSIGN_OR_RETURN(const Take take, LoadTake(dir));
          if (take.info.platform_hz) {
            dirs.push_back(dir);
          } else {
            skipped.push_back(dir);
          }
        }
        if (dirs.empty()) {
          return NotFoundError("twin fit: " + o.processed +
                               " has no reconstructed takes with a platform frequency");
        }
      }
      std::vector<Take> takes;
      takes.reserve(dirs.size());
      for (const std::string& dir : dirs) {
        FACEDYN_ASSIGN_OR_RETURN(Take take, LoadTake(dir));
        takes.push_back(std::move(take));
      }
      std::vector<std::pair<std::string, const Take*>> named;
      for (size_t i = 0; i < takes.size(); ++i) named.push_back({dirs[i], &takes[i]});
      FACEDYN_ASSIGN_OR_RETURN(const physics::FittedTwin fitted,
                               physics::FitTwin(rig, named, fit_options));
      Json json = physics::TwinToJson(fitted);
      json["skipped_takes"] = skipped;
      FACEDYN_RETURN_IF_ERROR(WriteJsonFile(o.out, json));
      if (o.json) {
        std::printf("%s\n", json.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      } else {
        spdlog::info(
            "twin of '{}' from {} platform takes: cheeks {:.3f} +- {:.3f} Hz, damping ratio {:.4f} "
            "+- {:.4f} "
            "(prior {:.2f} Hz, {:.3f}); phasor residual {:.3f} -> {:.3f} mm; wrote {}",
            rig.name, takes.size(), fitted.cheek_mode.omega_rad_s / (2 * M_PI),
            fitted.cheek_hz_stddev, fitted.cheek_mode.damping_ratio,
            fitted.cheek_damping_ratio_stddev, fitted.prior_cheek_mode.omega_rad_s / (2 * M_PI),
            fitted.prior_cheek_mode.damping_ratio, fitted.fit.rms_initial_mm,
            fitted.fit.rms_final_mm, o.out);
        if (fitted.body) {
          spdlog::info(
              "body: resonance {:.2f} +- {:.2f} Hz, damping ratio {:.3f} +- {:.3f}, pitch "
              "{:.4f} rad/g, from {} frequencies",
              fitted.body->resonance_hz, fitted.body->resonance_hz_stddev,
              fitted.body->damping_ratio, fitted.body->damping_ratio_stddev,
              fitted.body->pitch_rad_per_g, fitted.body->distinct_frequencies);
        } else {
          spdlog::info("body: {}", fitted.body_note);
        }
        for (const std::string& dir : skipped)
          spdlog::info("skipped (no platform frequency): {}", dir);
      }
      return Status::Ok();
    };
  });
  AddTwinPerformCommand(twin, selected);
  AddTwinTargetCommand(twin, selected);
}

void AddTwinPerformCommand(CLI::App* twin_command, CommandRunner* selected) {
  struct PerformOptions {
    std::string twin;
    std::string face = "procedural";
    std::string motion = "nod";
    std::string out;
    sim::PerformanceOptions performance;
  };
  auto options = std::make_shared<PerformOptions>();
  auto& p = options->performance;
  auto* perform = twin_command->add_subcommand(
      "perform",
      "Simulate the twin: its fitted tissue under an expression and a head motion (training data)");
  perform->add_option("--twin", options->twin, "Twin JSON from `facedyn twin fit`")->required();
  perform
      ->add_option("--face", options->face, "The FaceRig the twin was fitted to, or 'procedural'")
      ->capture_default_str();
  AddPerformanceFlags(perform, &p, &options->motion);
  perform->add_option("--step-s", p.tissue.max_step_s, "Largest integration step (s)")
      ->capture_default_str();
  perform->add_option("--out", options->out, "Take folder to write")->required();
  perform->callback([options, selected] {
    *selected = [options]() -> Status {
      sim::PerformanceOptions performance = options->performance;
      FACEDYN_ASSIGN_OR_RETURN(performance.motion.kind,
                               sim::ParseMotionKind(options->motion, &performance.motion.file));
      performance.motion.seed = performance.seed;
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(options->face));
      FACEDYN_ASSIGN_OR_RETURN(const physics::LoadedTwin twin,
                               physics::LoadTwin(options->twin, rig));
      const double step_s = performance.tissue.max_step_s;
      performance.tissue = twin.tissue;
      performance.tissue.max_step_s = step_s;
      performance.material = twin.material;
      // The platform carries the twin through its own fitted body (when the fit had the
      // platform's amplitude and three frequencies), not the simulator's standing-body default.
      if (twin.body && performance.motion.kind == sim::MotionKind::kPlatform) {
        performance.motion.body_resonance_hz = twin.body->resonance_hz;
        performance.motion.body_damping_ratio = twin.body->damping_ratio;
        performance.motion.pitch_rad_per_g = twin.body->pitch_rad_per_g;
        spdlog::info(
            "platform through the twin's body: resonance {:.2f} Hz, damping ratio {:.3f}, "
            "pitch {:.4f} rad/g",
            twin.body->resonance_hz, twin.body->damping_ratio, twin.body->pitch_rad_per_g);
      }
      sim::PerformanceSummary summary;
      FACEDYN_ASSIGN_OR_RETURN(Take take, sim::SimulatePerformance(rig, performance, &summary));
      take.info.source = "twin perform";
      take.info.metadata["generator"] = "facedyn twin perform";
      take.info.metadata["twin"] = options->twin;
      take.info.metadata["twin_cheek_mode"] = {{"hz", twin.cheek_mode.omega_rad_s / (2 * M_PI)},
                                               {"damping_ratio", twin.cheek_mode.damping_ratio}};
      FACEDYN_RETURN_IF_ERROR(SaveTake(take, options->out));
      spdlog::info("wrote {} ({} frames of the twin, cheeks {:.2f} Hz; simulated in {:.1f} s)",
                   options->out, take.frame_count(), twin.cheek_mode.omega_rad_s / (2 * M_PI),
                   summary.simulate_s);
      return Status::Ok();
    };
  });
}

void AddTwinTargetCommand(CLI::App* twin_command, CommandRunner* selected) {
  struct TargetOptions {
    std::string twin;
    std::string face = "procedural";
    std::string take;
    double from_s = -1.0;  // < 0: the take's first held frame
    double to_s = -1.0;    // < 0: its end
    physics::TargetingOptions targeting;
    std::string out;
  };
  auto options = std::make_shared<TargetOptions>();
  auto* target = twin_command->add_subcommand(
      "target",
      "Fit a held expression with the twin: the expression whose equilibrium under the frame's "
      "gravity matches the markers (Bao et al. 2018), beside the plain blendshape fit");
  target->add_option("--twin", options->twin, "Twin JSON from `facedyn twin fit`")->required();
  target->add_option("--face", options->face, "The FaceRig the twin was fitted to, or 'procedural'")
      ->capture_default_str();
  target->add_option("--take", options->take, "Reconstructed take folder (skin and skull pose)")
      ->required();
  target->add_option("--from-s", options->from_s,
                     "Start of the held window, s (default: the take's hold start, or 0)");
  target->add_option("--to-s", options->to_s,
                     "End of the held window, s (default: the take's end)");
  target
      ->add_option("--max-iterations", options->targeting.max_iterations,
                   "Gauss-Newton iterations of the twin fit (each re-factorises the flesh)")
      ->capture_default_str();
  target
      ->add_option("--robust-mm", options->targeting.robust_scale_mm,
                   "Cauchy loss of this scale (mm) on each marker's distance, so gross marker "
                   "errors pull less (0: least squares)")
      ->capture_default_str();
  target->add_flag("--align-skull,!--no-align-skull", options->targeting.align_skull,
                   "Also fit a small rigid correction of the skull pose with the expression (both "
                   "fits; on by default: with the robust loss it halved the twin's expression "
                   "error on twin_bench's lying-back validation frames)");
  target->add_option("--out", options->out, "Result JSON to write")->required();
  target->callback([options, selected] {
    *selected = [options]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(options->face));
      FACEDYN_ASSIGN_OR_RETURN(const physics::LoadedTwin twin,
                               physics::LoadTwin(options->twin, rig));
      FACEDYN_ASSIGN_OR_RETURN(const Take take, LoadTake(options->take));
      if (take.vertex_count() != rig.vertex_count()) {
        return FailedPreconditionError(fmt::format(
            "twin target: take {} has {} vertices per frame, face '{}' has {} (a take in the "
            "face's topology is needed: `facedyn reconstruct` output)",
            options->take, take.vertex_count(), rig.name, rig.vertex_count()));
      }
      if (!std::isfinite(options->from_s) || !std::isfinite(options->to_s)) {
        return InvalidArgumentError("twin target: --from-s and --to-s must be finite");
      }
      const double from_s = options->from_s >= 0 ? options->from_s
                            : FirstHeldFrame(take) < take.frame_count()
                                ? take.time_s[FirstHeldFrame(take)]
                                : 0.0;
      const double to_s = options->to_s >= 0 ? options->to_s : take.time_s.back() + 1.0;
      std::vector<int> frames;
      for (int f = 0; f < take.frame_count(); ++f) {
        if (take.time_s[f] >= from_s - 1e-9 && take.time_s[f] < to_s) frames.push_back(f);
      }
      if (frames.empty()) {
        return InvalidArgumentError(fmt::format(
            "twin target: no frame of {} lies in [{:g}, {:g}) s (the take spans {:g}-{:g} s)",
            options->take, from_s, to_s, take.time_s.front(), take.time_s.back()));
      }
      // The window's mean in the skull frame, and its mean gravity there.
      const std::vector<int> vertices = physics::TwinMarkerVertices(rig);
      FACEDYN_ASSIGN_OR_RETURN(
          const physics::HeldWindow window,
          physics::MeanHeldWindow(take, vertices, frames.front(), frames.back() + 1));
      const Eigen::Vector3d& gravity_change = window.gravity_change_in_skull;
      FACEDYN_ASSIGN_OR_RETURN(std::unique_ptr<physics::SoftTissueModel> model,
                               physics::SoftTissueModel::Create(rig, twin.tissue, twin.material));
      spdlog::info(
          "targeting {} frames ({:.3f}-{:.3f} s) of {} at {} markers; gravity changed by "
          "{:.0f} mm/s^2 in the skull frame",
          frames.size(), take.time_s[frames.front()], take.time_s[frames.back()], options->take,
          vertices.size(), gravity_change.norm());
      FACEDYN_ASSIGN_OR_RETURN(
          const physics::ExpressionTargeting fit,
          physics::TargetHeldExpression(*model, rig, vertices, window.positions_in_skull,
                                        gravity_change, options->targeting));
      auto fit_json = [&](const physics::ExpressionTargetingFit& f) {
        Json weights = Json::object();
        for (size_t k = 0; k < rig.blendshape_names.size(); ++k)
          weights[rig.blendshape_names[k]] = f.weights[k];
        return Json{{"weights", weights},
                    {"jaw_angle_rad", f.jaw_angle_rad},
                    {"marker_rms_mm", f.rms_mm},
                    {"common_inlier_rms_mm", f.common_inlier_rms_mm},
                    {"common_inlier_markers", f.common_inlier_markers},
                    {"flesh_volume_change", f.flesh_volume_change},
                    {"skull_rotation_deg", f.skull_rotation_deg},
                    {"skull_translation_mm", f.skull_translation_mm},
                    {"outlier_markers", f.outlier_markers},
                    {"iterations", f.iterations},
                    {"seconds", f.seconds}};
      };
      auto twin_json = [&](const physics::ExpressionTargetingFit& f) {
        Json json = fit_json(f);
        json["cost_history"] = f.cost_history;
        json["termination"] = f.termination;
        return json;
      };
      const Json out = {{"format", "facedyn-twin-targeting"},
                        {"version", 1},
                        {"take", options->take},
                        {"twin", options->twin},
                        {"face", rig.name},
                        {"frames", {frames.front(), frames.back()}},
                        {"window_s", {take.time_s[frames.front()], take.time_s[frames.back()]}},
                        {"markers", vertices.size()},
                        {"align_skull", options->targeting.align_skull},
                        {"robust_scale_mm", options->targeting.robust_scale_mm},
                        {"gravity_change_in_skull_mm_s2",
                         {gravity_change.x(), gravity_change.y(), gravity_change.z()}},
                        {"blendshape", fit_json(fit.blendshape)},
                        {"twin_fit", twin_json(fit.twin)}};
      FACEDYN_RETURN_IF_ERROR(WriteJsonFile(options->out, out));
      spdlog::info(
          "marker RMS: blendshape fit {:.3f} mm, twin {:.3f} mm ({} iterations, {:.1f} s); "
          "flesh volume change {:+.3f}% / {:+.3f}%; wrote {}",
          fit.blendshape.rms_mm, fit.twin.rms_mm, fit.twin.iterations, fit.twin.seconds,
          100 * fit.blendshape.flesh_volume_change, 100 * fit.twin.flesh_volume_change,
          options->out);
      if (options->targeting.align_skull) {
        spdlog::info("twin fit's skull correction: {:.3f} deg, {:.3f} mm",
                     fit.twin.skull_rotation_deg, fit.twin.skull_translation_mm);
      }
      if (options->targeting.robust_scale_mm > 0 && fit.twin.outlier_markers > 0) {
        spdlog::warn(
            "{} of {} markers are more than {:g} mm off the twin fit (down-weighted as gross "
            "errors; see the reconstruction)",
            fit.twin.outlier_markers, vertices.size(), 3 * options->targeting.robust_scale_mm);
      }
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
