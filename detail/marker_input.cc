#include "detail/marker_input.h"

#include <map>

namespace facedyn::detail {

StatusOr<MarkerFrames> MarkersFromTracks(const MarkerTracks& tracks,
                                         const std::vector<Rigid3>& world_from_skull,
                                         const std::vector<Marker>& layout, const Mesh& neutral) {
  if (static_cast<int>(world_from_skull.size()) != tracks.frame_count()) {
    return InvalidArgumentError("marker tracks have " + std::to_string(tracks.frame_count()) +
                                " frames but the take has " +
                                std::to_string(world_from_skull.size()) + " skull poses");
  }
  std::map<std::string, int> track_of;
  for (int i = 0; i < tracks.marker_count(); ++i) track_of[tracks.names[i]] = i;
  const int m_count = static_cast<int>(layout.size());
  std::vector<int> source(m_count);
  for (int m = 0; m < m_count; ++m) {
    const auto it = track_of.find(layout[m].name);
    if (it == track_of.end()) {
      return NotFoundError("marker '" + layout[m].name +
                           "' of the model's layout is not in the take's marker tracks (" +
                           std::to_string(tracks.marker_count()) + " markers)");
    }
    source[m] = it->second;
  }
  MarkerFrames out;
  const int frames = tracks.frame_count();
  out.markers_mm.assign(frames, Eigen::Matrix3Xd(3, m_count));
  std::vector<bool> present(static_cast<size_t>(frames) * m_count, false);
  for (int f = 0; f < frames; ++f) {
    const Rigid3 skull_from_world = world_from_skull[f].Inverse();
    for (int m = 0; m < m_count; ++m) {
      if (!tracks.present(source[m], f)) continue;
      present[static_cast<size_t>(f) * m_count + m] = true;
      out.markers_mm[f].col(m) =
          skull_from_world * Eigen::Vector3d(tracks.world_mm.block(3 * source[m], f, 3, 1));
    }
  }
  for (int m = 0; m < m_count; ++m) {
    int first = -1;
    for (int f = 0; f < frames && first < 0; ++f) {
      if (present[static_cast<size_t>(f) * m_count + m]) first = f;
    }
    Eigen::Vector3d held = first >= 0 ? Eigen::Vector3d(out.markers_mm[first].col(m))
                                      : layout[m].point.Evaluate(neutral.positions_mm);
    if (first < 0) out.never_seen.push_back(layout[m].name);
    for (int f = 0; f < frames; ++f) {
      if (present[static_cast<size_t>(f) * m_count + m]) {
        held = out.markers_mm[f].col(m);
      } else {
        out.markers_mm[f].col(m) = held;
        ++out.filled;
      }
    }
  }
  return out;
}

}  // namespace facedyn::detail
