// `facedyn reconstruct`: a recorded take of a capture session -> a Take (meshes in the
// FaceRig's topology plus world_from_skull per frame) and a per-frame quality report.

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "app/command.h"
#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/take.h"
#include "reconstruct/pipeline.h"
#include "reconstruct/session_input.h"
#include "sim/procedural_face.h"

namespace facedyn::app {

void AddReconstructCommand(CLI::App& app, CommandRunner* selected) {
  struct ReconstructOptions {
    std::string session;
    std::string take;
    std::string out;
    std::string face = "procedural";
    std::string calibration;
    std::string markers;
    double marker_diameter_px = 8.0;
    bool bright = false;
    bool occlusion_refit = false;
    std::string skull_deflection = "tissue-model";
    bool json = false;
  };
  auto options = std::make_shared<ReconstructOptions>();
  auto* command = app.add_subcommand(
      "reconstruct",
      "Reconstruct a recorded take: marker detection, triangulation, labelling, skull pose and "
      "dense fit -> a Take, plus TAKE/reconstruction.json (per-frame quality)");
  command->add_option("--session", options->session, "Capture session folder")->required();
  command->add_option("--take", options->take, "Take name in the session")->required();
  command->add_option("--out", options->out, "Output take folder")->required();
  command
      ->add_option("--face", options->face,
                   "FaceRig folder of the subject, or \"procedural\" (the built-in face)")
      ->capture_default_str();
  command->add_option("--calibration", options->calibration,
                      "Calibration YAML (default: the session's calibration.yaml)");
  command->add_option("--markers", options->markers,
                      "The markers painted for this take when they are fewer than the face's: a "
                      "count (the face's first N) or a file of marker names (a head-mounted "
                      "camera's sparse layout)");
  command
      ->add_option("--marker-diameter-px", options->marker_diameter_px,
                   "Typical marker diameter in the images (tunes the detector)")
      ->capture_default_str();
  command->add_flag("--bright-markers", options->bright, "Markers brighter than the skin");
  command
      ->add_option("--skull-deflection", options->skull_deflection,
                   "How the skull pose models the stable markers' jiggle: tissue-model (the face "
                   "model's deflection shapes; rigs without one fall back) or thickness-squared "
                   "(one deflection growing with tissue thickness squared)")
      ->check(CLI::IsMember({"tissue-model", "thickness-squared"}))
      ->capture_default_str();
  command->add_flag("--occlusion-refit", options->occlusion_refit,
                    "Refit dots smaller than their neighbours as partly hidden (off by default: "
                    "it moves obliquely seen dots off their centres; never on head-mounted takes)");
  command->add_flag("--json", options->json, "Print the summary as JSON on stdout");
  command->callback([options, selected] {
    *selected = [options]() -> Status {
      FaceRig rig;
      if (options->face == "procedural") {
        FACEDYN_ASSIGN_OR_RETURN(rig, sim::MakeProceduralFace(sim::ProceduralFaceOptions()));
      } else {
        FACEDYN_ASSIGN_OR_RETURN(rig, LoadFaceRig(options->face));
      }
      if (!options->markers.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(rig.markers,
                                 SelectMarkerLayout(rig, options->markers, "--markers"));
      }
      reconstruct::SessionInputOptions input_options;
      input_options.calibration_path = options->calibration;
      auto& detection = input_options.detection;
      detection.polarity = options->bright ? reconstruct::MarkerPolarity::kBright
                                           : reconstruct::MarkerPolarity::kDark;
      if (!(options->marker_diameter_px >= 2.0 && options->marker_diameter_px <= 100.0)) {
        return InvalidArgumentError("--marker-diameter-px must be in [2, 100], got " +
                                    std::to_string(options->marker_diameter_px));
      }
      const reconstruct::MarkerPolarity polarity = detection.polarity;
      detection = reconstruct::MarkerDetectionOptionsForDiameter(options->marker_diameter_px);
      detection.polarity = polarity;
      detection.occlusion_refit = options->occlusion_refit;
      FACEDYN_ASSIGN_OR_RETURN(
          const reconstruct::SessionDetections input,
          reconstruct::DetectSessionTake(options->session, options->take, input_options));
      for (const std::string& problem : input.take_problems) spdlog::warn("{}", problem);
      reconstruct::ReconstructionOptions reconstruction_options =
          input.head_mounted ? reconstruct::HeadMountedReconstructionOptions()
                             : reconstruct::ReconstructionOptions();
      reconstruction_options.skull.deflection_shape =
          options->skull_deflection == "thickness-squared"
              ? reconstruct::DeflectionShape::kThicknessSquared
              : reconstruct::DeflectionShape::kTissueModel;
      if (input.head_mounted) {
        spdlog::info("head-mounted cameras: markers in the helmet (skull) frame, no skull pose");
      }
      FACEDYN_ASSIGN_OR_RETURN(reconstruct::Reconstruction result,
                               reconstruct::ReconstructTake(rig, input.cameras, input.detections,
                                                            input.fps, reconstruction_options));
      if (!result.jaw_status.ok()) {
        spdlog::warn("jaw not estimated (the take has no jaw.csv): {}",
                     result.jaw_status.message());
      }
      if (input.platform_hz) result.take.info.platform_hz = input.platform_hz;
      if (input.hold_start_s) result.take.info.hold_start_s = input.hold_start_s;
      result.take.info.metadata["session"] = options->session;
      result.take.info.metadata["session_take"] = options->take;
      // The labelled markers themselves, before take.json (written last by SaveTake).
      result.take.info.metadata["marker_tracks"] = {{"world", kMarkerTracksFile},
                                                    {"skull", kMarkerTracksSkullFile}};
      FACEDYN_RETURN_IF_ERROR(SaveMarkerTracks(reconstruct::MarkerTracksOf(rig, result),
                                               result.take.world_from_skull, options->out));
      FACEDYN_RETURN_IF_ERROR(SaveTake(result.take, options->out));

      Json report;
      report["session"] = options->session;
      report["take"] = options->take;
      report["out"] = options->out;
      report["cameras"] = Json::array();
      for (const auto& camera : input.cameras) report["cameras"].push_back(camera.name);
      report["take_problems"] = input.take_problems;
      report["jaw"] =
          result.jaw_status.ok()
              ? Json(result.take.skull_from_jaw.empty() ? "rig has no jaw" : "estimated")
              : Json("not estimated: " + result.jaw_status.message());
      report["frames"] = result.take.frame_count();
      report["camera_mount"] = input.head_mounted ? "head" : "world";
      if (!input.head_mounted) {
        report["skull_deflection_shape"] = result.take.info.metadata["skull_deflection_shape"];
        spdlog::info("skull pose: deflection shape {}",
                     result.take.info.metadata["skull_deflection_shape"].get<std::string>());
        report["skull_reference"] = result.take.info.metadata.value("skull_reference", Json());
        spdlog::info("skull pose: stable markers' reference {}", report["skull_reference"].dump());
      }
      report["seconds"] = {{"detect", input.detect_s},
                           {"triangulate", result.timings.triangulate_s},
                           {"track", result.timings.track_s},
                           {"skull", result.timings.skull_s},
                           {"dense", result.timings.dense_s}};
      // Where detection spends its time on this take's images (reconstruct_bench reports the
      // same per image for its own rendered frames): counters per image, CPU ms per stage.
      {
        const auto& t = input.detection_totals;
        const double n = std::max<int64_t>(1, input.images_detected);
        report["seconds"]["detect_cpu_ms_per_image"] = {
            {"candidates", t.candidates_ms / n},
            {"fits", t.fit_ms / n},
            {"occlusion_and_merge", t.occlusion_ms / n}};
        report["detection"] = {
            {"images", input.images_detected},
            {"candidates_per_image", t.candidates / n},
            {"accepted_per_image", t.accepted / n},
            {"rejected_per_image",
             {{"fit", t.rejected_fit / n},
              {"size", t.rejected_size / n},
              {"of_which_unfitted_size", t.rejected_size_unfitted / n},
              {"contrast", t.rejected_contrast / n},
              {"quality", t.rejected_quality / n},
              {"duplicates", t.duplicates / n}}},
            {"fits_per_image", t.fits / n},
            {"iterations_per_fit", t.fit_iterations / std::max(1.0, double(t.fits))},
            {"window_pixels_per_evaluation",
             t.fit_pixel_evaluations / std::max(1.0, double(t.fit_evaluations))},
            {"occlusion_fits_per_image", t.occlusion_fits / n},
            {"occlusion_refits_kept_per_image", t.refitted_for_occlusion / n}};
      }
      int problem_frames = 0;
      double mean_reprojection = 0.0, mean_labelled = 0.0, mean_fit = 0.0;
      for (size_t f = 0; f < result.quality.size(); ++f) {
        const auto& q = result.quality[f];
        std::string problem = q.problem;
        for (const std::string& p : input.frame_problems[f]) {
          problem += (problem.empty() ? "" : "; ") + p;
        }
        problem_frames += problem.empty() ? 0 : 1;
        mean_reprojection += q.reprojection_rms_px / result.quality.size();
        mean_labelled += static_cast<double>(q.labelled) / result.quality.size();
        mean_fit += q.fit_marker_rms_mm / result.quality.size();
        report["per_frame"].push_back({{"frame", q.frame},
                                       {"detections", q.detections},
                                       {"points", q.points},
                                       {"reprojection_rms_px", q.reprojection_rms_px},
                                       {"labelled", q.labelled},
                                       {"bridged", q.bridged},
                                       {"missing", q.missing},
                                       {"unlabelled_points", q.unlabelled_points},
                                       {"skull_rms_mm", q.skull_rms_mm},
                                       {"fit_marker_rms_mm", q.fit_marker_rms_mm},
                                       {"jaw_markers", q.jaw_markers},
                                       {"jaw_rms_mm", q.jaw_rms_mm},
                                       {"jaw_angle_rad", q.jaw_angle_rad},
                                       {"jaw_carried", q.jaw_carried},
                                       {"problem", problem}});
      }
      report["summary"] = {{"frames_with_problems", problem_frames},
                           {"mean_reprojection_rms_px", mean_reprojection},
                           {"mean_labelled_markers", mean_labelled},
                           {"markers", rig.markers.size()},
                           {"mean_fit_marker_rms_mm", mean_fit}};
      FACEDYN_RETURN_IF_ERROR(WriteJsonFile(options->out + "/reconstruction.json", report));
      if (options->json) {
        Json brief = report;
        brief.erase("per_frame");
        std::printf("%s\n", brief.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      } else {
        std::printf(
            "reconstructed %d frames from %zu cameras -> %s\n"
            "  reprojection %.3f px, %.1f of %zu markers labelled per frame, fit %.3f mm; "
            "%d frames with problems (see %s/reconstruction.json)\n",
            result.take.frame_count(), input.cameras.size(), options->out.c_str(),
            mean_reprojection, mean_labelled, rig.markers.size(), mean_fit, problem_frames,
            options->out.c_str());
      }
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
