#include "report/report.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "core/json_io.h"
#include "report/face_render.h"

namespace facedyn::report {

std::string EscapeHtml(const std::string& text) {
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

std::string SvgBarChart(const std::string& title,
                        const std::vector<std::pair<std::string, double>>& bars,
                        const std::string& unit) {
  const int label_w = 330, bar_w = 360, row_h = 22, top = 28;
  const int height = top + row_h * static_cast<int>(bars.size()) + 8;
  double max_value = 0;
  for (const auto& bar : bars) {
    if (std::isfinite(bar.second)) max_value = std::max(max_value, bar.second);
  }
  if (max_value <= 0) max_value = 1;
  std::string svg = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" role=\"img\">"
      "<text x=\"4\" y=\"18\" font-size=\"14\" font-weight=\"bold\">{}</text>",
      label_w + bar_w + 90, height, EscapeHtml(title));
  for (size_t k = 0; k < bars.size(); ++k) {
    const int y = top + static_cast<int>(k) * row_h;
    const double value = bars[k].second;
    const bool finite = std::isfinite(value) && value >= 0;
    const int w =
        finite ? std::max(1, static_cast<int>(bar_w * std::min(value, max_value) / max_value)) : 0;
    // The methods learned from the capture (F..., H..., modal...) in red, everything they are
    // compared with in grey.
    const std::string& label = bars[k].first;
    const bool network = ((label.rfind("F", 0) == 0 || label.rfind("H", 0) == 0) &&
                          (label.size() == 1 || label[1] == '_' || label[1] == ' ')) ||
                         label.rfind("modal", 0) == 0;
    svg += fmt::format(
        "<text x=\"{}\" y=\"{}\" font-size=\"12\" text-anchor=\"end\">{}</text>"
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"{}\"/>"
        "<text x=\"{}\" y=\"{}\" font-size=\"12\">{} {}</text>",
        label_w - 6, y + 14, EscapeHtml(label), label_w, y + 2, w, row_h - 6,
        network ? "#c0392b" : "#7f8c8d", label_w + w + 6, y + 14,
        finite ? fmt::format("{:.3f}", value) : std::string("n/a"), EscapeHtml(unit));
  }
  svg += "</svg>";
  return svg;
}

namespace {

// A "nice" tick step (1, 2 or 5 times a power of ten) giving about `target` ticks over `span`.
double TickStep(double span, int target) {
  if (!(span > 0)) return 1.0;
  const double raw = span / target;
  const double power = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0}) {
    if (m * power >= raw) return m * power;
  }
  return 10.0 * power;
}

}  // namespace

std::string SvgLinePlot(const std::string& title, const std::string& x_label,
                        const std::string& y_label, const std::vector<SvgSeries>& series,
                        const std::vector<std::pair<double, double>>& shaded) {
  const int width = 880, height = 340, left = 60, right = 180, top = 30, bottom = 45;
  const int plot_w = width - left - right, plot_h = height - top - bottom;
  double x_lo = INFINITY, x_hi = -INFINITY, y_lo = INFINITY, y_hi = -INFINITY;
  for (const SvgSeries& line : series) {
    const size_t n = std::min(line.x.size(), line.y.size());
    for (size_t k = 0; k < n; ++k) {
      if (!std::isfinite(line.x[k]) || !std::isfinite(line.y[k])) continue;
      x_lo = std::min(x_lo, line.x[k]);
      x_hi = std::max(x_hi, line.x[k]);
      y_lo = std::min(y_lo, line.y[k]);
      y_hi = std::max(y_hi, line.y[k]);
    }
  }
  if (!(x_hi > x_lo)) x_lo = 0, x_hi = 1;
  if (!(y_hi >= y_lo)) y_lo = 0, y_hi = 1;
  if (y_lo >= 0) y_lo = 0;
  if (!(y_hi > y_lo)) y_hi = y_lo + 1;
  const double y_step = TickStep(y_hi - y_lo, 6), x_step = TickStep(x_hi - x_lo, 10);
  y_hi = std::ceil(y_hi / y_step) * y_step;
  auto px = [&](double x) { return left + plot_w * (x - x_lo) / (x_hi - x_lo); };
  auto py = [&](double y) { return top + plot_h * (1.0 - (y - y_lo) / (y_hi - y_lo)); };
  std::string svg = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" role=\"img\">"
      "<text x=\"4\" y=\"18\" font-size=\"14\" font-weight=\"bold\">{}</text>",
      width, height, EscapeHtml(title));
  for (const auto& [a, b] : shaded) {
    if (!std::isfinite(a) || !std::isfinite(b) || b <= a) continue;
    svg +=
        fmt::format("<rect x=\"{:.1f}\" y=\"{}\" width=\"{:.1f}\" height=\"{}\" fill=\"#eaf2fb\"/>",
                    px(a), top, px(b) - px(a), plot_h);
  }
  for (double y = y_lo; y <= y_hi + 1e-9 * y_step; y += y_step) {
    svg += fmt::format(
        "<line x1=\"{}\" y1=\"{:.1f}\" x2=\"{}\" y2=\"{:.1f}\" stroke=\"#ddd\"/>"
        "<text x=\"{}\" y=\"{:.1f}\" font-size=\"11\" text-anchor=\"end\">{:g}</text>",
        left, py(y), left + plot_w, py(y), left - 5, py(y) + 4, std::round(y / y_step) * y_step);
  }
  for (double x = std::ceil(x_lo / x_step) * x_step; x <= x_hi + 1e-9 * x_step; x += x_step) {
    svg += fmt::format(
        "<line x1=\"{:.1f}\" y1=\"{}\" x2=\"{:.1f}\" y2=\"{}\" stroke=\"#999\"/>"
        "<text x=\"{:.1f}\" y=\"{}\" font-size=\"11\" text-anchor=\"middle\">{:g}</text>",
        px(x), top + plot_h, px(x), top + plot_h + 4, px(x), top + plot_h + 16,
        std::round(x / x_step) * x_step);
  }
  svg += fmt::format(
      "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#555\"/>"
      "<text x=\"{}\" y=\"{}\" font-size=\"12\" text-anchor=\"middle\">{}</text>"
      "<text x=\"14\" y=\"{}\" font-size=\"12\" text-anchor=\"middle\" "
      "transform=\"rotate(-90 14 {})\">{}</text>",
      left, top, plot_w, plot_h, left + plot_w / 2, height - 8, EscapeHtml(x_label),
      top + plot_h / 2, top + plot_h / 2, EscapeHtml(y_label));
  int legend_row = 0;
  for (const SvgSeries& line : series) {
    const size_t n = std::min(line.x.size(), line.y.size());
    std::string points;
    auto flush = [&] {
      if (points.empty()) return;
      svg +=
          fmt::format("<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"{}\"{} points=\"{}\"/>",
                      EscapeHtml(line.colour), line.width_px,
                      line.dashed ? " stroke-dasharray=\"6 4\"" : "", points);
      points.clear();
    };
    for (size_t k = 0; k < n; ++k) {
      if (!std::isfinite(line.x[k]) || !std::isfinite(line.y[k])) {
        flush();
        continue;
      }
      points += fmt::format("{:.1f},{:.1f} ", px(line.x[k]), py(line.y[k]));
    }
    flush();
    const int ly = top + 10 + 18 * legend_row++;
    svg += fmt::format(
        "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{}\" stroke-width=\"{}\"{}/>"
        "<text x=\"{}\" y=\"{}\" font-size=\"12\">{}</text>",
        left + plot_w + 10, ly, left + plot_w + 34, ly, EscapeHtml(line.colour),
        std::max(2.0, line.width_px), line.dashed ? " stroke-dasharray=\"6 4\"" : "",
        left + plot_w + 40, ly + 4, EscapeHtml(line.name));
  }
  svg += "</svg>";
  return svg;
}

namespace {

// A number from a JSON object, NaN when the field is missing or not a number: the report draws
// whatever the metrics hold and shows gaps instead of failing.
double Number(const Json& object, const std::string& key) {
  if (!object.is_object() || !object.contains(key) || !object[key].is_number()) return NAN;
  return object[key].get<double>();
}

std::string Text(const Json& object, const std::string& key) {
  if (!object.is_object() || !object.contains(key)) return "";
  const Json& value = object[key];
  return value.is_string() ? value.get<std::string>()
                           : value.dump(-1, ' ', false, kJsonReplaceInvalidUtf8);
}

const Json& Field(const Json& object, const std::string& key) {
  static const Json kNull;
  return object.is_object() && object.contains(key) ? object[key] : kNull;
}

std::vector<double> Numbers(const Json& array) {
  std::vector<double> values;
  if (!array.is_array()) return values;
  for (const Json& v : array) values.push_back(v.is_number() ? v.get<double>() : NAN);
  return values;
}

// A two-column table of the fields of a JSON object, in the order of `keys`.
std::string FieldTable(const Json& object, const std::vector<std::string>& keys) {
  std::string table = "<table>";
  for (const std::string& key : keys) {
    if (!object.is_object() || !object.contains(key)) continue;
    const Json& value = object[key];
    table +=
        "<tr><td>" + EscapeHtml(key) + "</td><td>" +
        (value.is_number_float() ? fmt::format("{:.4g}", value.get<double>())
         : value.is_string()     ? EscapeHtml(value.get<std::string>())
                             : EscapeHtml(value.dump(-1, ' ', false, kJsonReplaceInvalidUtf8))) +
        "</td></tr>";
  }
  return table + "</table>";
}

// Platform frequency against time over the sweep: target per step (from the step's start to the
// end of its hold), the sensor's reading and the simulator's true frequency; holds shaded.
std::string RigPlot(const Json& rig) {
  const Json& series = Field(rig, "time_series");
  if (!series.is_object()) return "";
  SvgSeries target{"target", "#222", {}, {}, true, 1.5};
  for (const Json& step : Field(rig, "steps")) {
    const double start = Number(step, "start_s"), end = Number(step, "hold_end_s");
    target.x.insert(target.x.end(), {start, end, NAN});
    target.y.insert(target.y.end(), {Number(step, "target_hz"), Number(step, "target_hz"), NAN});
  }
  std::vector<std::pair<double, double>> holds;
  for (const Json& step : Field(rig, "steps")) {
    holds.emplace_back(Number(step, "hold_start_s"), Number(step, "hold_end_s"));
  }
  const std::vector<double> t = Numbers(Field(series, "t_s"));
  return SvgLinePlot(
      "Platform frequency during the sweep (holds shaded)", "time since the sweep started (s)",
      "platform frequency (Hz)",
      {SvgSeries{"measured (sensor)", "#2e86c1", t, Numbers(Field(series, "measured_hz")), false,
                 1.5},
       SvgSeries{"true (simulator)", "#c0392b", t, Numbers(Field(series, "true_hz")), false, 1.5},
       target},
      holds);
}

// The figures a removal chart's bars are read against: the mean true offset (no removal) and,
// on reconstructed takes, Eq. 7 with the exact offsets in the estimated skull frame.
std::string RemovalChartNote(const Json& removal) {
  std::string note =
      fmt::format(" (mean true offset {:.3f} mm", Number(removal, "mean_dynamic_offset_mm"));
  if (removal.contains("exact_offsets_removed_mm")) {
    note += fmt::format(", Eq. 7 with the exact offsets in the estimated skull frame {:.3f} mm",
                        Number(removal, "exact_offsets_removed_mm"));
  }
  return note + ")";
}

// Bars for a removal entry's methods; the learned ones (F, the modal model) first, then the
// baselines.
std::vector<std::pair<std::string, double>> MethodBars(const Json& methods,
                                                       const std::string& figure) {
  std::vector<std::pair<std::string, double>> bars;
  if (!methods.is_object()) return bars;
  for (const auto& [method, figures] : methods.items()) {
    bars.emplace_back(method, Number(figures, figure));
  }
  std::stable_sort(bars.begin(), bars.end(), [](const auto& a, const auto& b) {
    auto network = [](const std::string& label) {
      return label == "F" || label.rfind("F_", 0) == 0 || label.rfind("modal", 0) == 0;
    };
    return network(a.first) > network(b.first);
  });
  return bars;
}

std::string Fig5Chart(const Json& fig5, const std::string& title) {
  std::vector<std::pair<std::string, double>> bars;
  for (const Json& subset : Field(fig5, "subsets")) {
    std::string label = "F on";
    for (double hz : Numbers(Field(subset, "train_hz"))) label += fmt::format(" {:g}", hz);
    bars.emplace_back(label + " Hz", Number(subset, "jiggle_mean_mm"));
  }
  for (const auto& [name, value] : Field(fig5, "baselines").items()) {
    bars.emplace_back(name, value.is_number() ? value.get<double>() : NAN);
  }
  return SvgBarChart(title, bars, "mm");
}

std::string DynamicsSection(const Json& dynamics) {
  const Json& setup = Field(dynamics, "setup");
  std::string html = "<h2 id=\"dynamics\">Secondary dynamics, trained on reconstructed takes</h2>";
  html += fmt::format(
      "<p>Subject A held {} on the platform at {} Hz ({} takes of {} s). Every take was "
      "simulated and filmed: rendered by the 8 simulated cameras, its dots detected in the "
      "images and reconstructed (the training takes and walks, the held-out take of the "
      "reconstruction section, the test walk and the speech performance). {} "
      "The removal network F was "
      "trained on the reconstructed takes with {} targets ({} epochs), "
      "the synthesis network H on those takes decomposed by F ({} epochs). Errors are against the "
      "simulator's exact truth, in mm, over the vertices where the face jiggles.</p>",
      dynamics.contains("replicates_note")
          ? EscapeHtml(Text(dynamics, "replicates_note"))
          : "One seed: differences here are not comparisons (facedyn demo --seeds 1,2,3 "
            "replicates this stage; see the README).",
      EscapeHtml(Text(setup, "expressions")), EscapeHtml(Text(setup, "train_hz")),
      EscapeHtml(Text(setup, "training_takes")), EscapeHtml(Text(setup, "seconds_per_take")),
      EscapeHtml(Text(setup, "targets")), EscapeHtml(Text(setup, "removal_epochs")),
      EscapeHtml(Text(setup, "synthesis_epochs")));
  const Json& reconstruction = Field(dynamics, "reconstruction");
  if (reconstruction.is_array() && !reconstruction.empty()) {
    html +=
        "<details><summary>Reconstruction of the training takes</summary><table><tr><th>subject"
        "</th><th>take</th><th>frames</th><th>sample RMS mm</th><th>dense fit frames/s</th></tr>";
    for (const Json& entry : reconstruction) {
      html +=
          fmt::format("<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.3f}</td><td>{:.1f}</td></tr>",
                      EscapeHtml(Text(entry, "subject")), EscapeHtml(Text(entry, "take")),
                      EscapeHtml(Text(entry, "frames")), Number(entry, "sample_rms_mm"),
                      Number(entry, "dense_fit_fps"));
    }
    html += "</table></details>";
  }
  const Json& removal = Field(dynamics, "removal");
  if (removal.is_object()) {
    html += std::string("<h3>Removal at a platform frequency never trained on</h3>") +
            "<p>Error against the simulator's exact quasistatic over the jiggling vertices, "
            "on the scored frames (after the take's hold start and the window). The lower "
            "reference is Eq. 7 with the exact offsets applied in the skull frame the "
            "reconstruction estimated: what a perfect F would leave. The low-pass cutoff is set "
            "by a rule that needs no truth; lowpass_oracle is the best cutoff against the truth, "
            "which no user could set. modal is the removal by the modal model "
            "(dynamics/modal_synthesis.h, trained on the same held takes), which predicts the "
            "offsets from the skull's motion; modal_lowpass follows it with the low-pass whose "
            "cutoff its own leave-one-take-out error calls for. These bars are one seed: a "
            "difference here is not a comparison.</p>" +
            SvgBarChart(Text(removal, "take") + RemovalChartNote(removal),
                        MethodBars(Field(removal, "methods"), "jiggle_mean_mm"), "mm");
  }
  const Json& performance = Field(dynamics, "removal_performance");
  if (performance.is_object()) {
    html += "<h3>Removal from a performance (changing expression) at that frequency</h3>" +
            SvgBarChart(Text(performance, "take") + RemovalChartNote(performance),
                        MethodBars(Field(performance, "methods"), "jiggle_mean_mm"), "mm");
  }
  const Json& walk_removal = Field(dynamics, "removal_walk");
  if (walk_removal.is_object()) {
    html += std::string(
                "<h3>Removal from a new head motion (a walk at a step rate never trained "
                "on)</h3>") +
            "<p>A walk's dynamics lie at the step rate and its first harmonics, inside the band a "
            "low-pass filter must keep for the performance; the platform's frequencies lie "
            "above it.</p>" +
            SvgBarChart(Text(walk_removal, "take") + RemovalChartNote(walk_removal),
                        MethodBars(Field(walk_removal, "methods"), "jiggle_mean_mm"), "mm");
  }
  const Json& fig5 = Field(dynamics, "removal_by_training_frequencies");
  if (fig5.is_object()) {
    html += "<h3>Removal error against the number of training frequencies (paper Fig. 5)</h3>" +
            Fig5Chart(fig5, Text(fig5, "take") + ", never trained on");
  }
  const Json& synthesis = Field(dynamics, "synthesis");
  if (synthesis.is_object()) {
    html += "<h3>Synthesis residuals</h3>";
    // Fig. 7 on the held-out take and on the held-out performance, where the demo has one.
    for (const char* key : {"resynthesis", "resynthesis_performance"}) {
      const Json& resynthesis = Field(synthesis, key);
      if (!resynthesis.is_object()) continue;
      std::vector<std::pair<std::string, double>> bars = {
          {"H resynthesis residual", Number(resynthesis, "resynthesis_residual_mm")}};
      if (resynthesis.contains("modal_resynthesis_residual_mm")) {
        bars.emplace_back("modal resynthesis residual",
                          Number(resynthesis, "modal_resynthesis_residual_mm"));
      }
      if (resynthesis.contains("H_joint_resynthesis_residual_mm")) {  // --joint-training
        bars.emplace_back("F_joint then H_joint residual",
                          Number(resynthesis, "H_joint_resynthesis_residual_mm"));
      }
      bars.emplace_back("removed, not resynthesised",
                        Number(resynthesis, "removed_without_synthesis_mm"));
      bars.emplace_back("true dynamic offset", Number(resynthesis, "mean_dynamic_offset_mm"));
      html += SvgBarChart("Remove with F, then resynthesise (paper Fig. 7): " +
                              Text(resynthesis, "take"),
                          bars, "mm");
    }
    const Json& walk = Field(synthesis, "walk");
    if (walk.is_object()) {
      std::vector<std::pair<std::string, double>> bars = {
          {"H synthesised", Number(Field(Field(walk, "methods"), "H"), "offset_mean_mm")}};
      if (Field(walk, "methods").contains("modal")) {
        bars.emplace_back("modal synthesis",
                          Number(Field(Field(walk, "methods"), "modal"), "offset_mean_mm"));
      }
      bars.emplace_back("no dynamics",
                        Number(Field(Field(walk, "methods"), "no_dynamics"), "offset_mean_mm"));
      html += "<br>" +
              SvgBarChart("New head motion: " + Text(walk, "take") +
                              ", dynamic-offset error vs simulated truth",
                          bars, "mm");
    }
  }
  const Json& retarget = Field(dynamics, "retarget");
  if (retarget.is_object()) {
    html += "<h3>Root-motion retargeting to a second subject (paper Figs. 9-10)</h3><p>" +
            EscapeHtml(Text(retarget, "target")) +
            ", with its own F and H trained on its own reconstructed takes, driven by subject A's "
            "walk; compared with subject B simulated walking the same walk. modal_B_retarget is "
            "B's modal synthesis: a linear response to the skull's accelerations through a fixed "
            "resonator bank, fitted to B's reconstructed held takes (each decomposed by its held "
            "mean), no network.</p>";
    std::vector<std::pair<std::string, double>> bars;
    for (const auto& [name, figures] : Field(retarget, "methods").items()) {
      bars.emplace_back(name, Number(figures, "offset_mean_mm"));
    }
    html +=
        SvgBarChart("dynamic-offset error vs truth (mean true offset " +
                        fmt::format("{:.3f}", Number(retarget, "mean_dynamic_offset_mm")) + " mm)",
                    bars, "mm");
  }
  return html;
}

// The simulated-data reference (eval/dynamics_study.h): F and H on simulated takes.
// `facedyn demo --seeds`: each method's mean and spread over the seeds, and the learned
// method's verdict against each other method under the tie rule (eval/replicates.h).
std::string ReplicatesSection(const Json& replicates) {
  std::string html = fmt::format(
      "<h2 id=\"replicates\">Replicates: the dynamics stage over {} seeds</h2><p>Each seed "
      "draws its own training takes, test performance and walk, and network initialisation "
      "(seeds {}). Mean &plusmn; sample standard deviation, mm; {}: a verdict of "
      "<em>tie</em> is not a win. The 11 Hz held-out take and the simulated-data reference F are "
      "the same in every seed.</p>",
      EscapeHtml(Text(replicates, "replicates")), EscapeHtml(Text(replicates, "seeds")),
      EscapeHtml(Text(replicates, "rule")));
  const std::vector<std::pair<std::string, std::string>> sections = {
      {"removal", "Removal (error against the exact quasistatic, jiggling vertices)"},
      {"resynthesis", "Remove, then resynthesise (Fig. 7)"},
      {"new_motion_synthesis", "Synthesis for a new head motion (offset error)"},
      {"retarget", "Retargeting to subject B (offset error)"}};
  for (const auto& [key, title] : sections) {
    const Json& takes = Field(replicates, key);
    if (!takes.is_array() || takes.empty()) continue;
    html += "<h3>" + EscapeHtml(title) + "</h3>";
    for (const Json& take : takes) {
      html += "<p><strong>" + EscapeHtml(Text(take, "protocol")) +
              "</strong></p><table><tr><th>method</th><th>mean mm</th><th>sd mm</th>"
              "<th>replicates</th><th>verdict of the learned method</th></tr>";
      std::map<std::string, std::string> verdict;
      for (const Json& v : Field(take, "verdicts")) {
        verdict[Text(v, "against")] += (verdict[Text(v, "against")].empty() ? "" : "; ") +
                                       Text(v, "method") + " " + Text(v, "error_is");
      }
      for (const auto& [method, spread] : Field(take, "methods").items()) {
        html +=
            fmt::format("<tr><td>{}</td><td>{:.4f}</td><td>{:.4f}</td><td>{}</td><td>{}</td></tr>",
                        EscapeHtml(method), Number(spread, "mean_mm"), Number(spread, "sd_mm"),
                        EscapeHtml(Text(spread, "replicates")),
                        EscapeHtml(verdict.count(method) ? verdict[method] : ""));
      }
      html += "</table>";
    }
  }
  return html;
}

std::string ReferenceSection(const Json& reference) {
  const Json& setup = Field(reference, "setup");
  std::string html = fmt::format(
      "<h2>Reference: trained on simulated takes with exact targets</h2><p>F trained on "
      "simulated platform takes at {} Hz ({} takes, {} epochs) with the simulator's exact "
      "quasistatic as target, which no capture has; mean error over the jiggling vertices "
      "(mm).</p>",
      EscapeHtml(Text(setup, "train_hz")), EscapeHtml(Text(setup, "training_takes")),
      EscapeHtml(Text(setup, "removal_epochs")));
  for (const Json& entry : Field(reference, "removal")) {
    html += SvgBarChart(Text(entry, "take") + fmt::format(" simulated (mean true offset {:.3f} mm)",
                                                          Number(entry, "mean_dynamic_offset_mm")),
                        MethodBars(Field(entry, "methods"), "jiggle_mean_mm"), "mm") +
            "<br>";
  }
  const Json& fig5 = Field(reference, "removal_by_training_frequencies");
  if (fig5.is_object())
    html += Fig5Chart(fig5, Text(fig5, "take") + " simulated, never trained on");
  const Json& synthesis = Field(reference, "synthesis");
  if (synthesis.is_object()) {
    html +=
        "<table><tr><th>take</th><th>mean dynamic offset mm</th><th>resynthesis residual mm</th>"
        "<th>relative</th></tr>";
    for (const Json& entry : Field(synthesis, "takes")) {
      html += fmt::format("<tr><td>{}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.1f}%</td></tr>",
                          EscapeHtml(Text(entry, "take")), Number(entry, "mean_dynamic_offset_mm"),
                          Number(entry, "resynthesis_residual_mm"),
                          100 * Number(entry, "relative_to_offset"));
    }
    html += "</table>";
  }
  return html;
}

// Rig solving (FDLS) of the reconstructed performance: weight error against the reference per
// marker source and method, and the weight curves of the most active channels.
std::string SolveSection(const Json& solve) {
  std::string html =
      "<h2>Rig solving (FDLS): the reconstructed performance into the puppet's controls</h2><p>" +
      EscapeHtml(Text(solve, "note")) +
      " Reference: " + EscapeHtml(Text(Field(solve, "reference"), "what")) +
      ". Step RMS: frame-to-frame change of the weights, where picked-up jiggle shows.</p>"
      "<table><tr><th>markers from</th><th>method</th><th>weight RMSE</th><th>jaw weight "
      "RMSE</th><th>marker RMSE (mm)</th><th>weight step RMS</th></tr>";
  for (const auto& [key, label] :
       {std::pair<const char*, const char*>{"from_reconstructed", "reconstructed (with jiggle)"},
        {"from_removed", "after removal (F)"}}) {
    for (const char* method : {"network", "network_finetuned"}) {
      const Json& f = Field(Field(solve, key), method);
      html += fmt::format(
          "<tr><td>{}</td><td>{}</td><td>{:.4f}</td><td>{:.4f}</td><td>{:.3f}</td><td>{:.4f}</td>"
          "</tr>",
          label, method, Number(f, "weight_rmse"), Number(f, "jaw_weight_rmse"),
          Number(f, "marker_rmse_mm"), Number(f, "weight_step_rms"));
    }
  }
  html += fmt::format(
      "<tr><td>reference</td><td></td><td></td><td></td><td></td><td>{:.4f}</td>"
      "</tr></table>",
      Number(Field(solve, "reference"), "weight_step_rms"));
  const Json& curves = Field(solve, "curves");
  const std::vector<double> t = Numbers(Field(curves, "time_s"));
  for (const Json& channel : Field(curves, "channels")) {
    html += SvgLinePlot("Weight of '" + Text(channel, "channel") + "' (after fine-tuning)",
                        "time (s)", "weight",
                        {SvgSeries{"reference (exact quasistatic)", "#222", t,
                                   Numbers(Field(channel, "reference")), true, 1.5},
                         SvgSeries{"from the reconstructed take", "#c0392b", t,
                                   Numbers(Field(channel, "from_reconstructed")), false, 1.2},
                         SvgSeries{"after removal (F)", "#2e86c1", t,
                                   Numbers(Field(channel, "from_removed")), false, 1.5}});
  }
  if (solve.contains("driven")) {
    html += "<p>Second character: " + EscapeHtml(Text(solve["driven"], "rig")) +
            " driven by the weights solved after removal, take " +
            EscapeHtml(Text(solve["driven"], "take")) + ".</p>";
  }
  return html;
}

}  // namespace

// Reads a render the demo wrote (a path relative to `base`, the output folder) as base64.
StatusOr<std::string> InlinePng(const Json& image, const std::filesystem::path& base) {
  std::filesystem::path image_file(Text(image, "path"));
  if (image_file.is_relative()) image_file = base / image_file;
  std::ifstream in(image_file, std::ios::binary);
  const std::vector<unsigned char> png((std::istreambuf_iterator<char>(in)),
                                       std::istreambuf_iterator<char>());
  if (png.empty()) return DataLossError(image_file.string() + ": render missing or empty");
  return Base64(png);
}

// Fine detail from a head-mounted camera (app/detail_demo.h).
StatusOr<std::string> DetailSection(const Json& detail, const std::filesystem::path& base) {
  const Json& hmc = Field(detail, "hmc");
  const Json& training = Field(detail, "training");
  std::string html = fmt::format(
      "<h2>Fine detail from a head-mounted camera (Masquerade)</h2><p>A simulated head-mounted "
      "camera (two helmet cameras, {} painted markers) filmed {} frames of {}; "
      "the markers were detected in the rendered images and triangulated in the helmet's frame "
      "({:.0f}% of marker-frames observed, median {:.3f} mm from their true positions; missing "
      "ones held). The upsampler was trained on {} range-of-motion frames ({} selected) "
      "reconstructed on the multi-view rig from {}. Vertex error in mm against the simulator's "
      "skin, skull frame.</p><table><tr><th>method</th><th>face mean</th><th>face p95</th>"
      "<th>lips mean</th><th>lips p95</th></tr>",
      EscapeHtml(Text(hmc, "markers")), EscapeHtml(Text(hmc, "frames")),
      EscapeHtml(Text(hmc, "performance")), 100 * Number(hmc, "observed_fraction"),
      Number(hmc, "marker_error_median_mm"),
      EscapeHtml(Text(training, "rom_frames")), EscapeHtml(Text(training, "selected_frames")),
      EscapeHtml(Text(training, "reconstructed_from")));
  for (const auto& [key, label] : {std::pair<const char*, const char*>{"large_scale_only",
                                                                       "large-scale only"},
                                   {"masquerade", "Masquerade"}}) {
    const Json& e = Field(Field(detail, "methods"), key);
    html += fmt::format(
        "<tr><td>{}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.3f}</td></tr>", label,
        Number(e, "face_mean_mm"), Number(e, "face_p95_mm"), Number(e, "lips_mean_mm"),
        Number(e, "lips_p95_mm"));
  }
  html += "</table>";
  const Json& images = Field(detail, "images");
  if (images.is_array() && !images.empty()) {
    html += fmt::format(
        "<p>Frame {} (the large-scale skin's worst over the lips): shapes, then the signed error "
        "along the normal, red out of the true skin and green into it, saturating at "
        "&plusmn;{:g} mm.</p><table><tr>",
        EscapeHtml(Text(images.front(), "frame")), Number(detail, "range_mm"));
    for (const Json& image : images) {
      FACEDYN_ASSIGN_OR_RETURN(const std::string png, InlinePng(image, base));
      html += fmt::format(
          "<td><figure style=\"margin:2px\"><img alt=\"{0}\" src=\"data:image/png;base64,{1}\">"
          "<figcaption>{0}</figcaption></figure></td>",
          EscapeHtml(Text(image, "view")), png);
    }
    html += "</tr></table>";
  }
  return html;
}

// The subject's physical twin (app/twin_demo.h).
std::string TwinSection(const Json& twin) {
  const Json& fit = Field(twin, "fit");
  std::string html = fmt::format(
      "<h2>The subject's physical twin (after Bao et al. 2018)</h2><p>Subject B's tissue "
      "material fitted to {} reconstructed platform takes (markers and skull pose only; {} "
      "stiffness group(s)). Cheek mode: fitted {:.3f} &plusmn; {:.3f} Hz, damping ratio {:.4f} "
      "&plusmn; {:.4f}; configured in the simulator (never told to the fit) {:.3f} Hz, {:.4f} "
      "({:+.2f}%, {:+.2f}%); the twin's prior {:.3f} Hz, {:.4f}. {}</p>",
      EscapeHtml(Text(fit, "takes")), EscapeHtml(Text(fit, "groups")), Number(fit, "fitted_hz"),
      Number(fit, "fitted_hz_sd"), Number(fit, "fitted_damping_ratio"),
      Number(fit, "fitted_damping_ratio_sd"), Number(fit, "true_hz"),
      Number(fit, "true_damping_ratio"), Number(fit, "hz_error_percent"),
      Number(fit, "damping_error_percent"), Number(fit, "prior_hz"),
      Number(fit, "prior_damping_ratio"), EscapeHtml(Text(fit, "note")));
  const Json& body = Field(twin, "body");
  if (body.contains("fitted_hz")) {
    html += fmt::format(
        "<p>The body between platform and skull (from the skull's motion against the rig's "
        "platform amplitude, {} frequencies): resonance {:.3f} &plusmn; {:.3f} Hz, damping ratio "
        "{:.4f} &plusmn; {:.4f}; configured {:.3f} Hz, {:.4f}.</p>",
        EscapeHtml(Text(body, "frequencies")), Number(body, "fitted_hz"),
        Number(body, "fitted_hz_sd"), Number(body, "fitted_damping_ratio"),
        Number(body, "fitted_damping_ratio_sd"), Number(body, "true_hz"),
        Number(body, "true_damping_ratio"));
  } else if (body.contains("note")) {
    html += "<p>The body between platform and skull: " + EscapeHtml(Text(body, "note")) + ".</p>";
  }
  const Json& training = Field(twin, "training");
  html += fmt::format(
      "<p>Removal under head motions no training take has: F trained on B's {} reconstructed "
      "takes alone, and with {} takes of the twin nodding and shaking (the twin's own exact "
      "quasistatic as targets), the same {} optimiser steps. Error in mm against B's exact "
      "quasistatic over the jiggling vertices; one seed (bench/twin_bench gives the spread "
      "over seeds).</p><table><tr><th>held-out take</th><th>no removal</th>"
      "<th>F, captured takes</th><th>F, with the twin's</th></tr>",
      EscapeHtml(Text(training, "captured_takes")), EscapeHtml(Text(training, "twin_takes")),
      EscapeHtml(Text(training, "optimizer_steps")));
  for (const Json& take : Field(twin, "removal")) {
    const Json& methods = Field(take, "methods");
    html += fmt::format("<tr><td>{}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.3f}</td></tr>",
                        EscapeHtml(Text(take, "take")),
                        Number(Field(methods, "no_removal"), "jiggle_mean_mm"),
                        Number(Field(methods, "F_captured"), "jiggle_mean_mm"),
                        Number(Field(methods, "F_augmented"), "jiggle_mean_mm"));
  }
  html += "</table>";
  if (twin.contains("targeting")) {
    const Json& targeting = twin["targeting"];
    const Json& plain = Field(targeting, "blendshape");
    const Json& fitted = Field(targeting, "twin");
    html += fmt::format(
        "<p>Targeting a held frame (after Bao et al. 2018): B filmed holding {} lying back by {} "
        "degrees, so gravity turned in the skull frame ({:.0f} mm/s&sup2;) and the flesh sagged; "
        "the mean of {} held frames at {} markers fitted by the blendshapes and by the twin (the "
        "expression whose equilibrium under that gravity matches). Both fits use a Cauchy loss "
        "on each marker and correct the skull frame by a small rigid motion; the marker RMS on "
        "the {} markers neither fit treats as a gross error compares them on the same markers."
        "</p><table><tr><th></th>"
        "<th>marker RMS, all (mm)</th><th>marker RMS, common inliers (mm)</th><th>expression vs "
        "configured (mm)</th><th>flesh volume change"
        "</th></tr><tr><td>blendshape fit</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:+.2f}%</td></tr>"
        "<tr><td>twin</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:+.2f}%</td></tr></table>",
        EscapeHtml(Text(targeting, "expression")), EscapeHtml(Text(targeting, "lie_back_deg")),
        Number(targeting, "gravity_change_mm_s2"), EscapeHtml(Text(targeting, "frames")),
        EscapeHtml(Text(targeting, "markers")), EscapeHtml(Text(fitted, "common_inlier_markers")),
        Number(plain, "marker_rms_mm"), Number(plain, "common_inlier_rms_mm"),
        Number(plain, "expression_rms_mm"), 100 * Number(plain, "flesh_volume_change"),
        Number(fitted, "marker_rms_mm"), Number(fitted, "common_inlier_rms_mm"),
        Number(fitted, "expression_rms_mm"), 100 * Number(fitted, "flesh_volume_change"));
  }
  return html;
}

Status WriteDemoReport(const Json& metrics, const std::string& path, const std::string& files_dir) {
  const std::filesystem::path base = files_dir.empty() ? std::filesystem::path(path).parent_path()
                                                       : std::filesystem::path(files_dir);
  std::string html =
      "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>facedyn demo report</title>"
      "<style>body{font-family:sans-serif;max-width:960px;margin:2em auto;color:#222}"
      "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
      "th{background:#f4f4f4}td:first-child{text-align:left}figure img{width:180px}"
      "figcaption{font-size:11px;max-width:180px}</style></head><body>"
      "<h1>facedyn demo report</h1><p>Everything below ran on the simulated stage; errors are "
      "measured against the simulator's exact ground truth. Figures are also in "
      "metrics.json beside this file.</p>";
  if (metrics.contains("rig")) {
    const Json& rig = metrics["rig"];
    html += "<h2>Platform: simulated drive over Modbus TCP, scripted sweep</h2>" + RigPlot(rig) +
            "<table><tr><th>step</th><th>target Hz</th><th>measured Hz</th>"
            "<th>true platform Hz</th><th>max |error| Hz</th><th>hold s</th><th>prompt</th></tr>";
    int index = 0;
    for (const Json& step : Field(rig, "steps")) {
      html += fmt::format(
          "<tr><td>{}</td><td>{:.2f}</td><td>{:.3f}</td><td>{:.3f}</td>"
          "<td>{:.3f}</td><td>{:.1f}</td><td>{}</td></tr>",
          ++index, Number(step, "target_hz"), Number(step, "measured_mean_hz"),
          Number(step, "true_platform_hz"), Number(step, "max_abs_error_hz"),
          Number(step, "hold_s"), EscapeHtml(Text(step, "prompt")));
    }
    html += "</table>";
  }
  if (metrics.contains("capture")) {
    html += "<h2>Capture: simulated trigger-synchronised cameras</h2>" +
            FieldTable(metrics["capture"],
                       {"status", "cameras", "fps", "triggers_requested", "triggers_emitted",
                        "platform_hz_true", "megabytes_written", "megabytes_per_s",
                        "render_frames_per_s_per_thread", "backpressure", "session_complete"});
  }
  if (metrics.contains("reconstruct")) {
    const Json& reconstruct = metrics["reconstruct"];
    html +=
        "<h2>Calibration and reconstruction of the simulated 11 Hz take against ground "
        "truth</h2>"
        "<p>The take was filmed: every frame rendered by the 8 simulated cameras (shaded skin, "
        "painted dots, blur, noise, lens distortion) and its dots detected in the images, then "
        "triangulated, labelled and fitted with the calibrated cameras.</p>";
    const Json& per_camera = Field(reconstruct, "calibration_per_camera");
    if (per_camera.is_array() && !per_camera.empty()) {
      std::vector<std::pair<std::string, double>> bars;
      for (const Json& camera : per_camera) {
        bars.emplace_back(Text(camera, "camera") + " (" + Text(camera, "corners") + " corners)",
                          Number(camera, "rms_px"));
      }
      html += SvgBarChart("Reprojection RMS per camera after bundle adjustment", bars, "px");
    }
    html += FieldTable(
        reconstruct,
        {"calibration_rms_px", "calibration_worst_centre_error_mm", "skull_origin_rms_mm",
         "skull_origin_max_mm", "skull_rotation_rms_deg", "skull_rotation_max_deg",
         "skull_origin_constant_mm", "skull_origin_varying_rms_mm",
         "skull_rotation_varying_rms_deg", "sample_rms_mm",
         "dynamic_offset_correlation", "triangulate_fps", "dense_fit_fps"});
  }
  if (metrics.contains("dynamics")) html += DynamicsSection(metrics["dynamics"]);
  if (metrics.contains("solve")) html += SolveSection(metrics["solve"]);
  if (metrics.contains("detail")) {
    FACEDYN_ASSIGN_OR_RETURN(const std::string section, DetailSection(metrics["detail"], base));
    html += section;
  }
  if (metrics.contains("twin")) html += TwinSection(metrics["twin"]);
  if (metrics.contains("renders")) {
    const Json& renders = metrics["renders"];
    html +=
        "<h2 id=\"renders\">Signed dynamic offset</h2><p>Red: out of the skin, green: into "
        "it, saturating at the &plusmn;range given per row (as in Zoss et al. 2020). Rendered "
        "by facedyn.</p><table>";
    // One row per (group, frame), one column per view, in the order the demo rendered them.
    std::string last_row;
    for (const Json& image : Field(renders, "images")) {
      std::filesystem::path image_file(Text(image, "path"));
      if (image_file.is_relative()) image_file = base / image_file;
      const std::string image_path = image_file.string();
      std::ifstream in(image_path, std::ios::binary);
      const std::vector<unsigned char> png((std::istreambuf_iterator<char>(in)),
                                           std::istreambuf_iterator<char>());
      if (png.empty()) return DataLossError(image_path + ": render missing or empty");
      const std::string group = Text(image, "group");
      const std::string row = group + "\n" + Text(image, "frame");
      if (row != last_row) {
        const double range_mm = std::isfinite(Number(image, "range_mm"))
                                    ? Number(image, "range_mm")
                                    : Number(renders, "range_mm");
        html +=
            (last_row.empty() ? "" : "</tr>") +
            fmt::format("<tr><td>{}{}frame {}<br>&plusmn;{:g} mm</td>", EscapeHtml(group),
                        group.empty() ? "" : "<br>", EscapeHtml(Text(image, "frame")), range_mm);
        last_row = row;
      }
      html += fmt::format(
          "<td><figure style=\"margin:2px\"><img alt=\"{0}\" src=\"data:image/png;base64,{1}\">"
          "<figcaption>{0}</figcaption></figure></td>",
          EscapeHtml(Text(image, "view")), Base64(png));
    }
    if (!last_row.empty()) html += "</tr>";
    html += "</table>";
    // Viewer pages are too large to inline: linked relative to the report, wherever it is.
    if (renders.contains("viewers") && renders["viewers"].is_array() &&
        !renders["viewers"].empty()) {
      html += "<p>Play these takes in the browser (facedyn view; drag to orbit):</p><ul>";
      const std::filesystem::path report_dir = std::filesystem::absolute(path).parent_path();
      for (const Json& viewer : renders["viewers"]) {
        std::filesystem::path page(Text(viewer, "path"));
        if (page.is_relative()) page = std::filesystem::absolute(base / page);
        const std::string link = page.lexically_relative(report_dir).generic_string();
        html += fmt::format("<li><a href=\"{}\">{}</a> ({:.1f} MB){}</li>", EscapeHtml(link),
                            EscapeHtml(Text(viewer, "title")), Number(viewer, "megabytes"),
                            std::filesystem::exists(page) ? "" : " &mdash; <em>missing</em>");
      }
      html += "</ul>";
    }
  }
  if (metrics.contains("dynamics_replicates")) {
    html += ReplicatesSection(metrics["dynamics_replicates"]);
  }
  if (metrics.contains("simulated_reference")) {
    html += ReferenceSection(metrics["simulated_reference"]);
  }
  if (metrics.contains("stages_s")) {
    std::vector<std::pair<std::string, double>> bars;
    for (const Json& stage : metrics["stages_s"]) {
      bars.emplace_back(Text(stage, "stage"), Number(stage, "seconds"));
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

}  // namespace facedyn::report
