#include "solve/solve_io.h"

#include <fmt/format.h>

#include <array>
#include <cctype>
#include <cmath>
#include <map>

#include "core/csv.h"
#include "core/file_util.h"

namespace facedyn::solve {

StatusOr<BlendshapeWeightsTrack> WeightsToTrack(const Puppet& puppet,
                                                const std::vector<double>& time_s,
                                                const Eigen::MatrixXd& weights) {
  if (weights.rows() != puppet.channel_count() ||
      weights.cols() != static_cast<Eigen::Index>(time_s.size())) {
    return InvalidArgumentError(fmt::format("weights: {} x {} for {} channels and {} times",
                                            weights.rows(), weights.cols(), puppet.channel_count(),
                                            time_s.size()));
  }
  BlendshapeWeightsTrack track;
  track.names = puppet.channel_names;
  track.time_s = time_s;
  track.weights = weights.transpose();
  FACEDYN_RETURN_IF_ERROR(track.Validate());
  return track;
}

StatusOr<Eigen::MatrixXd> WeightsFromTrack(const Puppet& puppet,
                                           const BlendshapeWeightsTrack& track,
                                           const std::string& source) {
  Eigen::MatrixXd weights = Eigen::MatrixXd::Zero(puppet.channel_count(), track.sample_count());
  for (size_t column = 0; column < track.names.size(); ++column) {
    const int c = puppet.ChannelIndex(track.names[column]);
    if (c < 0) {
      std::string known;
      for (const std::string& name : puppet.channel_names)
        known += (known.empty() ? "" : ", ") + name;
      return InvalidArgumentError(
          fmt::format("{}: column {} '{}' is not a channel of rig '{}' (channels: {})", source,
                      column + 2, track.names[column], puppet.rig_name, known));
    }
    weights.row(c) = track.weights.col(static_cast<Eigen::Index>(column)).transpose();
  }
  return weights;
}

Status WriteWeightsCsv(const std::string& path, const Puppet& puppet,
                       const std::vector<double>& time_s, const Eigen::MatrixXd& weights) {
  FACEDYN_ASSIGN_OR_RETURN(const BlendshapeWeightsTrack track,
                           WeightsToTrack(puppet, time_s, weights));
  return WriteBlendshapeWeightsCsv(path, track);
}

Status WriteWeightsJson(const std::string& path, const Puppet& puppet,
                        const std::vector<double>& time_s, const Eigen::MatrixXd& weights) {
  FACEDYN_ASSIGN_OR_RETURN(const BlendshapeWeightsTrack track,
                           WeightsToTrack(puppet, time_s, weights));
  return WriteBlendshapeWeightsJson(path, track);
}

std::string WeightsJsonTwinPath(const std::string& csv_path) {
  if (LowercaseExtension(csv_path) == ".csv")
    return csv_path.substr(0, csv_path.size() - 4) + ".json";
  return csv_path + ".json";
}

StatusOr<Eigen::MatrixXd> ReadWeightsCsv(const std::string& path, const Puppet& puppet,
                                         std::vector<double>* time_s) {
  FACEDYN_ASSIGN_OR_RETURN(const BlendshapeWeightsTrack track, ReadBlendshapeWeightsCsv(path));
  if (time_s != nullptr) *time_s = track.time_s;
  return WeightsFromTrack(puppet, track, path);
}

StatusOr<MarkerFrames> ReadMarkersCsv(const std::string& path, const Puppet& puppet) {
  FACEDYN_ASSIGN_OR_RETURN(const CsvTable table, CsvTable::ReadWithHeader(path));
  const std::vector<std::string>& columns = table.columns();
  if (columns.empty() || columns[0] != "time_s") {
    return DataLossError(path +
                         ": the header's first column must be time_s (then <marker>_x,_y,_z)");
  }
  std::map<std::string, size_t> column_of;
  for (size_t i = 1; i < columns.size(); ++i) {
    if (!column_of.emplace(columns[i], i).second) {
      return DataLossError(
          fmt::format("{}: the header names the column '{}' twice", path, columns[i]));
    }
  }
  const int m_count = puppet.marker_count();
  std::vector<std::array<size_t, 3>> marker_columns(m_count);
  std::string missing;
  int missing_count = 0;
  for (int m = 0; m < m_count; ++m) {
    for (int a = 0; a < 3; ++a) {
      const std::string name = puppet.marker_names[m] + "_" + "xyz"[a];
      const auto it = column_of.find(name);
      if (it == column_of.end()) {
        if (missing_count < 8) missing += (missing.empty() ? "" : ", ") + name;
        ++missing_count;
        continue;
      }
      marker_columns[m][a] = it->second;
    }
  }
  if (missing_count > 0) {
    return DataLossError(fmt::format("{}: {} marker columns of rig '{}' are missing: {}{}", path,
                                     missing_count, puppet.rig_name, missing,
                                     missing_count > 8 ? ", ..." : ""));
  }
  const size_t n = table.row_count();
  if (n == 0) return DataLossError(path + ": no frames");
  MarkerFrames frames;
  frames.time_s.resize(n);
  frames.markers_in_skull = Eigen::MatrixXd::Zero(3 * m_count, static_cast<Eigen::Index>(n));
  frames.present = MarkerPresence::Constant(m_count, static_cast<Eigen::Index>(n), true);
  for (size_t row = 0; row < n; ++row) {
    FACEDYN_ASSIGN_OR_RETURN(frames.time_s[row], table.Number(row, 0));
    if (row > 0 && !(frames.time_s[row] > frames.time_s[row - 1])) {
      return table.RowError(row, fmt::format("time_s {} is not after the previous row's {}",
                                             frames.time_s[row], frames.time_s[row - 1]));
    }
    for (int m = 0; m < m_count; ++m) {
      int empty = 0;
      for (int a = 0; a < 3; ++a) empty += table.Text(row, marker_columns[m][a]).empty() ? 1 : 0;
      if (empty == 3) {
        frames.present(m, static_cast<Eigen::Index>(row)) = false;
        continue;
      }
      if (empty != 0) {
        return table.RowError(
            row, fmt::format("marker '{}' has {} of its 3 coordinates empty (all or none)",
                             puppet.marker_names[m], empty));
      }
      for (int a = 0; a < 3; ++a) {
        FACEDYN_ASSIGN_OR_RETURN(frames.markers_in_skull(3 * m + a, static_cast<Eigen::Index>(row)),
                                 table.Number(row, marker_columns[m][a]));
      }
    }
  }
  return frames;
}

Status WriteMarkersCsv(const std::string& path, const Puppet& puppet, const MarkerFrames& frames) {
  const Eigen::Index n = static_cast<Eigen::Index>(frames.time_s.size());
  if (frames.markers_in_skull.rows() != 3 * puppet.marker_count() ||
      frames.markers_in_skull.cols() != n || frames.present.rows() != puppet.marker_count() ||
      frames.present.cols() != n) {
    return InvalidArgumentError("markers CSV: frames do not match the puppet's markers");
  }
  std::string text = "time_s";
  for (const std::string& name : puppet.marker_names)
    text += "," + name + "_x," + name + "_y," + name + "_z";
  text += "\n";
  for (Eigen::Index f = 0; f < n; ++f) {
    text += fmt::format("{:.9g}", frames.time_s[f]);
    for (int m = 0; m < puppet.marker_count(); ++m) {
      for (int a = 0; a < 3; ++a) {
        text += frames.present(m, f) ? fmt::format(",{:.9g}", frames.markers_in_skull(3 * m + a, f))
                                     : ",";
      }
    }
    text += "\n";
  }
  return WriteFileAtomic(path, text);
}

StatusOr<MarkerFrames> MarkersFromTake(const Puppet& puppet, const FaceRig& rig, const Take& take,
                                       const std::string& channel) {
  if (static_cast<int>(rig.markers.size()) != puppet.marker_count()) {
    return InvalidArgumentError(fmt::format("rig '{}' has {} markers, the solver's puppet '{}' {}",
                                            rig.name, rig.markers.size(), puppet.rig_name,
                                            puppet.marker_count()));
  }
  for (int m = 0; m < puppet.marker_count(); ++m) {
    if (rig.markers[m].name != puppet.marker_names[m]) {
      return InvalidArgumentError(
          fmt::format("rig '{}' marker {} is '{}', the solver's puppet expects '{}'", rig.name, m,
                      rig.markers[m].name, puppet.marker_names[m]));
    }
  }
  if (take.vertex_count() != rig.vertex_count()) {
    return InvalidArgumentError(
        fmt::format("take of subject '{}' has {} vertices, rig '{}' {}: not in the rig's topology",
                    take.info.subject, take.vertex_count(), rig.name, rig.vertex_count()));
  }
  // Truth channels of the simulator never feed a method (ARCHITECTURE.md).
  if (channel == "quasistatic" || channel == "dynamic_offset") {
    return InvalidArgumentError(fmt::format(
        "channel '{}' is simulator truth; solve from the take's positions or a method's output",
        channel));
  }
  const PointCache* cache = &take.positions;
  if (!channel.empty()) {
    const auto it = take.channels.find(channel);
    if (it == take.channels.end()) {
      return NotFoundError(fmt::format("take has no channel '{}'", channel));
    }
    cache = &it->second;
  }
  const int n = take.frame_count();
  const int m_count = puppet.marker_count();
  MarkerFrames frames;
  frames.time_s.resize(n);
  frames.markers_in_skull.resize(3 * m_count, n);
  frames.present = MarkerPresence::Constant(m_count, n, true);
  for (int f = 0; f < n; ++f) {
    frames.time_s[f] =
        f < static_cast<int>(take.time_s.size()) ? take.time_s[f] : f / take.info.fps;
    const Eigen::Matrix3Xd skin_in_world = cache->Frame(f).cast<double>();
    const Rigid3 skull_from_world = take.world_from_skull[f].Inverse();
    for (int m = 0; m < m_count; ++m) {
      frames.markers_in_skull.block<3, 1>(3 * m, f) =
          skull_from_world * rig.markers[m].point.Evaluate(skin_in_world);
    }
  }
  return frames;
}

StatusOr<MarkerFrames> MarkersFromTracks(const Puppet& puppet, const MarkerTracks& tracks,
                                         const std::vector<Rigid3>& world_from_skull) {
  const int n = tracks.frame_count();
  if (static_cast<int>(world_from_skull.size()) != n) {
    return InvalidArgumentError(fmt::format(
        "marker tracks have {} frames, the take's skull motion {}", n, world_from_skull.size()));
  }
  std::vector<int> track_of(puppet.marker_count(), -1);
  for (int m = 0; m < puppet.marker_count(); ++m) {
    for (int i = 0; i < tracks.marker_count(); ++i) {
      if (tracks.names[i] == puppet.marker_names[m]) track_of[m] = i;
    }
    if (track_of[m] < 0) {
      return InvalidArgumentError(
          fmt::format("the marker tracks have no marker '{}' of puppet '{}'",
                      puppet.marker_names[m], puppet.rig_name));
    }
  }
  MarkerFrames frames;
  frames.time_s = tracks.time_s;
  frames.markers_in_skull.setZero(3 * puppet.marker_count(), n);
  frames.present = MarkerPresence::Constant(puppet.marker_count(), n, false);
  for (int f = 0; f < n; ++f) {
    const Rigid3 skull_from_world = world_from_skull[f].Inverse();
    for (int m = 0; m < puppet.marker_count(); ++m) {
      const int i = track_of[m];
      if (!tracks.present(i, f)) continue;
      frames.markers_in_skull.block(3 * m, f, 3, 1) =
          skull_from_world * Eigen::Vector3d(tracks.world_mm.block(3 * i, f, 3, 1));
      frames.present(m, f) = true;
    }
  }
  return frames;
}

StatusOr<Take> DriveRig(const FaceRig& rig, const BlendshapeWeightsTrack& track,
                        const std::string& source) {
  FACEDYN_RETURN_IF_ERROR(track.Validate().WithContext(source));
  std::vector<int> column_channel;
  for (size_t column = 0; column < track.names.size(); ++column) {
    const int k = rig.BlendshapeIndex(track.names[column]);
    if (k < 0) {
      return InvalidArgumentError(fmt::format("{}: column {} '{}' is not a blendshape of rig '{}'",
                                              source, column + 2, track.names[column], rig.name));
    }
    column_channel.push_back(k);
  }
  if (track.sample_count() < 2) return InvalidArgumentError(source + ": needs at least 2 frames");
  Take take;
  take.info.fps = (track.sample_count() - 1) / (track.time_s.back() - track.time_s.front());
  take.info.subject = rig.name;
  take.info.expression = "solved";
  take.info.motion = "none";
  take.info.source = "solve apply";
  take.topology = rig.neutral;
  take.positions.vertex_count = rig.vertex_count();
  take.positions.positions.resize(3 * rig.vertex_count(), track.sample_count());
  for (int f = 0; f < track.sample_count(); ++f) {
    Eigen::VectorXd w =
        Eigen::VectorXd::Zero(static_cast<Eigen::Index>(rig.blendshape_names.size()));
    for (size_t column = 0; column < column_channel.size(); ++column) {
      w[column_channel[column]] = track.weights(f, static_cast<Eigen::Index>(column));
    }
    take.positions.Frame(f) = rig.Evaluate(w).cast<float>();
    take.time_s.push_back(track.time_s[f] - track.time_s.front());
    take.world_from_skull.push_back(Rigid3::Identity());
  }
  FACEDYN_RETURN_IF_ERROR(take.Validate());
  return take;
}

}  // namespace facedyn::solve
