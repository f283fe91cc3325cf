// `facedyn report`: the demo's report.html drawn again from a metrics.json, e.g. after the
// demo's output folder was moved or the report code changed, without rerunning the demo.

#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "app/command.h"
#include "report/report.h"
#include "core/file_util.h"
#include "core/json_io.h"

namespace facedyn::app {
namespace {

struct ReportOptions {
  std::string metrics_path;
  std::string out;  // empty: report.html beside the metrics
};

Status RunReport(const ReportOptions& options) {
  FACEDYN_ASSIGN_OR_RETURN(const std::string text, ReadFileToString(options.metrics_path));
  Json metrics;
  try {
    metrics = Json::parse(text);
  } catch (const Json::parse_error& e) {
    return InvalidArgumentError(options.metrics_path + ": not JSON (" + e.what() + ")");
  }
  if (!metrics.is_object()) {
    return InvalidArgumentError(options.metrics_path +
                                ": not a demo metrics file (the top level is not an object)");
  }
  // Renders are named relative to the demo's output folder, which is where metrics.json is.
  std::string files_dir = std::filesystem::path(options.metrics_path).parent_path().string();
  if (files_dir.empty()) files_dir = ".";
  const std::string out = options.out.empty() ? JoinPath(files_dir, "report.html") : options.out;
  FACEDYN_RETURN_IF_ERROR(report::WriteDemoReport(metrics, out, files_dir));
  std::printf("Report: %s\n", out.c_str());
  return Status::Ok();
}

}  // namespace

void AddReportCommand(CLI::App& app, CommandRunner* selected) {
  auto options = std::make_shared<ReportOptions>();
  auto* command = app.add_subcommand(
      "report", "Draw the demo's self-contained report.html again from its metrics.json");
  command->add_option("--metrics", options->metrics_path, "metrics.json written by facedyn demo")
      ->required();
  command->add_option("--out", options->out,
                      "Report to write (default: report.html beside the metrics)");
  command->callback([options, selected] { *selected = [options] { return RunReport(*options); }; });
}

}  // namespace facedyn::app
