// The demo's self-contained HTML report (issue 8): every figure comes from metrics.json, plots
// are inline SVG, nothing is fetched from the network. Sections are drawn for whichever stages
// the metrics contain, so the report grows as stages join the demo.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::report {

// `text` with < > & " as HTML entities, for element text and attribute values.
std::string EscapeHtml(const std::string& text);

// Writes `path` (HTML) from the demo metrics. Renders are embedded from the files the metrics
// name ("renders" "images" "path"); a relative path is read from `files_dir` (empty: the folder
// of `path`, which for the demo is where metrics.json and renders/ are). Errors when a render
// is missing or empty (DataLoss, naming it) or the file cannot be written.
Status WriteDemoReport(const Json& metrics, const std::string& path,
                       const std::string& files_dir = "");

// A horizontal bar chart as an inline SVG element: one bar per (label, value), values >= 0,
// with the value printed at the bar's end in `unit`. Escapes labels.
std::string SvgBarChart(const std::string& title,
                        const std::vector<std::pair<std::string, double>>& bars,
                        const std::string& unit);

// One line of a line plot: points (x[k], y[k]); a non-finite y breaks the line there.
struct SvgSeries {
  std::string name;    // legend text
  std::string colour;  // any SVG colour, e.g. "#c0392b"
  std::vector<double> x, y;
  bool dashed = false;
  double width_px = 1.5;
};

// A line plot as an inline SVG element with axes, ticks, labels and a legend; `shaded` are
// x-intervals drawn as light bands behind the lines (e.g. the holds of a sweep). The axes span
// the finite data (y from 0 when all y >= 0). Escapes text. Series with mismatched x and y
// sizes are drawn up to the shorter.
std::string SvgLinePlot(const std::string& title, const std::string& x_label,
                        const std::string& y_label, const std::vector<SvgSeries>& series,
                        const std::vector<std::pair<double, double>>& shaded = {});

}  // namespace facedyn::report
