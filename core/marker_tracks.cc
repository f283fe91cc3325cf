#include "core/marker_tracks.h"

#include <fmt/format.h>

#include <cctype>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <set>

#include "core/csv.h"
#include "core/file_util.h"

namespace facedyn {
namespace {

constexpr char kHeader[] = "frame,time_s,marker,state,confidence,x_mm,y_mm,z_mm";

bool ValidName(const std::string& name) {
  if (name.empty()) return false;
  for (char c : name) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.')) {
      return false;
    }
  }
  return true;
}

}  // namespace

const char* MarkerTrackStateName(MarkerTrackState state) {
  switch (state) {
    case MarkerTrackState::kObserved:
      return "observed";
    case MarkerTrackState::kBridged:
      return "bridged";
    case MarkerTrackState::kMissing:
      return "missing";
  }
  return "missing";
}

Status MarkerTracks::Validate() const {
  const int m = marker_count(), n = frame_count();
  if (world_mm.rows() != 3 * m || world_mm.cols() != n || confidence.rows() != m ||
      confidence.cols() != n || static_cast<int>(state.size()) != n) {
    return InvalidArgumentError(fmt::format(
        "marker tracks: {} markers and {} frames, but positions are {}x{}, confidence {}x{}, "
        "states for {} frames",
        m, n, world_mm.rows(), world_mm.cols(), confidence.rows(), confidence.cols(),
        state.size()));
  }
  std::set<std::string> seen;
  for (const std::string& name : names) {
    if (!ValidName(name))
      return InvalidArgumentError("marker tracks: bad marker name '" + name + "'");
    if (!seen.insert(name).second)
      return InvalidArgumentError("marker tracks: marker '" + name + "' twice");
  }
  for (int f = 0; f < n; ++f) {
    if (!std::isfinite(time_s[f]) || (f > 0 && !(time_s[f] > time_s[f - 1]))) {
      return InvalidArgumentError(
          fmt::format("marker tracks: time of frame {} is not after the previous", f));
    }
    if (static_cast<int>(state[f].size()) != m) {
      return InvalidArgumentError(fmt::format(
          "marker tracks: frame {} has {} states for {} markers", f, state[f].size(), m));
    }
    for (int i = 0; i < m; ++i) {
      const double c = confidence(i, f);
      if (!(c >= 0.0 && c <= 1.0)) {
        return InvalidArgumentError(
            fmt::format("marker tracks: confidence of {} in frame {} is {}", names[i], f, c));
      }
      if (present(i, f) && !world_mm.block(3 * i, f, 3, 1).allFinite()) {
        return InvalidArgumentError(
            fmt::format("marker tracks: {} in frame {} is present but not finite", names[i], f));
      }
    }
  }
  return Status::Ok();
}

Status SaveMarkerTracks(const MarkerTracks& tracks, const std::vector<Rigid3>& world_from_skull,
                        const std::string& take_dir) {
  FACEDYN_RETURN_IF_ERROR(tracks.Validate());
  if (static_cast<int>(world_from_skull.size()) != tracks.frame_count()) {
    return InvalidArgumentError(fmt::format("marker tracks: {} frames but {} skull poses",
                                            tracks.frame_count(), world_from_skull.size()));
  }
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(take_dir));
  std::string world = std::string(kHeader) + "\n";
  std::string skull = "time_s";
  for (const std::string& name : tracks.names)
    skull += "," + name + "_x," + name + "_y," + name + "_z";
  skull += "\n";
  for (int f = 0; f < tracks.frame_count(); ++f) {
    const Rigid3 skull_from_world = world_from_skull[f].Inverse();
    skull += fmt::format("{:.9g}", tracks.time_s[f]);
    for (int i = 0; i < tracks.marker_count(); ++i) {
      const MarkerTrackState state = tracks.state[f][i];
      world += fmt::format("{},{:.9g},{},{},{:.4f}", f, tracks.time_s[f], tracks.names[i],
                           MarkerTrackStateName(state), tracks.confidence(i, f));
      if (state == MarkerTrackState::kMissing) {
        world += ",,,\n";
        skull += ",,,";
        continue;
      }
      const Eigen::Vector3d p = tracks.world_mm.block(3 * i, f, 3, 1);
      const Eigen::Vector3d q = skull_from_world * p;
      world += fmt::format(",{:.6f},{:.6f},{:.6f}\n", p.x(), p.y(), p.z());
      skull += fmt::format(",{:.6f},{:.6f},{:.6f}", q.x(), q.y(), q.z());
    }
    skull += "\n";
  }
  FACEDYN_RETURN_IF_ERROR(WriteFileAtomic(JoinPath(take_dir, kMarkerTracksFile), world));
  return WriteFileAtomic(JoinPath(take_dir, kMarkerTracksSkullFile), skull);
}

StatusOr<MarkerTracks> LoadMarkerTracks(const std::string& take_dir) {
  const std::string path = JoinPath(take_dir, kMarkerTracksFile);
  std::error_code ec;
  if (!std::filesystem::exists(path, ec))
    return NotFoundError(path + ": the take has no marker tracks");
  FACEDYN_ASSIGN_OR_RETURN(const CsvTable table, CsvTable::Read(path, kHeader));
  MarkerTracks tracks;
  // Markers in the order of their first appearance; rows grouped by frame, frames in order, and
  // every frame lists every marker once.
  std::map<std::string, int> index;
  struct Row {
    int marker;
    MarkerTrackState state;
    double confidence;
    Eigen::Vector3d p;
  };
  std::vector<std::vector<Row>> frames;
  for (size_t r = 0; r < table.row_count(); ++r) {
    FACEDYN_ASSIGN_OR_RETURN(const int frame, table.Integer(r, 0));
    FACEDYN_ASSIGN_OR_RETURN(const double time, table.Number(r, 1));
    const std::string& name = table.Text(r, 2);
    if (!ValidName(name)) return table.RowError(r, "bad marker name '" + name + "'");
    const std::string& state_text = table.Text(r, 3);
    MarkerTrackState state;
    if (state_text == "observed") {
      state = MarkerTrackState::kObserved;
    } else if (state_text == "bridged") {
      state = MarkerTrackState::kBridged;
    } else if (state_text == "missing") {
      state = MarkerTrackState::kMissing;
    } else {
      return table.RowError(r, "state is '" + state_text + "', not observed, bridged or missing");
    }
    FACEDYN_ASSIGN_OR_RETURN(const double confidence, table.Number(r, 4));
    if (!(confidence >= 0.0 && confidence <= 1.0))
      return table.RowError(r, "confidence outside [0, 1]");
    Eigen::Vector3d p = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
    if (state == MarkerTrackState::kMissing) {
      for (int k = 5; k < 8; ++k) {
        if (!table.Text(r, k).empty()) return table.RowError(r, "a missing marker has a position");
      }
    } else {
      for (int k = 0; k < 3; ++k) {
        FACEDYN_ASSIGN_OR_RETURN(p[k], table.Number(r, 5 + k));
      }
    }
    if (frame < 0 || frame > static_cast<int>(frames.size())) {
      return table.RowError(r, fmt::format("frame {} out of order (expected {} or {})", frame,
                                           static_cast<int>(frames.size()) - 1, frames.size()));
    }
    if (frame == static_cast<int>(frames.size())) {
      if (frame > 0 && frames[frame - 1].size() != index.size()) {
        return table.RowError(r, fmt::format("frame {} lists {} of {} markers", frame - 1,
                                             frames[frame - 1].size(), index.size()));
      }
      if (frame > 0 && !(time > tracks.time_s.back())) {
        return table.RowError(r, "time does not increase");
      }
      frames.emplace_back();
      tracks.time_s.push_back(time);
    } else if (time != tracks.time_s.back()) {
      return table.RowError(r, "time differs within frame " + std::to_string(frame));
    }
    auto it = index.find(name);
    if (it == index.end()) {
      if (frame > 0) return table.RowError(r, "marker '" + name + "' not in frame 0");
      it = index.emplace(name, static_cast<int>(tracks.names.size())).first;
      tracks.names.push_back(name);
    }
    for (const Row& row : frames.back()) {
      if (row.marker == it->second)
        return table.RowError(r, "marker '" + name + "' twice in a frame");
    }
    frames.back().push_back({it->second, state, confidence, p});
  }
  if (frames.empty()) return DataLossError(path + ": no frames");
  if (frames.back().size() != index.size()) {
    return DataLossError(fmt::format("{}: the last frame lists {} of {} markers", path,
                                     frames.back().size(), index.size()));
  }
  const int m = tracks.marker_count(), n = static_cast<int>(frames.size());
  tracks.world_mm.resize(3 * m, n);
  tracks.confidence.resize(m, n);
  tracks.state.assign(n, std::vector<MarkerTrackState>(m, MarkerTrackState::kMissing));
  for (int f = 0; f < n; ++f) {
    for (const Row& row : frames[f]) {
      tracks.world_mm.block(3 * row.marker, f, 3, 1) = row.p;
      tracks.confidence(row.marker, f) = row.confidence;
      tracks.state[f][row.marker] = row.state;
    }
  }
  return tracks;
}

}  // namespace facedyn
