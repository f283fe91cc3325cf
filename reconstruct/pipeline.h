// The reconstruction pipeline for one take: per frame, marker detections in every camera ->
// triangulated points -> labelled markers -> skull pose -> dense mesh; out comes a Take in the
// FaceRig's topology with world_from_skull per frame, plus a per-frame quality report.
//
// Bad frames do not stop the take: a frame whose cameras saw nothing, or too few markers for a
// fit, is reported (FrameQuality::problem) and gets the skull pose interpolated from its
// neighbours and the mesh of the nearest good frame carried to that pose.
#pragma once

#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/status.h"
#include "core/take.h"
#include "reconstruct/camera.h"
#include "reconstruct/dense_fit.h"
#include "reconstruct/skull_pose.h"
#include "reconstruct/tracking.h"
#include "reconstruct/triangulation.h"

namespace facedyn::reconstruct {

struct ReconstructionOptions {
  CorrespondenceOptions correspondence;
  TrackingOptions tracking;
  SkullPoseOptions skull;
  DenseFitOptions dense;
  Status Check() const;
};

struct FrameQuality {
  int frame = 0;
  int detections = 0;
  int points = 0;
  double reprojection_rms_px = 0.0;  // mean over the frame's points
  int labelled = 0;                  // markers observed
  int bridged = 0;
  int missing = 0;
  int unlabelled_points = 0;
  double skull_rms_mm = 0.0;
  double fit_marker_rms_mm = 0.0;
  std::string problem;  // empty when the frame reconstructed normally
};

struct ReconstructionTimings {
  double triangulate_s = 0.0;  // correspondence + triangulation
  double track_s = 0.0;
  double skull_s = 0.0;
  double dense_s = 0.0;
};

struct Reconstruction {
  Take take;
  std::vector<FrameQuality> quality;
  std::vector<TrackedFrame> tracked;
  ReconstructionTimings timings;
};

// detections[f][c]: camera c's marker detections in frame f (pixels, weight = quality).
StatusOr<Reconstruction> ReconstructTake(
    const FaceRig& rig, const std::vector<Camera>& cameras,
    const std::vector<std::vector<std::vector<ImageObservation>>>& detections, double fps,
    const ReconstructionOptions& options);

}  // namespace facedyn::reconstruct
