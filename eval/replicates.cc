#include "eval/replicates.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <utility>

namespace facedyn::eval {

Spread SpreadOf(const std::vector<double>& values) {
  Spread spread;
  spread.count = static_cast<int>(values.size());
  if (values.empty()) return spread;
  double sum = 0.0;
  for (double v : values) sum += v;
  spread.mean = sum / values.size();
  double squares = 0.0;
  for (double v : values) squares += (v - spread.mean) * (v - spread.mean);
  spread.sd = values.size() > 1 ? std::sqrt(squares / (values.size() - 1)) : 0.0;
  spread.min = *std::min_element(values.begin(), values.end());
  spread.max = *std::max_element(values.begin(), values.end());
  return spread;
}

std::string CompareLowerIsBetter(const Spread& a, const Spread& b) {
  if (a.count < 3 || b.count < 3) return "too few replicates";
  const double margin = std::max(a.sd, b.sd);
  if (a.mean < b.mean - margin) return "lower";
  if (a.mean > b.mean + margin) return "higher";
  return "tie";
}

namespace {

Json SpreadJson(const Spread& s) {
  auto round = [](double x) { return std::round(x * 1e5) / 1e5; };
  return {{"mean_mm", round(s.mean)}, {"sd_mm", round(s.sd)}, {"min_mm", round(s.min)},
          {"max_mm", round(s.max)},   {"replicates", s.count}};
}

}  // namespace

Json SummariseMethodReplicates(const std::vector<Json>& replicates, const std::string& figure,
                               const std::vector<std::string>& learned_prefixes) {
  // take -> method -> values, in first-seen order of takes.
  std::vector<std::string> take_order;
  std::map<std::string, std::map<std::string, std::vector<double>>> values;
  std::map<std::string, std::string> protocol;
  for (const Json& entries : replicates) {
    if (!entries.is_array()) continue;
    for (const Json& take : entries) {
      if (!take.contains("take") || !take.contains("methods")) continue;
      const std::string name = take["take"].get<std::string>();
      if (values.count(name) == 0) take_order.push_back(name);
      if (take.contains("protocol") && take["protocol"].is_string())
        protocol[name] = take["protocol"].get<std::string>();
      for (const auto& [method, figures] : take["methods"].items()) {
        if (figures.contains(figure) && figures[figure].is_number()) {
          values[name][method].push_back(figures[figure].get<double>());
        }
      }
    }
  }
  auto learned = [&](const std::string& method) {
    for (const std::string& prefix : learned_prefixes) {
      if (method.rfind(prefix, 0) == 0) return true;
    }
    return false;
  };
  Json takes = Json::array();
  for (const std::string& name : take_order) {
    Json methods = Json::object();
    std::map<std::string, Spread> spreads;
    for (const auto& [method, list] : values[name]) {
      spreads[method] = SpreadOf(list);
      methods[method] = SpreadJson(spreads[method]);
    }
    Json verdicts = Json::array();
    for (const auto& [method, spread] : spreads) {
      if (!learned(method)) continue;
      for (const auto& [baseline, other] : spreads) {
        if (learned(baseline)) continue;
        verdicts.push_back({{"method", method},
                            {"against", baseline},
                            {"error_is", CompareLowerIsBetter(spread, other)}});
      }
    }
    Json entry = {{"take", name}, {"methods", methods}, {"verdicts", verdicts}};
    if (protocol.count(name)) entry["protocol"] = protocol[name];
    takes.push_back(std::move(entry));
  }
  return takes;
}

Json SummariseRemovalReplicates(const std::vector<Json>& studies) {
  std::vector<Json> replicates;
  for (const Json& study : studies) {
    if (study.contains("removal") && study["removal"].is_array()) {
      replicates.push_back(study["removal"]);
    }
  }
  return {{"replicates", studies.size()},
          {"rule", "a difference within the larger standard deviation is a tie"},
          {"removal", SummariseMethodReplicates(replicates, "jiggle_mean_mm", {"F"})}};
}

namespace {

// One take entry {"take", "protocol", "methods": {name: {"mm": value}}} from named values.
Json Entry(const std::string& take, const std::string& protocol,
           const std::vector<std::pair<std::string, double>>& values) {
  Json methods = Json::object();
  for (const auto& [name, mm] : values) methods[name] = {{"mm", mm}};
  return {{"take", take}, {"protocol", protocol}, {"methods", methods}};
}

double Number(const Json& json, const char* key) {
  return json.contains(key) && json[key].is_number() ? json[key].get<double>() : 0.0;
}

}  // namespace

Json SummariseDemoReplicates(const std::vector<Json>& stages, const std::vector<uint64_t>& seeds) {
  const std::vector<std::pair<const char*, const char*>> removal_sections = {
      {"removal", "held-out platform frequency"},
      {"removal_performance", "held-out performance (speech) at that frequency"},
      {"removal_walk", "held-out motion (a walk at a new step rate)"}};
  std::vector<Json> removal, resynthesis, new_motion, retarget;
  for (const Json& stage : stages) {
    Json removal_entries = Json::array();
    for (const auto& [section, protocol] : removal_sections) {
      if (!stage.contains(section) || !stage[section].contains("methods")) continue;
      const Json& figures = stage[section];
      Json methods = Json::object();
      for (const auto& [method, values] : figures["methods"].items()) {
        if (values.contains("jiggle_mean_mm")) {
          methods[method] = {{"mm", values["jiggle_mean_mm"].get<double>()}};
        }
      }
      // What a perfect F would leave on this reconstruction (eval/skull_frame.h).
      if (figures.contains("exact_offsets_removed_mm")) {
        methods["lower_reference"] = {{"mm", figures["exact_offsets_removed_mm"].get<double>()}};
      }
      // Named by section, not by take: the performance and walk takes differ per seed.
      removal_entries.push_back({{"take", section}, {"protocol", protocol}, {"methods", methods}});
    }
    removal.push_back(std::move(removal_entries));
    if (stage.contains("synthesis")) {
      const Json& synthesis = stage["synthesis"];
      // Fig. 7 on the held-out take and, where the demo has one, on the held-out performance:
      // the residual of F's removal resynthesised by H and by the modal model, beside what
      // removal alone leaves (the dynamics themselves).
      Json figures = Json::array();
      for (const auto& [key, take] :
           {std::pair<const char*, const char*>{"resynthesis", "held-out take"},
            {"resynthesis_performance", "held-out performance (speech)"}}) {
        if (!synthesis.contains(key)) continue;
        const Json& r = synthesis[key];
        std::vector<std::pair<std::string, double>> values = {
            {"H_resynthesis_residual", Number(r, "resynthesis_residual_mm")}};
        if (r.contains("modal_resynthesis_residual_mm"))
          values.emplace_back("modal_resynthesis_residual",
                              Number(r, "modal_resynthesis_residual_mm"));
        if (r.contains("H_joint_resynthesis_residual_mm"))  // the demo's --joint-training
          values.emplace_back("H_joint_resynthesis_residual",
                              Number(r, "H_joint_resynthesis_residual_mm"));
        // The joint training's cross pairings: F_joint then H, F then H_joint.
        for (const char* cross : {"F_joint_then_H", "F_then_H_joint"}) {
          const std::string cross_key = std::string(cross) + "_resynthesis_residual_mm";
          if (r.contains(cross_key)) {
            values.emplace_back(std::string(cross) + "_resynthesis_residual",
                                Number(r, cross_key.c_str()));
          }
        }
        values.emplace_back("removed_without_synthesis", Number(r, "removed_without_synthesis_mm"));
        figures.push_back(Entry(
            take,
            fmt::format("remove, then resynthesise the {} with its own head motion (Fig. 7)", take),
            values));
      }
      if (!figures.empty()) resynthesis.push_back(std::move(figures));
      if (synthesis.contains("walk") && synthesis["walk"].contains("methods")) {
        Json entries = Json::array();
        Json methods = Json::object();
        for (const auto& [method, values] : synthesis["walk"]["methods"].items()) {
          methods[method] = {{"mm", Number(values, "offset_mean_mm")}};
        }
        entries.push_back({{"take", "walk synthesis"},
                           {"protocol", "new head motion, subject A"},
                           {"methods", methods}});
        new_motion.push_back(std::move(entries));
      }
    }
    if (stage.contains("retarget") && stage["retarget"].contains("methods")) {
      Json methods = Json::object();
      for (const auto& [method, values] : stage["retarget"]["methods"].items()) {
        methods[method] = {{"mm", Number(values, "offset_mean_mm")}};
      }
      retarget.push_back(Json::array({{{"take", "B walking A's walk"},
                                       {"protocol", "retargeting between subjects (Figs. 9-10)"},
                                       {"methods", methods}}}));
    }
  }
  return {{"replicates", stages.size()},
          {"seeds", seeds},
          {"rule", "a difference within the larger standard deviation is a tie"},
          {"removal", SummariseMethodReplicates(removal, "mm", {"F", "modal"})},
          {"resynthesis", SummariseMethodReplicates(resynthesis, "mm", {"H", "modal"})},
          {"new_motion_synthesis", SummariseMethodReplicates(new_motion, "mm", {"H", "modal"})},
          {"retarget", SummariseMethodReplicates(retarget, "mm", {"H", "modal"})}};
}

void PrintReplicateSummary(const Json& summary) {
  std::printf("\nReplicates over %s seeds (mean +- sd, mm; %s):\n",
              summary.value("replicates", Json(0)).dump().c_str(),
              summary.value("rule", std::string()).c_str());
  for (const char* section : {"removal", "resynthesis", "new_motion_synthesis", "retarget"}) {
    if (!summary.contains(section) || !summary[section].is_array()) continue;
    for (const Json& take : summary[section]) {
      std::printf("  %s\n", take.value("protocol", take.value("take", std::string())).c_str());
      std::map<std::string, std::string> verdict;
      for (const Json& v : take["verdicts"]) {
        std::string& text = verdict[v["against"].get<std::string>()];
        text += (text.empty() ? "" : "; ") + v["method"].get<std::string>() + " " +
                v["error_is"].get<std::string>();
      }
      for (const auto& [method, spread] : take["methods"].items()) {
        std::printf("    %-30s %8.4f +- %.4f  %s\n", method.c_str(),
                    spread["mean_mm"].get<double>(), spread["sd_mm"].get<double>(),
                    verdict.count(method) ? verdict[method].c_str() : "");
      }
    }
  }
}

}  // namespace facedyn::eval
