// `facedyn calibrate`: camera intrinsics and rig extrinsics from images of a board.

#include <spdlog/spdlog.h>

#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "app/command.h"
#include "core/json_io.h"
#include "reconstruct/board.h"
#include "reconstruct/calibration.h"
#include "reconstruct/calibration_images.h"

namespace facedyn::app {

void AddCalibrateCommand(CLI::App& app, CommandRunner* selected) {
  struct CalibrateOptions {
    std::vector<std::string> images;
    std::string board;
    std::string out;
    std::string cameras_by = "auto";
    bool no_k3 = false;
    bool json = false;
  };
  auto options = std::make_shared<CalibrateOptions>();
  auto* command = app.add_subcommand(
      "calibrate",
      "Calibrate cameras from board images: intrinsics + distortion per camera, then every "
      "camera's pose by joint bundle adjustment; writes OpenCV FileStorage YAML");
  command
      ->add_option("--images", options->images,
                   "Image files or quoted globs. Images in different folders are different "
                   "cameras (folder = camera name); the same file name in several folders is "
                   "one instant")
      ->required()
      ->expected(1, -1);
  command
      ->add_option("--board", options->board,
                   "chessboard:COLSxROWS:SQUARE_MM (inner corners) or "
                   "charuco:COLSxROWS:SQUARE_MM:MARKER_MM[:DICT][:legacy] (squares; legacy = "
                   "a board printed before OpenCV 4.6 with an even row count)")
      ->required();
  command->add_option("--out", options->out, "Output calibration YAML")->required();
  command->add_option("--cameras-by", options->cameras_by, "auto | dir | single")
      ->check(CLI::IsMember({"auto", "dir", "single"}))
      ->capture_default_str();
  command->add_flag("--no-k3", options->no_k3, "Hold the k3 radial coefficient at 0");
  command->add_flag("--json", options->json, "Print the figures as JSON on stdout");
  command->callback([options, selected] {
    *selected = [options]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(const reconstruct::BoardSpec board,
                               reconstruct::BoardSpec::Parse(options->board));
      FACEDYN_ASSIGN_OR_RETURN(const std::vector<std::string> paths,
                               reconstruct::ExpandImagePatterns(options->images));
      const reconstruct::CameraGrouping grouping =
          options->cameras_by == "dir"      ? reconstruct::CameraGrouping::kByDirectory
          : options->cameras_by == "single" ? reconstruct::CameraGrouping::kSingleCamera
                                            : reconstruct::CameraGrouping::kAuto;
      std::vector<reconstruct::SkippedImage> skipped;
      FACEDYN_ASSIGN_OR_RETURN(const reconstruct::CalibrationInput input,
                               reconstruct::DetectBoardInImages(paths, board, grouping, &skipped));
      for (const auto& skip : skipped) spdlog::warn("skipped {}: {}", skip.path, skip.reason);
      reconstruct::CalibrationOptions calibration_options;
      calibration_options.estimate_k3 = !options->no_k3;
      reconstruct::CalibrationSummary summary;
      FACEDYN_ASSIGN_OR_RETURN(const reconstruct::RigCalibration calibration,
                               reconstruct::Calibrate(input, calibration_options, &summary));
      for (const auto& dropped : summary.dropped) spdlog::warn("left out {}", dropped);
      if (!summary.converged) spdlog::warn("the final adjustment did not converge");
      FACEDYN_RETURN_IF_ERROR(reconstruct::SaveCalibration(calibration, options->out));

      nlohmann::json report;
      report["out"] = options->out;
      report["board"] = calibration.board;
      report["images"] = paths.size();
      report["rms_px"] = calibration.rms_px;
      report["corners"] = summary.corners;
      report["outliers"] = summary.outliers;
      report["converged"] = summary.converged;
      report["iterations"] = summary.iterations;
      for (size_t c = 0; c < calibration.cameras.size(); ++c) {
        const auto& camera = calibration.cameras[c];
        const Eigen::Vector3d centre = camera.CenterInWorld();
        report["cameras"].push_back(
            {{"name", camera.name},
             {"image_size", {camera.width_px, camera.height_px}},
             {"fx", camera.fx()},
             {"fy", camera.fy()},
             {"cx", camera.cx()},
             {"cy", camera.cy()},
             {"distortion",
              std::vector<double>(camera.intrinsics.begin() + 4, camera.intrinsics.end())},
             {"center_in_world_mm", {centre.x(), centre.y(), centre.z()}},
             {"rms_px", calibration.camera_rms_px[c]},
             {"corners", calibration.camera_corners[c]}});
      }
      for (const auto& error : calibration.view_errors) {
        report["views"].push_back({{"view", calibration.view_names[error.view]},
                                   {"camera", calibration.cameras[error.camera].name},
                                   {"corners", error.corners},
                                   {"outliers", error.outliers},
                                   {"rms_px", error.rms_px}});
      }
      report["skipped"] = nlohmann::json::array();
      for (const auto& skip : skipped) {
        report["skipped"].push_back({{"image", skip.path}, {"reason", skip.reason}});
      }
      if (options->json) {
        std::printf("%s\n", report.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      } else {
        std::printf(
            "calibrated %zu camera(s) from %zu images (%zu skipped), %d corners, %d "
            "outliers: RMS %.3f px -> %s\n",
            calibration.cameras.size(), paths.size(), skipped.size(), summary.corners,
            summary.outliers, calibration.rms_px, options->out.c_str());
        for (size_t c = 0; c < calibration.cameras.size(); ++c) {
          const auto& camera = calibration.cameras[c];
          std::printf("  %-10s fx %.2f fy %.2f cx %.2f cy %.2f  k1 %.4f k2 %.4f  RMS %.3f px\n",
                      camera.name.c_str(), camera.fx(), camera.fy(), camera.cx(), camera.cy(),
                      camera.intrinsics[4], camera.intrinsics[5], calibration.camera_rms_px[c]);
        }
      }
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
