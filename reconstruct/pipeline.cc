#include "reconstruct/pipeline.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "core/progress.h"

namespace facedyn::reconstruct {
namespace {

double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

Status ReconstructionOptions::Check() const {
  FACEDYN_RETURN_IF_ERROR(correspondence.Check().WithContext("correspondence"));
  FACEDYN_RETURN_IF_ERROR(tracking.Check().WithContext("tracking"));
  FACEDYN_RETURN_IF_ERROR(skull.Check().WithContext("skull pose"));
  FACEDYN_RETURN_IF_ERROR(jaw.Check().WithContext("jaw pose"));
  FACEDYN_RETURN_IF_ERROR(dense.Check().WithContext("dense fit"));
  return Status::Ok();
}

ReconstructionOptions HeadMountedReconstructionOptions() {
  ReconstructionOptions options;
  options.head_mounted = true;
  options.correspondence.min_views = 2;
  options.tracking.pose_fixed = true;
  options.correspondence.min_depth_mm = 100.0;
  options.correspondence.max_depth_mm = 600.0;
  return options;
}

StatusOr<Reconstruction> ReconstructTake(
    const FaceRig& rig, const std::vector<Camera>& cameras,
    const std::vector<std::vector<std::vector<ImageObservation>>>& detections, double fps,
    const ReconstructionOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check().WithContext("reconstruction options"));
  if (cameras.size() < 2) return InvalidArgumentError("reconstruction needs at least 2 cameras");
  if (detections.empty()) return InvalidArgumentError("the take has no frames");
  if (!(fps > 0)) return InvalidArgumentError("fps must be > 0");
  for (const Camera& camera : cameras) FACEDYN_RETURN_IF_ERROR(camera.Check());
  const SkullPoseEstimator skull(rig, options.skull);
  if (!options.head_mounted) FACEDYN_RETURN_IF_ERROR(skull.status());
  DenseFitter fitter(rig, options.dense);
  FACEDYN_RETURN_IF_ERROR(fitter.status());
  const int frame_count = static_cast<int>(detections.size());
  Reconstruction out;
  out.quality.resize(frame_count);
  MarkerTracker tracker(rig, options.tracking);
  Progress progress("reconstruct", 2L * frame_count);
  for (int f = 0; f < frame_count; ++f) {
    FrameQuality& q = out.quality[f];
    q.frame = f;
    std::vector<std::vector<ImageObservation>> frame = detections[f];
    if (frame.size() != cameras.size()) {
      // A missing camera's slot: treat as no detections and say so.
      q.problem = "frame has detections for " + std::to_string(frame.size()) + " of " +
                  std::to_string(cameras.size()) + " cameras";
      frame.resize(cameras.size());
    }
    for (size_t c = 0; c < frame.size(); ++c) {
      for (ImageObservation& o : frame[c]) o.camera = static_cast<int>(c);
      q.detections += static_cast<int>(frame[c].size());
    }
    auto start = std::chrono::steady_clock::now();
    const std::vector<TriangulatedPoint> points =
        TriangulateDetections(cameras, frame, options.correspondence);
    out.timings.triangulate_s += Seconds(start);
    q.points = static_cast<int>(points.size());
    for (const auto& p : points) q.reprojection_rms_px += p.rms_px / points.size();
    start = std::chrono::steady_clock::now();
    const auto tracked = tracker.AddFrame(points);
    out.timings.track_s += Seconds(start);
    if (!tracked.ok()) {
      q.problem = tracked.status().message();
      // The tracker could not start on this frame; feed it nothing so it waits for the next.
      (void)tracker.AddFrame({});
    }
    if (q.points == 0 && q.problem.empty()) q.problem = "no markers triangulated";
    progress.Advance();
  }
  out.tracked = tracker.Finish();
  // Skull poses; frames without a pose interpolate between their neighbours.
  std::vector<Rigid3> poses(frame_count);
  std::vector<bool> has_pose(frame_count, false);
  auto start = std::chrono::steady_clock::now();
  for (int f = 0; f < frame_count && options.head_mounted; ++f) has_pose[f] = true;
  TakeReferenceResult skull_reference;
  const std::vector<SkullPoseResult> skull_results =
      options.head_mounted ? std::vector<SkullPoseResult>()
                           : skull.EstimateTake(out.tracked, &skull_reference);
  for (int f = 0; f < frame_count && !options.head_mounted; ++f) {
    const SkullPoseResult& result = skull_results[f];
    poses[f] = result.world_from_skull;
    has_pose[f] = result.ok;
    out.quality[f].skull_rms_mm = result.rms_mm;
    if (!result.ok && out.quality[f].problem.empty()) {
      out.quality[f].problem = "too few stable markers for the skull pose";
    }
  }
  std::vector<int> good;
  for (int f = 0; f < frame_count; ++f) {
    if (has_pose[f]) good.push_back(f);
  }
  if (good.empty()) {
    return FailedPreconditionError(
        "no frame of the take had enough stable markers for a skull pose");
  }
  for (int f = 0; f < frame_count; ++f) {
    if (has_pose[f]) continue;
    const auto after = std::lower_bound(good.begin(), good.end(), f);
    if (after == good.begin()) {
      poses[f] = poses[*after];
    } else if (after == good.end()) {
      poses[f] = poses[good.back()];
    } else {
      const int a = *(after - 1), b = *after;
      poses[f] = Rigid3::Interpolate(poses[a], poses[b], double(f - a) / (b - a));
    }
  }
  out.timings.skull_s = Seconds(start);

  // Jaw: skull_from_jaw per frame from the jaw markers in the skull frame of `poses`.
  start = std::chrono::steady_clock::now();
  const JawPoseEstimator jaw(rig, options.jaw);
  out.jaw_status = jaw.status();
  if (!jaw.status().ok()) {
    out.take.info.metadata["jaw"] = "not estimated: " + jaw.status().message();
  } else if (jaw.has_jaw()) {
    JawSequence sequence = EstimateJawSequence(jaw, out.tracked, poses);
    int carried = 0;
    for (int f = 0; f < frame_count; ++f) {
      FrameQuality& q = out.quality[f];
      const JawPoseResult& result = sequence.results[f];
      q.jaw_markers = result.markers_used;
      q.jaw_rms_mm = result.rms_mm;
      q.jaw_angle_rad = JawHingeAngleRad(jaw.jaw(), sequence.skull_from_jaw[f]);
      q.jaw_carried = sequence.carried[f];
      if (q.jaw_carried) q.jaw_carried_from = sequence.carried_from[f];
      carried += q.jaw_carried ? 1 : 0;
    }
    out.take.skull_from_jaw = std::move(sequence.skull_from_jaw);
    out.take.info.metadata["jaw"] = {{"markers", jaw.jaw_markers().size()},
                                     {"frames_carried_over", carried}};
  }
  out.timings.jaw_s = Seconds(start);

  // Dense fit, warm-started frame to frame.
  const int vertex_count = rig.vertex_count();
  out.take.topology = rig.neutral;
  out.take.info.fps = fps;
  out.take.info.subject = rig.name;
  out.take.info.source = "reconstruct";
  out.take.info.motion = "captured";
  out.take.world_from_skull = poses;
  out.take.info.metadata["camera_mount"] = options.head_mounted ? "head" : "world";
  // Which model kept the stable markers' jiggle out of world_from_skull (skull_pose.h).
  if (!options.head_mounted) {
    out.take.info.metadata["skull_deflection_shape"] = skull.deflection_shape_used();
    // Where the stable markers' reference shape came from (SkullPoseEstimator::EstimateTake).
    out.take.info.metadata["skull_reference"] =
        skull_reference.applied ? Json{{"source", "take"},
                                       {"markers_refined", skull_reference.markers_refined},
                                       {"correction_rms_mm", skull_reference.correction_rms_mm},
                                       {"correction_max_mm", skull_reference.correction_max_mm}}
                                : Json{{"source", "rig"}, {"reason", skull_reference.reason}};
  }
  std::vector<Eigen::Matrix3Xd> in_skull(frame_count);
  std::vector<bool> fitted(frame_count, false);
  start = std::chrono::steady_clock::now();
  for (int f = 0; f < frame_count; ++f) {
    FrameQuality& q = out.quality[f];
    const TrackedFrame& t = out.tracked[f];
    q.labelled = t.observed();
    q.unlabelled_points = t.unlabelled_points;
    for (MarkerState s : t.states) {
      q.bridged += s == MarkerState::kBridged ? 1 : 0;
      q.missing += s == MarkerState::kMissing ? 1 : 0;
    }
    DenseFitSummary summary;
    const auto positions = fitter.Fit(t, poses[f], &summary);
    progress.Advance();
    if (!positions.ok()) {
      if (q.problem.empty()) q.problem = positions.status().message();
      continue;
    }
    q.fit_marker_rms_mm = summary.marker_rms_mm;
    in_skull[f] = poses[f].Inverse().Apply(*positions);
    fitted[f] = true;
  }
  out.timings.dense_s = Seconds(start);
  progress.Finish();
  int last_fitted = -1;
  for (int f = 0; f < frame_count; ++f) {
    if (fitted[f]) last_fitted = f;
  }
  if (last_fitted < 0) {
    // Say why, from the first frame: usually every frame fails the same way.
    return FailedPreconditionError(
        "no frame of the take could be fitted (frame 0: " +
        (out.quality[0].problem.empty() ? std::string("no fit") : out.quality[0].problem) + "; " +
        std::to_string(out.quality[0].detections) + " detections, " +
        std::to_string(out.quality[0].points) + " triangulated points)");
  }
  // Unfitted frames carry the nearest fitted frame's skull-frame shape to their own pose.
  out.take.positions.vertex_count = vertex_count;
  out.take.positions.positions.resize(3 * vertex_count, frame_count);
  for (int f = 0; f < frame_count; ++f) {
    int source = f;
    for (int d = 1; !fitted[source]; ++d) {
      if (f - d >= 0 && fitted[f - d]) {
        source = f - d;
      } else if (f + d < frame_count && fitted[f + d]) {
        source = f + d;
      }
    }
    out.take.positions.Frame(f) = poses[f].Apply(in_skull[source]).cast<float>();
  }
  // Jaw notes go after any other problem of the frame, which is the more fundamental one.
  for (FrameQuality& q : out.quality) {
    if (!q.jaw_carried) continue;
    const std::string note =
        "too few jaw markers (" + std::to_string(q.jaw_markers) + " usable, " +
        std::to_string(options.jaw.min_markers) + " needed); jaw pose " +
        (q.jaw_carried_from >= 0 ? "carried over from frame " + std::to_string(q.jaw_carried_from)
                                 : std::string("set to the rest pose (no earlier jaw estimate)"));
    q.problem += (q.problem.empty() ? "" : "; ") + note;
  }
  out.take.SetUniformTimes();
  FACEDYN_RETURN_IF_ERROR(out.take.Validate().WithContext("reconstructed take"));
  return out;
}

MarkerTracks MarkerTracksOf(const FaceRig& rig, const Reconstruction& reconstruction) {
  MarkerTracks tracks;
  const int m = static_cast<int>(rig.markers.size());
  const int n = static_cast<int>(reconstruction.tracked.size());
  for (const auto& marker : rig.markers) tracks.names.push_back(marker.name);
  tracks.time_s = reconstruction.take.time_s;
  tracks.time_s.resize(n);
  tracks.world_mm.setConstant(3 * m, n, std::numeric_limits<double>::quiet_NaN());
  tracks.confidence.setZero(m, n);
  tracks.state.assign(n, std::vector<MarkerTrackState>(m, MarkerTrackState::kMissing));
  for (int f = 0; f < n; ++f) {
    const TrackedFrame& t = reconstruction.tracked[f];
    for (int i = 0; i < m && i < static_cast<int>(t.states.size()); ++i) {
      if (t.states[i] == MarkerState::kMissing) continue;
      tracks.state[f][i] = t.states[i] == MarkerState::kObserved ? MarkerTrackState::kObserved
                                                                 : MarkerTrackState::kBridged;
      tracks.world_mm.block(3 * i, f, 3, 1) = t.positions_in_world.col(i);
      tracks.confidence(i, f) =
          i < static_cast<int>(t.confidence.size()) ? std::clamp(t.confidence[i], 0.0, 1.0) : 0.0;
    }
  }
  return tracks;
}

}  // namespace facedyn::reconstruct
