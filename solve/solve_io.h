// Files of the solve stage:
//   - weights CSV (core/blendshape_weights.h): `time_s`, then one column per channel (the rig's
//     names: ARKit names for ICT-FaceKit), one row per frame; read back onto a puppet's channels;
//   - labelled markers CSV, the layout marker systems export: `time_s`, then `<marker>_x`,
//     `<marker>_y`, `<marker>_z` per marker (mm, skull frame); an empty field marks a marker
//     missing in that frame (all three must then be empty). Markers the puppet does not know are
//     ignored (systems label more dots than a face rig paints); a puppet marker without columns
//     is an error naming it.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/blendshape_weights.h"
#include "core/face_rig.h"
#include "core/marker_tracks.h"
#include "core/status.h"
#include "core/take.h"
#include "solve/marker_fit.h"
#include "solve/puppet.h"

namespace facedyn::solve {

// Weights C x N of the puppet's channels over times (N) as a track (columns = channel names).
StatusOr<BlendshapeWeightsTrack> WeightsToTrack(const Puppet& puppet,
                                                const std::vector<double>& time_s,
                                                const Eigen::MatrixXd& weights);
// A track onto the puppet's channels (C x N): a column the puppet has no channel for is an
// error naming `source`, the column and the channels the puppet has; channels without a column
// are 0. `source` is the file the track came from, for messages.
StatusOr<Eigen::MatrixXd> WeightsFromTrack(const Puppet& puppet,
                                           const BlendshapeWeightsTrack& track,
                                           const std::string& source);
Status WriteWeightsCsv(const std::string& path, const Puppet& puppet,
                       const std::vector<double>& time_s, const Eigen::MatrixXd& weights);
// The same weights as the CSV's JSON twin (core/blendshape_weights.h's JSON layout), and where a
// command puts it: the CSV's path with ".json" for its ".csv" extension (appended when it has
// none), so `solve run --out W.csv` writes W.csv and W.json.
Status WriteWeightsJson(const std::string& path, const Puppet& puppet,
                        const std::vector<double>& time_s, const Eigen::MatrixXd& weights);
std::string WeightsJsonTwinPath(const std::string& csv_path);
// Reads `path` onto the puppet's channels; times into *time_s.
StatusOr<Eigen::MatrixXd> ReadWeightsCsv(const std::string& path, const Puppet& puppet,
                                         std::vector<double>* time_s);

struct MarkerFrames {
  std::vector<double> time_s;        // N
  Eigen::MatrixXd markers_in_skull;  // 3M x N in the puppet's marker order, mm (0 where missing)
  MarkerPresence present;            // M x N
};

// Reads a labelled-markers CSV onto the puppet's markers. Errors name the file, the line and the
// column: missing marker columns, a half-missing marker, a non-number, times not increasing.
StatusOr<MarkerFrames> ReadMarkersCsv(const std::string& path, const Puppet& puppet);
Status WriteMarkersCsv(const std::string& path, const Puppet& puppet, const MarkerFrames& frames);

// The puppet's markers read off a take in the rig's topology (a reconstructed take's dense fit,
// or a dynamics-removed take): each marker's surface point on the frame's mesh, taken into the
// skull frame with the take's world_from_skull; every marker present. `channel` selects a
// per-frame channel of the take instead of its positions. Errors: the rig's markers are not the
// puppet's (by name), the take is not in the rig's topology (vertex count), the channel is
// missing, or it is one of the simulator's truth channels (quasistatic, dynamic_offset), which
// never feed a method.
StatusOr<MarkerFrames> MarkersFromTake(const Puppet& puppet, const FaceRig& rig, const Take& take,
                                       const std::string& channel = "");

// The puppet's markers from a take's labelled marker tracks (core/marker_tracks.h, written by
// `facedyn reconstruct`): the triangulated markers themselves, not the fitted mesh, in the skull
// frame of `world_from_skull` (one pose per frame); a missing marker is absent, a bridged one
// present. Errors: a puppet marker the tracks do not have (named), frame counts that disagree.
StatusOr<MarkerFrames> MarkersFromTracks(const Puppet& puppet, const MarkerTracks& tracks,
                                         const std::vector<Rigid3>& world_from_skull);

// A rig driven by a weights track (`facedyn solve apply`): one frame per sample, the rig's
// blendshapes at the track's weights, head still (identity skull pose), times from 0. Columns are
// matched to the rig's blendshapes by name, so a track solved on one face drives any rig with the
// same channel names (another identity, the procedural face); the rig's other channels stay 0.
// Errors name `source` and the column the rig lacks; fewer than 2 samples is an error.
StatusOr<Take> DriveRig(const FaceRig& rig, const BlendshapeWeightsTrack& track,
                        const std::string& source);

}  // namespace facedyn::solve
