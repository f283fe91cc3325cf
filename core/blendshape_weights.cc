#include "core/blendshape_weights.h"

#include <fmt/format.h>

#include <cmath>
#include <set>

#include "core/csv.h"
#include "core/file_util.h"

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

}  // namespace facedyn
