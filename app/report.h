// The demo's self-contained HTML report (issue 8): every figure comes from metrics.json, plots
// are inline SVG, nothing is fetched from the network. Sections are drawn for whichever stages
// the metrics contain, so the report grows as stages join the demo.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::app {

// Writes `path` (HTML) from the demo metrics. Errors when the file cannot be written.
Status WriteDemoReport(const Json& metrics, const std::string& path);

// A horizontal bar chart as an inline SVG element: one bar per (label, value), values >= 0,
// with the value printed at the bar's end in `unit`. Escapes labels.
std::string SvgBarChart(const std::string& title,
                        const std::vector<std::pair<std::string, double>>& bars,
                        const std::string& unit);

}  // namespace facedyn::app
