// FeatureSpec: what a network's input means, saved with every model (removal F and synthesis H)
// so that applying it to an incompatible take is a clear error instead of silent garbage. The
// features of Zoss et al. 2020 are counted in frames (windows) and indexed by skull landmark and
// skin sample, so a model is tied to a frame rate, a landmark set and a sample set.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"
#include "core/take.h"
#include "dynamics/features.h"

namespace facedyn::dynamics {

// FNV-1a 64 over every point's three vertex indices (int32) and weights (float64), in order.
uint64_t HashSurfacePoints(const std::vector<SurfacePoint>& points);

struct FeatureSpec {
  FeatureConfig features;                // fps, window, stretch step
  std::vector<SkullLandmark> landmarks;  // B(t) landmarks, skull frame, mm
  int sample_count = 0;
  uint64_t samples_hash = 0;  // HashSurfacePoints of the rig's skin samples

  // The rig's landmarks and samples at `fps`, with the given feature window.
  static FeatureSpec ForRig(const FaceRig& rig, double fps, double window_s = 0.08);

  int skull_descriptor_size() const {
    return features.SkullDescriptorSize(static_cast<int>(landmarks.size()));
  }
  // features valid, at least one landmark, sample_count >= 1. The message names the field.
  Status Check() const;

  // FailedPrecondition naming what differs: "fps", "skull_landmarks", "skin_samples",
  // "vertex_count" (rig against take).
  Status CheckCompatible(const Take& take, const FaceRig& rig) const;

  // JSON object: fps, window_s, window_frames, stretch_step_mm, landmarks (name, position),
  // sample_count, samples_hash (hex).
  Json ToJson() const;
  // DataLoss naming the missing or inconsistent field.
  static StatusOr<FeatureSpec> FromJson(const Json& json);
};

}  // namespace facedyn::dynamics
