// `facedyn take info` and `facedyn export`.

#include <spdlog/spdlog.h>

#include <cstdio>
#include <memory>
#include <string>

#include "app/command.h"
#include "core/json_io.h"
#include "core/take.h"
#include "core/take_export.h"
#include "core/take_summary.h"

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
    std::string format;
    std::string out_dir;
  };
  auto options = std::make_shared<ExportOptions>();
  auto* command = app.add_subcommand(
      "export", "Write a take as per-frame OBJ/PLY meshes, or as topology.obj + PC2 point caches");
  command->add_option("--take", options->take_dir, "Take folder")->required();
  command->add_option("--format", options->format, "obj | ply | pc2 | mdd")
      ->required()
      ->check(CLI::IsMember({"obj", "ply", "pc2"}));
  command->add_option("--out", options->out_dir, "Output folder (created if missing)")->required();
  command->callback([options, selected] {
    *selected = [options]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(const ExportFormat format, ParseExportFormat(options->format));
      FACEDYN_ASSIGN_OR_RETURN(const Take take, LoadTake(options->take_dir));
      FACEDYN_ASSIGN_OR_RETURN(const ExportSummary summary, ExportTake(take, format, options->out_dir));
      spdlog::info("wrote {} files to {}", summary.files_written, options->out_dir);
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
