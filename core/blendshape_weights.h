// Blendshape weights over time: the animation curves a rig solve produces (solve/) and that
// exporters turn into glTF morph-weight animation (export/). One CSV file:
//
//   time_s,<name>,<name>,...        header: time in seconds, then one column per blendshape
//   0.000000,0.0,0.25,...           one row per sample, times strictly increasing
//
// Names are the FaceRig's blendshape names (the ARKit names for ICT-FaceKit); a rig's shapes
// that have no column are at weight 0. Weights are finite; no range is imposed (solves may
// overshoot 0..1 slightly and artists expect to see that).
//
// The same track as JSON (`facedyn solve run` writes it beside the CSV, for tools that would
// rather not parse CSV, such as a browser):
//
//   {"format": "facedyn.blendshape_weights", "version": 1,
//    "names": ["jawOpen", ...],            one per column, as the CSV's header after time_s
//    "time_s": [0.0, 0.0167, ...],         one per sample, strictly increasing
//    "weights": [[0.0, 0.25, ...], ...]}   one array per sample, in the names' order
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/status.h"

namespace facedyn {

struct BlendshapeWeightsTrack {
  std::vector<std::string> names;
  std::vector<double> time_s;  // per sample, strictly increasing
  Eigen::MatrixXd weights;     // samples x names

  int sample_count() const { return static_cast<int>(time_s.size()); }
  // Index of a column, or -1.
  int NameIndex(const std::string& name) const;
  // Sizes agree, at least one sample, times finite and strictly increasing, weights finite,
  // names non-empty, unique and free of commas.
  Status Validate() const;
};

// Errors name the file, the line and the column.
StatusOr<BlendshapeWeightsTrack> ReadBlendshapeWeightsCsv(const std::string& path);
// Validates first; written atomically (nothing is left under `path` on failure).
Status WriteBlendshapeWeightsCsv(const std::string& path, const BlendshapeWeightsTrack& track);

// The JSON layout above. Errors name the file, the line and the field (a sample whose weights
// are not one per name names the sample). Numbers are written in their shortest exact form, so
// a JSON round trip gives back the same doubles.
StatusOr<BlendshapeWeightsTrack> ReadBlendshapeWeightsJson(const std::string& path);
Status WriteBlendshapeWeightsJson(const std::string& path, const BlendshapeWeightsTrack& track);

// By the file's extension: ".json" (any case) the JSON layout, anything else the CSV.
StatusOr<BlendshapeWeightsTrack> ReadBlendshapeWeights(const std::string& path);

}  // namespace facedyn
