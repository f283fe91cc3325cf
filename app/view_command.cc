// `facedyn view TAKE [TAKE ...] [--color offset|error:TRUTH_TAKE|none] --out VIEW.html`.

#include <spdlog/spdlog.h>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "app/command.h"
#include "core/take.h"
#include "report/take_viewer.h"

namespace facedyn::app {

void AddViewCommand(CLI::App& app, CommandRunner* selected) {
  struct ViewOptions {
    std::vector<std::string> take_dirs;
    std::string colour = "offset";
    std::string title;
    int first_frame = 0;
    int max_frames = 0;
    std::string out;
  };
  auto options = std::make_shared<ViewOptions>();
  auto* command = app.add_subcommand(
      "view", "Write one self-contained HTML page that plays takes side by side in a browser");
  command->add_option("TAKE", options->take_dirs, "Take folders (shown left to right)")->required();
  command->add_option("--color", options->colour,
                      "offset (signed dynamic offset, red out / green in) | error:TRUTH_TAKE "
                      "(distance to a truth take) | none")
      ->capture_default_str();
  command->add_option("--title", options->title, "Page title (default: the take folders)");
  command->add_option("--first-frame", options->first_frame, "First frame shown")
      ->check(CLI::NonNegativeNumber);
  command->add_option("--max-frames", options->max_frames,
                      "At most this many frames from the first (0: to the end; the page holds about "
                      "9.3 bytes a vertex a frame)")
      ->check(CLI::NonNegativeNumber);
  command->add_option("--out", options->out, "HTML file to write")->required();
  command->callback([options, selected] {
    *selected = [options]() -> Status {
      report::ViewerOptions viewer;
      viewer.first_frame = options->first_frame;
      viewer.max_frames = options->max_frames;
      std::string mode = options->colour, truth_dir;
      if (mode.rfind("error:", 0) == 0) {
        truth_dir = mode.substr(6);
        mode = "error";
        if (truth_dir.empty()) return InvalidArgumentError("view: --color error:TRUTH_TAKE needs the truth take's folder");
      } else if (mode == "error") {
        return InvalidArgumentError("view: --color error needs the truth take, as error:TRUTH_TAKE");
      }
      FACEDYN_ASSIGN_OR_RETURN(viewer.colour, report::ParseViewerColour(mode));
      if (!truth_dir.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(viewer.truth, LoadTake(truth_dir));
      }
      std::vector<report::ViewerTake> takes;
      std::string names;
      for (const std::string& dir : options->take_dirs) {
        FACEDYN_ASSIGN_OR_RETURN(Take take, LoadTake(dir));
        const std::string label = std::filesystem::path(dir).filename().string().empty()
                                      ? std::filesystem::path(dir).parent_path().filename().string()
                                      : std::filesystem::path(dir).filename().string();
        names += (names.empty() ? "" : ", ") + label;
        takes.push_back({label, std::move(take)});
      }
      viewer.title = options->title.empty() ? "facedyn: " + names : options->title;
      FACEDYN_ASSIGN_OR_RETURN(const report::ViewerSummary summary,
                               report::WriteTakeViewer(takes, viewer, options->out));
      spdlog::info("wrote {} ({} takes, {} frames, colour range {:.3f} mm, {:.1f} MB)", options->out,
                   takes.size(), summary.frames, summary.colour_range_mm, summary.bytes / 1e6);
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
