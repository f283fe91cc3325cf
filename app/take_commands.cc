// `facedyn take info` and `facedyn export`.

#include <spdlog/spdlog.h>

#include <cstdio>
#include <memory>
#include <optional>
#include <string>

#include "app/command.h"
#include "core/blendshape_weights.h"
#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "core/take.h"
#include "core/take_summary.h"
#include "export/gltf_export.h"
#include "export/take_export.h"

namespace facedyn::app {

void AddTakeCommands(CLI::App& app, CommandRunner* selected) {
  auto* take = app.add_subcommand("take", "Inspect takes (mesh sequences plus skull motion)");
  take->require_subcommand(1);

  struct InfoOptions {
    std::string take_dir;
    bool json = false;
  };
  auto info_options = std::make_shared<InfoOptions>();
  auto* info = take->add_subcommand(
      "info", "Frames, fps, vertices, channels, duration and skull motion range of a take");
  info->add_option("TAKE", info_options->take_dir, "Take folder")->required();
  info->add_flag("--json", info_options->json, "Print JSON on stdout");
  info->callback([info_options, selected] {
    *selected = [info_options]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(const Take loaded, LoadTake(info_options->take_dir));
      const TakeSummary summary = SummarizeTake(loaded);
      if (info_options->json) {
        std::printf("%s\n", TakeSummaryToJson(loaded, summary)
                                .dump(2, ' ', false, kJsonReplaceInvalidUtf8)
                                .c_str());
      } else {
        std::printf("take          %s\n%s", info_options->take_dir.c_str(),
                    TakeSummaryToText(loaded, summary).c_str());
      }
      return Status::Ok();
    };
  });
}

void AddExportCommand(CLI::App& app, CommandRunner* selected) {
  struct ExportOptions {
    std::string take_dir;
    std::string rig_dir;
    std::string weights_csv;
    std::string format;
    std::string out_dir;
  };
  auto options = std::make_shared<ExportOptions>();
  auto* command = app.add_subcommand(
      "export",
      "Write a take as per-frame OBJ/PLY meshes, topology.obj + PC2 or MDD point caches, or a "
      "glTF binary; or a face rig (blendshapes as morph targets, optionally animated by a "
      "weights CSV) as a glTF binary");
  auto* take_option = command->add_option("--take", options->take_dir, "Take folder");
  auto* rig_option = command->add_option("--rig", options->rig_dir,
                                  "FaceRig folder (facedyn sim face): exported as DIR/rig.glb");
  take_option->excludes(rig_option);
  command
      ->add_option("--weights", options->weights_csv,
                   "With --rig: blendshape weights over time (CSV time_s,<name>,..., or "
                   "the JSON twin solve run writes) to animate the morph targets")
      ->needs(rig_option);
  command->add_option("--format", options->format, "obj | ply | pc2 | mdd | glb (--rig: glb)")
      ->required()
      ->check(CLI::IsMember({"obj", "ply", "pc2", "mdd", "glb"}));
  command->add_option("--out", options->out_dir, "Output folder (created if missing)")->required();
  command->callback([options, selected] {
    *selected = [options]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(const ExportFormat format, ParseExportFormat(options->format));
      if (options->take_dir.empty() && options->rig_dir.empty()) {
        return InvalidArgumentError("export: give --take TAKE or --rig FACE");
      }
      if (!options->rig_dir.empty()) {
        if (format != ExportFormat::kGlb) {
          return InvalidArgumentError("export --rig writes glTF only: use --format glb (got '" +
                                      options->format + "')");
        }
        FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFaceRig(options->rig_dir));
        std::optional<BlendshapeWeightsTrack> weights;
        if (!options->weights_csv.empty()) {
          FACEDYN_ASSIGN_OR_RETURN(weights, ReadBlendshapeWeights(options->weights_csv));
        }
        FACEDYN_RETURN_IF_ERROR(MakeDirectories(options->out_dir));
        const std::string path = JoinPath(options->out_dir, "rig.glb");
        FACEDYN_ASSIGN_OR_RETURN(const GlbSummary summary,
                                 WriteRigGlb(rig, weights ? &*weights : nullptr, path));
        spdlog::info("wrote {} ({} vertices, {} morph targets, {} animation samples, {:.1f} MB)",
                     path, summary.vertex_count, summary.morph_target_count,
                     summary.animation_samples, summary.bytes / 1e6);
        return Status::Ok();
      }
      FACEDYN_ASSIGN_OR_RETURN(const Take take, LoadTake(options->take_dir));
      FACEDYN_ASSIGN_OR_RETURN(const ExportSummary summary, ExportTake(take, format, options->out_dir));
      spdlog::info("wrote {} files to {}", summary.files_written, options->out_dir);
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
