// Labelled marker tracks of a take: what reconstruction triangulated and labelled, marker by
// marker and frame by frame, before any mesh was fitted to it — the data a marker-based solver
// (solve/, FDLS) or another marker system works from.
//
// In a take folder (written by `facedyn reconstruct`, beside the Take's own files; take.json's
// metadata "marker_tracks" names them):
//   marker_tracks.csv       frame,time_s,marker,state,confidence,x_mm,y_mm,z_mm
//                           one row per frame and marker, world frame; state observed (a
//                           triangulated point was labelled this marker), bridged (a short gap,
//                           predicted from the marker's own track) or missing (x, y, z empty);
//                           confidence in [0, 1]
//   marker_tracks_skull.csv the same markers in the skull frame (world_from_skull of the take) in
//                           the labelled-markers layout other marker systems export and
//                           `facedyn solve run --markers` reads: time_s, then <marker>_x, _y, _z;
//                           empty fields where the marker is missing
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/rigid3.h"
#include "core/status.h"

namespace facedyn {

enum class MarkerTrackState { kObserved = 0, kBridged = 1, kMissing = 2 };
const char* MarkerTrackStateName(MarkerTrackState state);

struct MarkerTracks {
  std::vector<std::string> names;                    // M, the FaceRig's marker names
  std::vector<double> time_s;                        // N
  Eigen::MatrixXd world_mm;                          // 3M x N (NaN where missing)
  Eigen::MatrixXd confidence;                        // M x N, in [0, 1] (0 where missing)
  std::vector<std::vector<MarkerTrackState>> state;  // [frame][marker]

  int marker_count() const { return static_cast<int>(names.size()); }
  int frame_count() const { return static_cast<int>(time_s.size()); }
  bool present(int marker, int frame) const {
    return state[frame][marker] != MarkerTrackState::kMissing;
  }
  // Sizes agree, names unique and non-empty (letters, digits, '_', '-', '.'), present positions
  // finite, confidence in [0, 1], times increasing.
  Status Validate() const;
};

inline constexpr char kMarkerTracksFile[] = "marker_tracks.csv";
inline constexpr char kMarkerTracksSkullFile[] = "marker_tracks_skull.csv";

// Writes both files into `take_dir` (each atomically). `world_from_skull` has one pose per frame.
Status SaveMarkerTracks(const MarkerTracks& tracks, const std::vector<Rigid3>& world_from_skull,
                        const std::string& take_dir);
// Reads marker_tracks.csv from `take_dir`; NotFound when the take has none. Errors name the file,
// line and field.
StatusOr<MarkerTracks> LoadMarkerTracks(const std::string& take_dir);

}  // namespace facedyn
