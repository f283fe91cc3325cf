#include "core/blendshape_weights.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <set>

#include "core/config_node.h"
#include "core/csv.h"
#include "core/file_util.h"
#include "core/json_io.h"

namespace facedyn {

int BlendshapeWeightsTrack::NameIndex(const std::string& name) const {
  for (size_t i = 0; i < names.size(); ++i) {
    if (names[i] == name) return static_cast<int>(i);
  }
  return -1;
}

Status BlendshapeWeightsTrack::Validate() const {
  if (time_s.empty()) return InvalidArgumentError("blendshape weights: no samples");
  if (weights.rows() != static_cast<Eigen::Index>(time_s.size()) ||
      weights.cols() != static_cast<Eigen::Index>(names.size())) {
    return InvalidArgumentError(fmt::format(
        "blendshape weights: {} x {} weights for {} samples and {} names", weights.rows(),
        weights.cols(), time_s.size(), names.size()));
  }
  std::set<std::string> seen;
  for (const std::string& name : names) {
    if (name.empty() || name.find(',') != std::string::npos) {
      return InvalidArgumentError("blendshape weights: name '" + name + "' is empty or has a comma");
    }
    if (!seen.insert(name).second) {
      return InvalidArgumentError("blendshape weights: the name '" + name + "' appears twice");
    }
  }
  for (size_t s = 0; s < time_s.size(); ++s) {
    if (!std::isfinite(time_s[s]) || (s > 0 && !(time_s[s] > time_s[s - 1]))) {
      return InvalidArgumentError(fmt::format(
          "blendshape weights: sample {} has time {} s, not finite and after the previous one", s,
          time_s[s]));
    }
  }
  if (!weights.allFinite()) return InvalidArgumentError("blendshape weights: a weight is not finite");
  return Status::Ok();
}

StatusOr<BlendshapeWeightsTrack> ReadBlendshapeWeightsCsv(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(const CsvTable table, CsvTable::ReadWithHeader(path));
  const std::vector<std::string>& columns = table.columns();
  if (columns.empty() || columns[0] != "time_s") {
    return DataLossError(path + ": the header's first column must be time_s (then one column per blendshape)");
  }
  BlendshapeWeightsTrack track;
  track.names.assign(columns.begin() + 1, columns.end());
  std::set<std::string> seen;
  for (const std::string& name : track.names) {
    if (name.empty()) return DataLossError(path + ": the header has an empty blendshape name");
    if (!seen.insert(name).second) {
      return DataLossError(path + ": the header names the blendshape '" + name + "' twice");
    }
  }
  if (table.row_count() == 0) return DataLossError(path + ": no samples after the header");
  track.time_s.resize(table.row_count());
  track.weights.resize(static_cast<Eigen::Index>(table.row_count()),
                       static_cast<Eigen::Index>(track.names.size()));
  for (size_t row = 0; row < table.row_count(); ++row) {
    FACEDYN_ASSIGN_OR_RETURN(track.time_s[row], table.Number(row, 0));
    if (row > 0 && !(track.time_s[row] > track.time_s[row - 1])) {
      return table.RowError(row, fmt::format("time_s {} is not after the previous sample's {}",
                                             track.time_s[row], track.time_s[row - 1]));
    }
    for (size_t c = 1; c < columns.size(); ++c) {
      FACEDYN_ASSIGN_OR_RETURN(const double w, table.Number(row, c));
      track.weights(static_cast<Eigen::Index>(row), static_cast<Eigen::Index>(c - 1)) = w;
    }
  }
  return track;
}

Status WriteBlendshapeWeightsCsv(const std::string& path, const BlendshapeWeightsTrack& track) {
  FACEDYN_RETURN_IF_ERROR(track.Validate());
  std::string text = "time_s";
  for (const std::string& name : track.names) text += "," + name;
  text += "\n";
  for (int s = 0; s < track.sample_count(); ++s) {
    // %.9g keeps a double's float-level precision; round-trips what any solve produces.
    text += fmt::format("{:.9g}", track.time_s[s]);
    for (Eigen::Index c = 0; c < track.weights.cols(); ++c) text += fmt::format(",{:.9g}", track.weights(s, c));
    text += "\n";
  }
  return WriteFileAtomic(path, text);
}

namespace {
constexpr char kJsonFormat[] = "facedyn.blendshape_weights";
constexpr int kJsonVersion = 1;
}  // namespace

StatusOr<BlendshapeWeightsTrack> ReadBlendshapeWeightsJson(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode root, ConfigNode::ReadFile(path));
  if (!root.IsMap()) return DataLossError(path + ": expected a JSON object (blendshape weights)");
  FACEDYN_RETURN_IF_ERROR(root.CheckFields({"format", "version", "names", "time_s", "weights"}));
  FACEDYN_ASSIGN_OR_RETURN(const std::string format, root.Get<std::string>("format"));
  if (format != kJsonFormat) {
    return root.Error("format", fmt::format("'{}' is not '{}'", format, kJsonFormat));
  }
  FACEDYN_ASSIGN_OR_RETURN(const int version, root.Get<int>("version"));
  if (version != kJsonVersion) {
    return root.Error(
        "version", fmt::format("{} is not a version this build reads ({})", version, kJsonVersion));
  }
  BlendshapeWeightsTrack track;
  FACEDYN_ASSIGN_OR_RETURN(track.names, root.Get<std::vector<std::string>>("names"));
  FACEDYN_ASSIGN_OR_RETURN(track.time_s, root.Get<std::vector<double>>("time_s"));
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode samples, root.Child("weights"));
  if (!samples.IsSequence()) return samples.Error("expected an array with one array per sample");
  if (samples.size() != track.time_s.size()) {
    return samples.Error(
        fmt::format("{} samples of weights for {} times", samples.size(), track.time_s.size()));
  }
  track.weights.resize(static_cast<Eigen::Index>(track.time_s.size()),
                       static_cast<Eigen::Index>(track.names.size()));
  for (size_t s = 0; s < samples.size(); ++s) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode sample, samples.At(s));
    FACEDYN_ASSIGN_OR_RETURN(const std::vector<double> values, sample.As<std::vector<double>>());
    if (values.size() != track.names.size()) {
      return sample.Error(fmt::format("sample {} has {} weights for {} names", s, values.size(),
                                      track.names.size()));
    }
    for (size_t c = 0; c < values.size(); ++c) {
      track.weights(static_cast<Eigen::Index>(s), static_cast<Eigen::Index>(c)) = values[c];
    }
  }
  const Status valid = track.Validate();
  if (!valid.ok()) return DataLossError(path + ": " + valid.message());
  return track;
}

Status WriteBlendshapeWeightsJson(const std::string& path, const BlendshapeWeightsTrack& track) {
  FACEDYN_RETURN_IF_ERROR(track.Validate());
  // One sample per line: readable and diffable, where a pretty-printed dump would put every
  // number on a line of its own.
  std::string text = "{\"format\": " + Json(kJsonFormat).dump() +
                     ", \"version\": " + std::to_string(kJsonVersion) + ",\n \"names\": " +
                     Json(track.names).dump(-1, ' ', false, kJsonReplaceInvalidUtf8) +
                     ",\n \"time_s\": " + Json(track.time_s).dump() + ",\n \"weights\": [";
  for (int s = 0; s < track.sample_count(); ++s) {
    Json row = Json::array();
    for (Eigen::Index c = 0; c < track.weights.cols(); ++c) row.push_back(track.weights(s, c));
    text += (s == 0 ? "\n  " : ",\n  ") + row.dump();
  }
  text += "\n ]}\n";
  return WriteFileAtomic(path, text);
}

StatusOr<BlendshapeWeightsTrack> ReadBlendshapeWeights(const std::string& path) {
  return LowercaseExtension(path) == ".json" ? ReadBlendshapeWeightsJson(path)
                                             : ReadBlendshapeWeightsCsv(path);
}

}  // namespace facedyn
