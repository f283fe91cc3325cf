// The reconstruction pipeline for one take: per frame, marker detections in every camera ->
// triangulated points -> labelled markers -> skull pose -> jaw pose -> dense mesh; out comes a
// Take in the FaceRig's topology with world_from_skull per frame (and skull_from_jaw per frame
// when the rig has a jaw, see jaw_pose.h), plus a per-frame quality report.
//
// Bad frames do not stop the take: a frame whose cameras saw nothing, or too few markers for a
// fit, is reported (FrameQuality::problem) and gets the skull pose interpolated from its
// neighbours and the mesh of the nearest good frame carried to that pose. A frame with too few
// jaw markers for a jaw pose keeps the previous frame's skull_from_jaw (identity before the
// first jaw estimate); it is flagged (FrameQuality::jaw_carried, and a note in problem).
#pragma once

#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/marker_tracks.h"
#include "core/status.h"
#include "core/take.h"
#include "reconstruct/camera.h"
#include "reconstruct/dense_fit.h"
#include "reconstruct/jaw_pose.h"
#include "reconstruct/skull_pose.h"
#include "reconstruct/tracking.h"
#include "reconstruct/triangulation.h"

namespace facedyn::reconstruct {

struct ReconstructionOptions {
  // Head-mounted cameras (capture.json "camera_mount": "head"): the calibration's frame is the
  // helmet's, which moves with the skull, so the markers are triangulated in the skull frame and
  // world_from_skull is the identity on every frame (no skull pose is estimated; the rig needs no
  // stable markers). A helmet that slips on the head is not corrected.
  bool head_mounted = false;
  CorrespondenceOptions correspondence;
  TrackingOptions tracking;
  SkullPoseOptions skull;
  JawPoseOptions jaw;
  DenseFitOptions dense;
  Status Check() const;
};

// Options for head-mounted cameras: head_mounted; labelling with the skull pose fixed at the
// identity (TrackingOptions::pose_fixed); and the correspondence a two-camera helmet needs —
// points seen by 2 views (a rig's 8 cameras ask for 3), triangulated 100-600 mm from the cameras
// (the face sits in the helmet; farther points are wrong epipolar matches).
ReconstructionOptions HeadMountedReconstructionOptions();

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
  // Jaw (all zero / false when the rig has no jaw): markers used, their weighted residual,
  // the hinge angle (positive opens), and whether the jaw pose was carried over from an
  // earlier frame because fewer than JawPoseOptions::min_markers jaw markers were usable.
  int jaw_markers = 0;
  double jaw_rms_mm = 0.0;
  double jaw_angle_rad = 0.0;
  bool jaw_carried = false;
  int jaw_carried_from = -1;  // when carried: the frame whose jaw pose it is, -1 the rest pose
  std::string problem;        // empty when the frame reconstructed normally
};

struct ReconstructionTimings {
  double triangulate_s = 0.0;  // correspondence + triangulation
  double track_s = 0.0;
  double skull_s = 0.0;
  double jaw_s = 0.0;
  double dense_s = 0.0;
};

struct Reconstruction {
  Take take;
  std::vector<FrameQuality> quality;
  std::vector<TrackedFrame> tracked;
  ReconstructionTimings timings;
  // Ok when the jaw was estimated or the rig has no jaw (then take.skull_from_jaw is empty);
  // otherwise why the rig's jaw could not be estimated at all (the take has no jaw either,
  // and take.info.metadata["jaw"] says so too).
  Status jaw_status;
};

// The labelled markers of a reconstruction as a take's marker tracks (core/marker_tracks.h): per
// frame and rig marker, the triangulated position (world frame), observed / bridged / missing and
// the tracker's confidence. Missing markers have no position (the tracker's prediction is not
// data).
MarkerTracks MarkerTracksOf(const FaceRig& rig, const Reconstruction& reconstruction);

// detections[f][c]: camera c's marker detections in frame f (pixels, weight = quality).
StatusOr<Reconstruction> ReconstructTake(
    const FaceRig& rig, const std::vector<Camera>& cameras,
    const std::vector<std::vector<std::vector<ImageObservation>>>& detections, double fps,
    const ReconstructionOptions& options);

}  // namespace facedyn::reconstruct
