#include "eval/replicates.h"

#include <algorithm>
#include <cmath>
#include <map>

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

Json SummariseRemovalReplicates(const std::vector<Json>& studies) {
  // take -> method -> values, in first-seen order of takes.
  std::vector<std::string> take_order;
  std::map<std::string, std::map<std::string, std::vector<double>>> values;
  std::map<std::string, std::string> protocol;
  for (const Json& study : studies) {
    if (!study.contains("removal") || !study["removal"].is_array()) continue;
    for (const Json& take : study["removal"]) {
      if (!take.contains("take") || !take.contains("methods")) continue;
      const std::string name = take["take"].get<std::string>();
      if (values.count(name) == 0) take_order.push_back(name);
      if (take.contains("protocol") && take["protocol"].is_string())
        protocol[name] = take["protocol"].get<std::string>();
      for (const auto& [method, figures] : take["methods"].items()) {
        if (figures.contains("jiggle_mean_mm")) {
          values[name][method].push_back(figures["jiggle_mean_mm"].get<double>());
        }
      }
    }
  }
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
      if (method.rfind("F", 0) != 0) continue;
      for (const auto& [baseline, other] : spreads) {
        if (baseline.rfind("F", 0) == 0) continue;
        verdicts.push_back({{"method", method},
                            {"against", baseline},
                            {"error_is", CompareLowerIsBetter(spread, other)}});
      }
    }
    Json entry = {{"take", name}, {"methods", methods}, {"verdicts", verdicts}};
    if (protocol.count(name)) entry["protocol"] = protocol[name];
    takes.push_back(std::move(entry));
  }
  return {{"replicates", studies.size()},
          {"rule", "a difference within the larger standard deviation is a tie"},
          {"removal", takes}};
}

}  // namespace facedyn::eval
