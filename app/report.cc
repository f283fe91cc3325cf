#include "app/report.h"

#include <fmt/format.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <utility>
#include <vector>

#include "app/face_render.h"

namespace facedyn::app {
namespace {

std::string Escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '&':
        out += "&amp;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// Bars for the methods of one removal test take, in a fixed order; the networks first.
std::vector<std::pair<std::string, double>> RemovalBars(const Json& entry) {
  std::vector<std::pair<std::string, double>> bars;
  for (const auto& [method, figures] : entry["methods"].items()) {
    bars.emplace_back(method, figures["jiggle_mean_mm"].get<double>());
  }
  std::stable_sort(bars.begin(), bars.end(), [](const auto& a, const auto& b) {
    return (a.first.rfind("F_", 0) == 0) > (b.first.rfind("F_", 0) == 0);
  });
  return bars;
}

}  // namespace

std::string SvgBarChart(const std::string& title,
                        const std::vector<std::pair<std::string, double>>& bars,
                        const std::string& unit) {
  const int label_w = 330, bar_w = 360, row_h = 22, top = 28;
  const int height = top + row_h * static_cast<int>(bars.size()) + 8;
  double max_value = 0;
  for (const auto& bar : bars) max_value = std::max(max_value, bar.second);
  if (max_value <= 0) max_value = 1;
  std::string svg = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" role=\"img\">"
      "<text x=\"4\" y=\"18\" font-size=\"14\" font-weight=\"bold\">{}</text>",
      label_w + bar_w + 90, height, Escape(title));
  for (size_t k = 0; k < bars.size(); ++k) {
    const int y = top + static_cast<int>(k) * row_h;
    const int w = std::max(1, static_cast<int>(bar_w * bars[k].second / max_value));
    const bool network = bars[k].first.rfind("F_", 0) == 0 || bars[k].first.rfind("H", 0) == 0;
    svg += fmt::format(
        "<text x=\"{}\" y=\"{}\" font-size=\"12\" text-anchor=\"end\">{}</text>"
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"{}\"/>"
        "<text x=\"{}\" y=\"{}\" font-size=\"12\">{:.3f} {}</text>",
        label_w - 6, y + 14, Escape(bars[k].first), label_w, y + 2, w, row_h - 6,
        network ? "#c0392b" : "#7f8c8d", label_w + w + 6, y + 14, bars[k].second, Escape(unit));
  }
  svg += "</svg>";
  return svg;
}

Status WriteDemoReport(const Json& metrics, const std::string& path) {
  std::string html =
      "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>facedyn demo report</title>"
      "<style>body{font-family:sans-serif;max-width:960px;margin:2em auto;color:#222}"
      "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
      "th{background:#f4f4f4}td:first-child{text-align:left}</style></head><body>"
      "<h1>facedyn demo report</h1><p>Everything below ran on the simulated stage; errors are "
      "measured against the simulator's exact quasistatic skin. Figures are also in "
      "metrics.json beside this file.</p>";
  if (metrics.contains("rig")) {
    const Json& rig = metrics["rig"];
    html +=
        "<h2>Platform: simulated drive over Modbus TCP, scripted sweep</h2><table><tr>"
        "<th>step</th><th>target Hz</th><th>measured Hz</th><th>true platform Hz</th>"
        "<th>max |error| Hz</th><th>hold s</th><th>prompt</th></tr>";
    int index = 0;
    for (const Json& step : rig["steps"]) {
      html += fmt::format(
          "<tr><td>{}</td><td>{:.2f}</td><td>{:.3f}</td><td>{:.3f}</td>"
          "<td>{:.3f}</td><td>{:.1f}</td><td>{}</td></tr>",
          ++index, step["target_hz"].get<double>(), step["measured_mean_hz"].get<double>(),
          step["true_platform_hz"].is_number() ? step["true_platform_hz"].get<double>() : 0.0,
          step["max_abs_error_hz"].get<double>(), step["hold_s"].get<double>(),
          Escape(step["prompt"].get<std::string>()));
    }
    html += "</table>";
  }
  // A two-column table of the numeric and string fields of a JSON object, in its order.
  auto field_table = [](const Json& object, const std::vector<std::string>& keys) {
    std::string table = "<table>";
    for (const std::string& key : keys) {
      if (!object.contains(key)) continue;
      const Json& value = object[key];
      table += "<tr><td>" + Escape(key) + "</td><td>" +
               (value.is_number_float() ? fmt::format("{:.4g}", value.get<double>())
                : value.is_string()     ? Escape(value.get<std::string>())
                                        : Escape(value.dump())) +
               "</td></tr>";
    }
    return table + "</table>";
  };
  if (metrics.contains("capture")) {
    html += "<h2>Capture: simulated trigger-synchronised cameras</h2>" +
            field_table(metrics["capture"],
                        {"status", "cameras", "fps", "triggers_requested", "triggers_emitted",
                         "platform_hz_true", "megabytes_written", "megabytes_per_s",
                         "render_frames_per_s_per_thread", "backpressure", "session_complete"});
  }
  if (metrics.contains("reconstruct")) {
    html += "<h2>Reconstruction of the simulated 11 Hz take against ground truth</h2>" +
            field_table(metrics["reconstruct"],
                        {"calibration_rms_px", "calibration_worst_centre_error_mm",
                         "skull_origin_rms_mm", "skull_origin_max_mm", "skull_rotation_rms_deg",
                         "skull_rotation_max_deg", "sample_rms_mm", "dynamic_offset_correlation",
                         "triangulate_fps", "dense_fit_fps"});
  }
  if (metrics.contains("dynamics")) {
    const Json& dynamics = metrics["dynamics"];
    const Json& setup = dynamics["setup"];
    html += "<h2>Secondary dynamics removal at a frequency never trained on</h2>";
    html += fmt::format(
        "<p>Removal network F trained on platform takes at {} Hz ({} takes, {} "
        "epochs); mean error over the jiggling vertices (mm).</p>",
        Escape(setup["train_hz"].dump()), setup["training_takes"].dump(),
        setup["removal_epochs"].dump());
    for (const Json& entry : dynamics["removal"]) {
      html += SvgBarChart(entry["take"].get<std::string>() + " (mean true offset " +
                              fmt::format("{:.3f}", entry["mean_dynamic_offset_mm"].get<double>()) +
                              " mm)",
                          RemovalBars(entry), "mm");
      html += "<br>";
    }
    if (dynamics.contains("removal_by_training_frequencies")) {
      const Json& fig5 = dynamics["removal_by_training_frequencies"];
      std::vector<std::pair<std::string, double>> bars;
      for (const Json& subset : fig5["subsets"]) {
        std::string label = "F on";
        for (const Json& hz : subset["train_hz"]) label += fmt::format(" {:g}", hz.get<double>());
        bars.emplace_back(label + " Hz", subset["jiggle_mean_mm"].get<double>());
      }
      for (const auto& [name, value] : fig5["baselines"].items()) {
        bars.emplace_back(name, value.get<double>());
      }
      html += "<h3>Error against the number of training frequencies (paper Fig. 5)</h3>" +
              SvgBarChart(fig5["take"].get<std::string>() + ", never trained on", bars, "mm");
    }
    if (dynamics.contains("synthesis")) {
      html +=
          "<h2>Remove, then resynthesise (paper Fig. 7)</h2><table><tr><th>take</th>"
          "<th>mean dynamic offset mm</th><th>resynthesis residual mm</th><th>relative</th></tr>";
      for (const Json& entry : dynamics["synthesis"]["takes"]) {
        html += fmt::format("<tr><td>{}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.1f}%</td></tr>",
                            Escape(entry["take"].get<std::string>()),
                            entry["mean_dynamic_offset_mm"].get<double>(),
                            entry["resynthesis_residual_mm"].get<double>(),
                            100 * entry["relative_to_offset"].get<double>());
      }
      html += "</table>";
    }
  }
  if (metrics.contains("end_to_end")) {
    std::vector<std::pair<std::string, double>> bars;
    for (const auto& [name, figures] : metrics["end_to_end"]["methods"].items()) {
      bars.emplace_back(name, figures["mean_mm"].get<double>());
    }
    html +=
        "<h2>End to end: cameras, reconstruction, removal</h2><p>The 11 Hz take filmed by the "
        "simulated cameras and reconstructed, its dynamics removed by F; mean error over the "
        "face against the exact quasistatic of the simulation that was filmed.</p>" +
        SvgBarChart("reconstructed neutral@11Hz", bars, "mm");
  }
  if (metrics.contains("renders")) {
    const Json& renders = metrics["renders"];
    html += "<h2>Signed dynamic offset, " + Escape(renders["take"].get<std::string>()) +
            "</h2><p>Red: out of the skin, green: into it, saturating at &plusmn;" +
            fmt::format("{:g}", renders["range_mm"].get<double>()) +
            " mm (as in Zoss et al. 2020). Rendered by facedyn.</p><table>";
    // One row per frame, one column per view, in the order the demo rendered them.
    int last_frame = -1;
    for (const Json& image : renders["images"]) {
      std::ifstream in(image["path"].get<std::string>(), std::ios::binary);
      const std::vector<unsigned char> png((std::istreambuf_iterator<char>(in)),
                                           std::istreambuf_iterator<char>());
      if (png.empty()) {
        return DataLossError(image["path"].get<std::string>() + ": render missing or empty");
      }
      const int frame = image["frame"].get<int>();
      if (frame != last_frame) {
        html += (last_frame >= 0 ? "</tr>" : "") + fmt::format("<tr><td>frame {}</td>", frame);
        last_frame = frame;
      }
      html += fmt::format(
          "<td><figure style=\"margin:2px\"><img alt=\"{0}\" src=\"data:image/png;base64,{1}\">"
          "<figcaption>{0}</figcaption></figure></td>",
          Escape(image["view"].get<std::string>()), Base64(png));
    }
    if (last_frame >= 0) html += "</tr>";
    html += "</table>";
  }
  if (metrics.contains("stages_s")) {
    std::vector<std::pair<std::string, double>> bars;
    for (const Json& stage : metrics["stages_s"]) {
      bars.emplace_back(stage["stage"].get<std::string>(), stage["seconds"].get<double>());
    }
    html += "<h2>Time per stage</h2>" + SvgBarChart("wall time", bars, "s");
  }
  html += "</body></html>\n";
  std::ofstream out(path, std::ios::binary);
  if (!out) return UnavailableError(path + ": cannot open for writing");
  out << html;
  out.close();
  if (!out) return UnavailableError(path + ": write failed");
  return Status::Ok();
}

}  // namespace facedyn::app
