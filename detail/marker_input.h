// HMC marker input for the upsamplers: a model's markers per frame in the skull frame, from a
// take's labelled marker tracks (core/marker_tracks.h, written by `facedyn reconstruct`).
//
// Masquerade's regions need every marker on every frame; a tracked marker can be missing (hidden
// by the lips, out of a camera's view). A missing marker is held at its last known skull-frame
// position (before it is first seen: its first seen position; never seen: its neutral position)
// and counted, so a caller can report how much of the input was filled rather than observed.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/marker_tracks.h"
#include "core/mesh.h"
#include "core/rigid3.h"
#include "core/status.h"

namespace facedyn::detail {

struct MarkerFrames {
  std::vector<Eigen::Matrix3Xd> markers_mm;  // per frame, 3 x M in `layout` order, skull frame
  int filled = 0;                            // marker-frames held (missing in the tracks)
  std::vector<std::string> never_seen;       // markers missing on every frame (held at neutral)
};

// `world_from_skull` has one pose per tracked frame. Errors name a layout marker the tracks do
// not have, or a frame-count mismatch.
StatusOr<MarkerFrames> MarkersFromTracks(const MarkerTracks& tracks,
                                         const std::vector<Rigid3>& world_from_skull,
                                         const std::vector<Marker>& layout, const Mesh& neutral);

}  // namespace facedyn::detail
