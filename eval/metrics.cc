#include "eval/metrics.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include "core/check.h"
#include <fmt/format.h>
#include <optional>

#include "dynamics/features.h"

namespace facedyn::eval {

ErrorStats ComputeErrorStats(std::vector<float>* errors_mm) {
  ErrorStats stats;
  std::vector<float>& errors = *errors_mm;
  stats.count = static_cast<long>(errors.size());
  if (errors.empty()) return stats;
  double sum = 0.0;
  float max_error = errors[0];
  for (float e : errors) {
    sum += e;
    max_error = std::max(max_error, e);
  }
  stats.mean_mm = sum / static_cast<double>(errors.size());
  stats.max_mm = max_error;
  const double position = 0.95 * static_cast<double>(errors.size() - 1);
  const size_t lower = static_cast<size_t>(std::floor(position));
  std::nth_element(errors.begin(), errors.begin() + lower, errors.end());
  const double lower_value = errors[lower];
  double upper_value = lower_value;
  if (lower + 1 < errors.size()) {
    upper_value = *std::min_element(errors.begin() + lower + 1, errors.end());
  }
  stats.p95_mm = lower_value + (position - static_cast<double>(lower)) * (upper_value - lower_value);
  return stats;
}

Status EvaluateOptions::Check() const {
  if (truth_channel.empty()) return InvalidArgumentError("EvaluateOptions.truth_channel is empty");
  if (skip_edge_frames < -1) {
    return InvalidArgumentError("EvaluateOptions.skip_edge_frames must be >= 0 (or -1 for the "
                                "window), got " + std::to_string(skip_edge_frames));
  }
  if (!std::isfinite(window_s) || window_s < 0.0 || window_s > 1.0) {
    return InvalidArgumentError("EvaluateOptions.window_s must be in [0, 1] s, got " +
                                std::to_string(window_s));
  }
  return baselines.Check();
}

StatusOr<ErrorReport> ComparePositions(const PointCache& predicted, const PointCache& truth,
                                       const FaceRig* rig, dynamics::FrameRange frames,
                                       const std::string& name) {
  if (predicted.vertex_count != truth.vertex_count) {
    return FailedPreconditionError(name + ": vertex count differs: prediction has " +
                                   std::to_string(predicted.vertex_count) + ", truth has " +
                                   std::to_string(truth.vertex_count));
  }
  if (predicted.frame_count() != truth.frame_count()) {
    return FailedPreconditionError(name + ": frame count differs: prediction has " +
                                   std::to_string(predicted.frame_count()) + ", truth has " +
                                   std::to_string(truth.frame_count()));
  }
  const int vertex_count = truth.vertex_count;
  const int frame_count = truth.frame_count();
  if (rig != nullptr && rig->vertex_count() != vertex_count) {
    return FailedPreconditionError("face rig '" + rig->name + "' has " +
                                   std::to_string(rig->vertex_count()) + " vertices, takes have " +
                                   std::to_string(vertex_count));
  }
  const int first = frames.begin;
  const int end = frames.end;
  if (frames.empty() || first < 0 || end > frame_count) {
    return FailedPreconditionError(fmt::format(
        "{}: take has {} frames: no frames to score in [{}, {})", name, frame_count, first, end));
  }
  const int used_frames = end - first;
  // Per-vertex, per-frame errors, vertex-major so regions gather contiguous runs.
  std::vector<float> errors(static_cast<size_t>(vertex_count) * used_frames);
  for (int t = first; t < end; ++t) {
    const Eigen::Map<const Eigen::Matrix3Xf> p = predicted.Frame(t);
    const Eigen::Map<const Eigen::Matrix3Xf> q = truth.Frame(t);
    for (int v = 0; v < vertex_count; ++v) {
      errors[static_cast<size_t>(v) * used_frames + (t - first)] = (p.col(v) - q.col(v)).norm();
    }
  }
  ErrorReport report;
  report.name = name;
  if (rig != nullptr) {
    std::vector<float> region_errors;
    for (const auto& [region, vertices] : rig->regions) {
      region_errors.clear();
      region_errors.reserve(vertices.size() * used_frames);
      for (int v : vertices) {
        if (v < 0 || v >= vertex_count) {
          return FailedPreconditionError("region '" + region + "' has vertex " + std::to_string(v) +
                                         " outside the take's " + std::to_string(vertex_count));
        }
        const auto begin = errors.begin() + static_cast<std::ptrdiff_t>(v) * used_frames;
        region_errors.insert(region_errors.end(), begin, begin + used_frames);
      }
      report.regions[region] = ComputeErrorStats(&region_errors);
    }
  }
  report.face = ComputeErrorStats(&errors);
  return report;
}

namespace {

Status CheckSameShape(const Take& a, const std::string& a_name, const Take& b,
                      const std::string& b_name) {
  if (a.vertex_count() != b.vertex_count() || a.positions.vertex_count != b.positions.vertex_count) {
    return FailedPreconditionError("vertex count differs: " + a_name + " has " +
                                   std::to_string(a.positions.vertex_count) + ", " + b_name +
                                   " has " + std::to_string(b.positions.vertex_count));
  }
  if (a.frame_count() != b.frame_count()) {
    return FailedPreconditionError("frame count differs: " + a_name + " has " +
                                   std::to_string(a.frame_count()) + ", " + b_name + " has " +
                                   std::to_string(b.frame_count()));
  }
  if (std::abs(a.info.fps - b.info.fps) > 1e-6 * std::max(1.0, b.info.fps)) {
    return FailedPreconditionError("fps differs: " + a_name + " has " + std::to_string(a.info.fps) +
                                   ", " + b_name + " has " + std::to_string(b.info.fps));
  }
  return Status::Ok();
}

Json StatsToJson(const ErrorStats& stats) {
  Json json = Json::object();
  json["mean_mm"] = stats.mean_mm;
  json["p95_mm"] = stats.p95_mm;
  json["max_mm"] = stats.max_mm;
  json["count"] = stats.count;
  return json;
}

}  // namespace

StatusOr<Evaluation> Evaluate(const Take& predicted, const Take& truth, const Take* input,
                              const FaceRig* rig, const EvaluateOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  FACEDYN_RETURN_IF_ERROR(CheckSameShape(predicted, "prediction", truth, "truth"));
  if (input != nullptr) FACEDYN_RETURN_IF_ERROR(CheckSameShape(*input, "input", truth, "truth"));
  const PointCache* truth_positions = &truth.positions;
  if (options.truth_channel != "positions") {
    const auto it = truth.channels.find(options.truth_channel);
    if (it == truth.channels.end()) {
      std::string available;
      for (const auto& [channel, cache] : truth.channels) available += " " + channel;
      return NotFoundError("truth take has no channel '" + options.truth_channel +
                           "' (channels:" + (available.empty() ? " none" : available) +
                           "; use \"positions\" to compare against its positions)");
    }
    truth_positions = &it->second;
  }
  Evaluation evaluation;
  evaluation.truth_channel = options.truth_channel;
  evaluation.frame_count = truth.frame_count();
  evaluation.vertex_count = truth.positions.vertex_count;
  if (options.skip_edge_frames >= 0) {
    evaluation.skip_edge_frames = options.skip_edge_frames;
    evaluation.scored = EdgeSkipped(truth.frame_count(), options.skip_edge_frames);
  } else {
    evaluation.skip_edge_frames = dynamics::WindowFrames(options.window_s, truth.info.fps);
    evaluation.scored = dynamics::ScoredFrames(truth, evaluation.skip_edge_frames);
  }
  FACEDYN_ASSIGN_OR_RETURN(ErrorReport prediction,
                           ComparePositions(predicted.positions, *truth_positions, rig,
                                            evaluation.scored, "prediction"));
  evaluation.reports.push_back(std::move(prediction));
  if (input != nullptr) {
    dynamics::BaselineOptions baseline_options = options.baselines;
    baseline_options.window_s = options.window_s;
    for (dynamics::BaselineKind kind :
         {dynamics::BaselineKind::kNoRemoval, dynamics::BaselineKind::kLowPass, dynamics::BaselineKind::kMovingAverage}) {
      FACEDYN_ASSIGN_OR_RETURN(const PointCache baseline, dynamics::ComputeBaseline(*input, kind, baseline_options));
      FACEDYN_ASSIGN_OR_RETURN(ErrorReport report,
                               ComparePositions(baseline, *truth_positions, rig,
                                                evaluation.scored, dynamics::BaselineName(kind)));
      evaluation.reports.push_back(std::move(report));
    }
    // The oracle: the cutoff of a sweep that is best against this very truth.
    std::optional<ErrorReport> oracle;
    double oracle_hz = 0.0;
    for (double hz = 0.5; hz <= 12.0 + 1e-9 && hz < 0.5 * truth.info.fps; hz += 0.5) {
      FACEDYN_ASSIGN_OR_RETURN(const PointCache filtered, dynamics::LowPassBaseline(*input, hz));
      FACEDYN_ASSIGN_OR_RETURN(ErrorReport report,
                               ComparePositions(filtered, *truth_positions, rig, evaluation.scored,
                                                "lowpass_oracle"));
      if (!oracle || report.face.mean_mm < oracle->face.mean_mm) {
        oracle = std::move(report);
        oracle_hz = hz;
      }
    }
    if (oracle) {
      evaluation.reports.push_back(std::move(*oracle));
      evaluation.oracle_cutoff_hz = oracle_hz;
    }
    evaluation.rule_cutoff_hz = options.baselines.lowpass_cutoff_hz > 0
                                    ? options.baselines.lowpass_cutoff_hz
                                    : dynamics::LowPassCutoffByRule(*input);
  }
  return evaluation;
}

StatusOr<PointCache> BaselinePositions(const Take& input, const Evaluation& evaluation,
                                       const std::string& name,
                                       const dynamics::BaselineOptions& options) {
  if (name == "lowpass_oracle") {
    if (!(evaluation.oracle_cutoff_hz > 0)) {
      return FailedPreconditionError("the evaluation has no low-pass oracle (made without input)");
    }
    return dynamics::LowPassBaseline(input, evaluation.oracle_cutoff_hz);
  }
  for (dynamics::BaselineKind kind : {dynamics::BaselineKind::kNoRemoval,
                                      dynamics::BaselineKind::kLowPass,
                                      dynamics::BaselineKind::kMovingAverage}) {
    if (name == dynamics::BaselineName(kind)) return dynamics::ComputeBaseline(input, kind, options);
  }
  return InvalidArgumentError("no baseline named '" + name + "'");
}

Json EvaluationToJson(const Evaluation& evaluation) {
  Json json = Json::object();
  json["truth_channel"] = evaluation.truth_channel;
  json["frame_count"] = evaluation.frame_count;
  json["vertex_count"] = evaluation.vertex_count;
  json["skip_edge_frames"] = evaluation.skip_edge_frames;
  json["scored_frames"] = {evaluation.scored.begin, evaluation.scored.end};
  if (evaluation.rule_cutoff_hz > 0) json["lowpass_cutoff_hz"] = evaluation.rule_cutoff_hz;
  if (evaluation.oracle_cutoff_hz > 0) json["lowpass_oracle_cutoff_hz"] = evaluation.oracle_cutoff_hz;
  Json reports = Json::object();
  for (const ErrorReport& report : evaluation.reports) {
    Json entry = Json::object();
    entry["face"] = StatsToJson(report.face);
    if (!report.regions.empty()) {
      Json regions = Json::object();
      for (const auto& [region, stats] : report.regions) regions[region] = StatsToJson(stats);
      entry["regions"] = std::move(regions);
    }
    reports[report.name] = std::move(entry);
  }
  json["reports"] = std::move(reports);
  return json;
}

std::string EvaluationToText(const Evaluation& evaluation) {
  std::string text;
  char line[256];
  std::snprintf(line, sizeof(line),
                "truth channel %s, %d vertices, %d frames (scored: frames %d..%d)\n",
                evaluation.truth_channel.c_str(), evaluation.vertex_count, evaluation.frame_count,
                evaluation.scored.begin, evaluation.scored.end - 1);
  text += line;
  std::snprintf(line, sizeof(line), "%-16s %-16s %9s %9s %9s\n", "method", "region", "mean_mm",
                "p95_mm", "max_mm");
  text += line;
  for (const ErrorReport& report : evaluation.reports) {
    auto add = [&](const std::string& region, const ErrorStats& stats) {
      std::snprintf(line, sizeof(line), "%-16s %-16s %9.4f %9.4f %9.4f\n", report.name.c_str(),
                    region.c_str(), stats.mean_mm, stats.p95_mm, stats.max_mm);
      text += line;
    };
    add("face", report.face);
    for (const auto& [region, stats] : report.regions) add(region, stats);
  }
  return text;
}

std::vector<int> JigglingVertices(const PointCache& true_offsets, dynamics::FrameRange frames) {
  Eigen::VectorXd mean_norm = Eigen::VectorXd::Zero(true_offsets.vertex_count);
  for (int t = std::max(0, frames.begin); t < std::min(frames.end, true_offsets.frame_count()); ++t) {
    mean_norm += true_offsets.Frame(t).colwise().norm().transpose().cast<double>();
  }
  std::vector<int> vertices;
  if (mean_norm.size() == 0) return vertices;
  const double threshold = 0.2 * mean_norm.maxCoeff();
  for (int v = 0; v < mean_norm.size(); ++v) {
    if (mean_norm[v] > 0 && mean_norm[v] >= threshold) vertices.push_back(v);
  }
  return vertices;
}

double MeanDistanceOverVertices(const PointCache& a, const PointCache& b,
                                const std::vector<int>& vertices, dynamics::FrameRange frames) {
  FACEDYN_CHECK(a.vertex_count == b.vertex_count && a.frame_count() == b.frame_count(),
                fmt::format("MeanDistanceOverVertices: {} vs {} vertices, {} vs {} frames",
                            a.vertex_count, b.vertex_count, a.frame_count(), b.frame_count()));
  FACEDYN_CHECK(frames.begin >= 0 && frames.end <= a.frame_count(),
                "MeanDistanceOverVertices: frames out of range");
  double sum = 0.0;
  long count = 0;
  for (int t = frames.begin; t < frames.end; ++t) {
    const auto frame_a = a.Frame(t);
    const auto frame_b = b.Frame(t);
    for (int v : vertices) {
      FACEDYN_CHECK(v >= 0 && v < a.vertex_count, "MeanDistanceOverVertices: vertex out of range");
      sum += (frame_a.col(v) - frame_b.col(v)).norm();
    }
    count += static_cast<long>(vertices.size());
  }
  return count > 0 ? sum / count : 0.0;
}

StatusOr<double> JiggleMeanErrorMm(const PointCache& predicted, const Take& simulated,
                                   int window_frames) {
  for (const char* channel : {"quasistatic", "dynamic_offset"}) {
    if (simulated.channels.count(channel) == 0) {
      return FailedPreconditionError(std::string("the simulated take has no \"") + channel +
                                     "\" channel");
    }
  }
  if (predicted.vertex_count != simulated.vertex_count() ||
      predicted.frame_count() != simulated.frame_count()) {
    return FailedPreconditionError(
        "the prediction has " + std::to_string(predicted.vertex_count) + " vertices and " +
        std::to_string(predicted.frame_count()) + " frames, the simulated take " +
        std::to_string(simulated.vertex_count()) + " and " +
        std::to_string(simulated.frame_count()));
  }
  const dynamics::FrameRange scored = dynamics::ScoredFrames(simulated, window_frames);
  const std::vector<int> jiggle =
      JigglingVertices(simulated.channels.at("dynamic_offset"), scored);
  return MeanDistanceOverVertices(predicted, simulated.channels.at("quasistatic"), jiggle, scored);
}

double ExpressionSkinRmsMm(const FaceRig& rig, const Eigen::VectorXd& weights,
                           const Eigen::VectorXd& reference) {
  const size_t shapes = rig.blendshape_deltas_mm.size();
  FACEDYN_CHECK(static_cast<size_t>(weights.size()) == shapes &&
                    static_cast<size_t>(reference.size()) == shapes,
                "one weight per blendshape");
  Eigen::Matrix3Xd difference = Eigen::Matrix3Xd::Zero(3, rig.vertex_count());
  for (size_t k = 0; k < shapes; ++k)
    difference += (weights[k] - reference[k]) * rig.blendshape_deltas_mm[k];
  return std::sqrt(difference.colwise().squaredNorm().mean());
}

double Percentile95(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const size_t k = static_cast<size_t>(std::ceil(0.95 * values.size())) - 1;
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[k];
}

DetailErrors ScoreDetail(const std::vector<Eigen::Matrix3Xd>& result,
                         const std::vector<Eigen::Matrix3Xd>& truth, const std::vector<int>& lips) {
  FACEDYN_CHECK(result.size() == truth.size(), "ScoreDetail: frame counts differ");
  std::vector<double> face, lip;
  for (size_t f = 0; f < truth.size(); ++f) {
    FACEDYN_CHECK(result[f].cols() == truth[f].cols(), "ScoreDetail: vertex counts differ");
    const Eigen::VectorXd e = (result[f] - truth[f]).colwise().norm().transpose();
    face.insert(face.end(), e.data(), e.data() + e.size());
    for (int v : lips) {
      FACEDYN_CHECK(v >= 0 && v < e.size(), "ScoreDetail: a lip vertex is out of range");
      lip.push_back(e[v]);
    }
  }
  auto mean = [](const std::vector<double>& values) {
    double sum = 0;
    for (double x : values) sum += x;
    return values.empty() ? 0.0 : sum / values.size();
  };
  DetailErrors errors;
  errors.face_mean_mm = mean(face);
  errors.lips_mean_mm = mean(lip);
  errors.face_p95_mm = Percentile95(std::move(face));
  errors.lips_p95_mm = Percentile95(std::move(lip));
  return errors;
}

Json DetailErrorsJson(const DetailErrors& errors) {
  return {{"face_mean_mm", errors.face_mean_mm},
          {"face_p95_mm", errors.face_p95_mm},
          {"lips_mean_mm", errors.lips_mean_mm},
          {"lips_p95_mm", errors.lips_p95_mm}};
}

}  // namespace facedyn::eval
