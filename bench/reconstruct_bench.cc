// reconstruct_bench: speed and fidelity of reconstruction, as JSON on stdout.
//
//  - detection + triangulation, 8 cameras: rendered 1280x1024 marker images of a simulated
//    face (painted disks projected through the cameras, lens blur, sensor noise), DetectMarkers
//    on all 8 (on 1 thread, and on all hardware threads) then TriangulateDetections; frames/s,
//    2D centre error and 3D marker error;
//  - the full take pipeline (triangulation, tracking, skull pose, dense fit) on a simulated
//    11 Hz take through the same cameras at 0.2 px detection noise; dense-fit frames/s, skull
//    pose error, 344-sample error, dynamic-offset correlation;
//  - jaw pose: skull_from_jaw from the jaw markers on simulated jaw_open and speech takes (11 Hz
//    platform) through the same cameras at 0.2 px, after triangulation, tracking and skull
//    pose: hinge angle error (deg), pivot and chin point error (mm) against the simulator's
//    skull_from_jaw, and jaw-pose frames/s;
//  - calibration: the 13 OpenCV photographs in ../shared/assets/opencv-calib against
//    cv::calibrateCamera on the same corners (when present), and a synthetic 4-camera rig.
//
//   reconstruct_bench [--shared DIR] [--frames N] [--seconds S] [--stage NAME]
//
//  - skull_offset: where a constant skull-pose error comes from — the same take reconstructed
//    from projected centres and from filmed images, each through the true and the calibrated
//    cameras, with the triangulated markers' bias in the skull frame (BenchSkullOffset);
//
// --stage detection|pipeline|jaw|skull_offset|calibration runs one part only; default all.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "bench/bench_flags.h"
#include "core/json_io.h"
#include "core/progress.h"
#include "eval/simulated_stage.h"
#include "eval/skull_frame.h"
#include "reconstruct/board.h"
#include "reconstruct/calibration.h"
#include "reconstruct/jaw_pose.h"
#include "reconstruct/marker_detection.h"
#include "reconstruct/pipeline.h"
#include "reconstruct/synthetic_views.h"
#include "reconstruct/triangulation.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"

namespace {

using facedyn::Json;
using namespace facedyn::reconstruct;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}

// One camera image of the markers on `skin`: disks of the markers' diameter, dark on skin.
cv::Mat RenderMarkers(const facedyn::FaceRig& rig, const Camera& camera,
                      const Eigen::Matrix3Xd& markers, const Eigen::Matrix3Xd& normals,
                      std::mt19937* rng) {
  std::vector<std::vector<Eigen::Vector2d>> disks;
  for (int m = 0; m < markers.cols(); ++m) {
    const auto outline = ProjectDiskOutline(camera, markers.col(m), normals.col(m),
                                            0.5 * rig.markers[m].diameter_mm);
    if (outline.size() >= 3) disks.push_back(outline);
  }
  cv::Mat image = RenderPolygons(camera.width_px, camera.height_px, disks, 170, 40, 4);
  cv::GaussianBlur(image, image, cv::Size(0, 0), 0.8);
  AddImageNoise(2.0, rng, &image);
  return image;
}

Json BenchDetection(const facedyn::FaceRig& rig, const facedyn::Take& take, int frames,
                    int threads) {
  const std::vector<Camera> cameras = MakeFaceCameraRing(8);
  std::mt19937 rng(1);
  // As `facedyn reconstruct --marker-diameter-px` sets them: 2 mm dots at 600 mm, f = 2200.
  const MarkerDetectionOptions detection = MarkerDetectionOptionsForDiameter(2.0 * 2200.0 / 600.0);
  double detect_s = 0.0, triangulate_s = 0.0, sq2d = 0.0, sq3d = 0.0, sq2d_facing = 0.0;
  double candidates_ms = 0.0, fit_ms = 0.0, occlusion_ms = 0.0, read_s = 0.0;
  long candidates = 0, fits = 0, iterations = 0, evaluations = 0, occlusion_fits = 0, refitted = 0,
       pixel_evaluations = 0, occlusion_iterations = 0;
  int n2d = 0, n3d = 0, detections = 0, points = 0, visible = 0, unmatched = 0, n2d_facing = 0;
  for (int k = 0; k < frames; ++k) {
    const int f = (k * 7) % take.frame_count();
    const Eigen::Matrix3Xd skin = take.FramePositions(f);
    const Eigen::Matrix3Xd markers = MarkerPositions(rig, skin);
    const Eigen::Matrix3Xd normals = MarkerNormals(rig, skin);
    std::vector<cv::Mat> images;
    for (const Camera& camera : cameras)
      images.push_back(RenderMarkers(rig, camera, markers, normals, &rng));
    // The floor: what merely reading every pixel of the 8 images once costs (a sum per image,
    // on the same threads), so the detection rate can be read against the memory bandwidth.
    auto start = Clock::now();
    {
      std::vector<double> sums(images.size());
      std::atomic<size_t> next{0};
      auto work = [&] {
        for (size_t i = next++; i < images.size(); i = next++) sums[i] = cv::sum(images[i])[0];
      };
      std::vector<std::thread> pool;
      for (int t = 1; t < threads; ++t) pool.emplace_back(work);
      work();
      for (std::thread& thread : pool) thread.join();
      if (sums[0] < 0) std::abort();  // keeps the sums live
    }
    read_s += Seconds(start);
    start = Clock::now();
    std::vector<std::vector<ImageObservation>> observed(cameras.size());
    std::vector<MarkerDetectionSummary> summaries;
    const auto found_all = DetectMarkersInImages(images, detection, threads, &summaries);
    for (const MarkerDetectionSummary& summary : summaries) {
      candidates_ms += summary.candidates_ms;
      fit_ms += summary.fit_ms;
      occlusion_ms += summary.occlusion_ms;
      candidates += summary.candidates;
      fits += summary.fits;
      iterations += summary.fit_iterations;
      evaluations += summary.fit_evaluations;
      pixel_evaluations += summary.fit_pixel_evaluations;
      occlusion_fits += summary.occlusion_fits;
      occlusion_iterations += summary.occlusion_iterations;
      refitted += summary.refitted_for_occlusion;
    }
    for (size_t c = 0; c < cameras.size(); ++c) {
      const auto& found = found_all[c];
      if (!found.ok()) continue;
      for (const MarkerDetection& d : *found) {
        ImageObservation o;
        o.camera = static_cast<int>(c);
        o.detection = static_cast<int>(observed[c].size());
        o.pixel = d.center_px;
        o.weight = d.quality;
        observed[c].push_back(o);
      }
    }
    detect_s += Seconds(start);
    start = Clock::now();
    const auto triangulated = TriangulateDetections(cameras, observed, CorrespondenceOptions());
    triangulate_s += Seconds(start);
    // Accuracy against the truth: each detection to the nearest projected marker centre, over
    // every dot the renderer drew (any marker facing the camera, however obliquely).
    const MarkerViews truth = ProjectMarkers(cameras, markers, normals, 0.0, &rng, 1e-9);
    for (size_t c = 0; c < cameras.size(); ++c) {
      visible += static_cast<int>(truth.detections[c].size());
      detections += static_cast<int>(observed[c].size());
      const Eigen::Vector3d camera_center = cameras[c].CenterInWorld();
      for (const ImageObservation& o : observed[c]) {
        double best = 1e9;
        int marker = -1;
        for (size_t i = 0; i < truth.detections[c].size(); ++i) {
          const double distance = (truth.detections[c][i].pixel - o.pixel).norm();
          if (distance < best) {
            best = distance;
            marker = truth.truth[c][i];
          }
        }
        if (best < 2.0) {
          sq2d += best * best;
          ++n2d;
          // Facing the camera at a cosine of at least 0.2 (the synthetic views' default; the
          // figure earlier versions of this bench reported).
          const double cosine =
              normals.col(marker).dot((camera_center - markers.col(marker)).normalized());
          if (cosine >= 0.2) {
            sq2d_facing += best * best;
            ++n2d_facing;
          }
        } else {
          ++unmatched;
        }
      }
    }
    for (const TriangulatedPoint& p : triangulated) {
      const double d = (markers.colwise() - p.position_in_world).colwise().norm().minCoeff();
      if (d < 1.0) {
        sq3d += d * d;
        ++n3d;
      }
    }
    points += static_cast<int>(triangulated.size());
  }
  Json out;
  out["cameras"] = 8;
  out["threads"] = threads;
  out["image_size"] = {1280, 1024};
  out["frames"] = frames;
  out["read_images_ms_per_frame"] = 1e3 * read_s / frames;
  out["read_images_fps"] = frames / read_s;
  out["detect_ms_per_frame"] = 1e3 * detect_s / frames;
  out["detect_fps"] = frames / detect_s;
  // Per image, summed over the threads (CPU time of each stage, not wall time of the frame).
  out["per_image_ms"] = {{"candidates", candidates_ms / (frames * cameras.size())},
                         {"fits", fit_ms / (frames * cameras.size())},
                         {"occlusion_and_merge", occlusion_ms / (frames * cameras.size())}};
  out["candidates_per_image"] = static_cast<double>(candidates) / (frames * cameras.size());
  out["fits_per_image"] = static_cast<double>(fits) / (frames * cameras.size());
  out["iterations_per_fit"] = static_cast<double>(iterations) / std::max(1L, fits);
  out["evaluations_per_fit"] = static_cast<double>(evaluations) / std::max(1L, fits);
  out["window_pixels_per_evaluation"] =
      static_cast<double>(pixel_evaluations) / std::max(1L, evaluations);
  out["fit_ns_per_pixel_evaluation"] = 1e6 * fit_ms / std::max(1L, pixel_evaluations);
  out["occlusion_fits_per_image"] = static_cast<double>(occlusion_fits) / (frames * cameras.size());
  out["iterations_per_occlusion_fit"] =
      static_cast<double>(occlusion_iterations) / std::max(1L, occlusion_fits);
  out["occlusion_refits_kept_per_image"] =
      static_cast<double>(refitted) / (frames * cameras.size());
  out["triangulate_ms_per_frame"] = 1e3 * triangulate_s / frames;
  out["detect_triangulate_fps"] = frames / (detect_s + triangulate_s);
  out["visible_markers_per_frame"] = static_cast<double>(visible) / frames;
  out["detections_per_frame"] = static_cast<double>(detections) / frames;
  // Detections more than 2 px from every rendered marker's projected centre, per frame.
  out["unmatched_detections_per_frame"] = static_cast<double>(unmatched) / frames;
  out["centre_rms_px"] = std::sqrt(sq2d / std::max(1, n2d));
  out["centre_rms_px_facing"] = std::sqrt(sq2d_facing / std::max(1, n2d_facing));
  out["points_per_frame"] = static_cast<double>(points) / frames;
  out["marker_rms_mm"] = std::sqrt(sq3d / std::max(1, n3d));
  return out;
}

// The skull poses of `tracked` by SkullPoseEstimator::EstimateTake with `options`, scored
// against the simulator's from frame `skip` (eval::ScoreSkullPoses), with the take-level
// reference's correction.
Json ScoreTakePoses(const facedyn::FaceRig& rig, const facedyn::Take& take,
                    const std::vector<TrackedFrame>& tracked, const SkullPoseOptions& options,
                    int skip) {
  const SkullPoseEstimator estimator(rig, options);
  TakeReferenceResult reference;
  std::vector<facedyn::Rigid3> poses;
  for (const SkullPoseResult& r : estimator.EstimateTake(tracked, &reference))
    poses.push_back(r.world_from_skull);
  Json out = facedyn::eval::SkullPoseErrorJson(facedyn::eval::ScoreSkullPoses(
      poses, take.world_from_skull,
      {skip, std::min(take.frame_count(), static_cast<int>(poses.size()))}));
  out["take_reference_correction_rms_mm"] = reference.applied ? reference.correction_rms_mm : 0.0;
  return out;
}

Json BenchPipeline(const facedyn::FaceRig& rig, const facedyn::Take& take) {
  const std::vector<Camera> cameras = MakeFaceCameraRing(8);
  std::mt19937 rng(2);
  std::vector<std::vector<std::vector<ImageObservation>>> detections;
  for (int f = 0; f < take.frame_count(); ++f) {
    const Eigen::Matrix3Xd skin = take.FramePositions(f);
    detections.push_back(
        ProjectMarkers(cameras, MarkerPositions(rig, skin), MarkerNormals(rig, skin), 0.2, &rng)
            .detections);
  }
  const auto start = Clock::now();
  const auto result =
      ReconstructTake(rig, cameras, detections, take.info.fps, ReconstructionOptions());
  const double total_s = Seconds(start);
  Json out;
  if (!result.ok()) {
    out["error"] = result.status().message();
    return out;
  }
  const auto& quasistatic = take.channels.at("quasistatic");
  const int skip = static_cast<int>(std::lround(0.5 * take.info.fps));
  double sq_sample = 0.0, sq_t = 0.0, sq_r = 0.0, max_t = 0.0, max_r = 0.0;
  int n_sample = 0, n_pose = 0;
  double sab = 0.0, saa = 0.0, sbb = 0.0, sa = 0.0, sb = 0.0;
  long n_offset = 0;
  for (int f = skip; f < take.frame_count(); ++f) {
    const facedyn::Rigid3 difference =
        take.world_from_skull[f].Inverse() * result->take.world_from_skull[f];
    const double t = difference.translation().norm(), r = difference.AngleRad() * 180.0 / M_PI;
    sq_t += t * t;
    sq_r += r * r;
    max_t = std::max(max_t, t);
    max_r = std::max(max_r, r);
    ++n_pose;
    const Eigen::Matrix3Xd fitted = rig.SamplePositions(result->take.FramePositions(f));
    const Eigen::Matrix3Xd dynamic = rig.SamplePositions(take.FramePositions(f));
    const Eigen::Matrix3Xd still = rig.SamplePositions(quasistatic.Frame(f).cast<double>());
    sq_sample += (fitted - dynamic).colwise().squaredNorm().sum();
    n_sample += static_cast<int>(fitted.cols());
    const Eigen::Matrix3d rotation = take.world_from_skull[f].Inverse().RotationMatrix();
    const Eigen::Matrix3Xd a = rotation * (fitted - still), b = rotation * (dynamic - still);
    for (int i = 0; i < a.size(); ++i) {
      sa += a.data()[i];
      sb += b.data()[i];
      sab += a.data()[i] * b.data()[i];
      saa += a.data()[i] * a.data()[i];
      sbb += b.data()[i] * b.data()[i];
      ++n_offset;
    }
  }
  const double cov = sab / n_offset - (sa / n_offset) * (sb / n_offset);
  const double va = saa / n_offset - std::pow(sa / n_offset, 2),
               vb = sbb / n_offset - std::pow(sb / n_offset, 2);
  const int frames = take.frame_count();
  out["frames"] = frames;
  out["cameras"] = 8;
  out["detection_noise_px"] = 0.2;
  out["total_s"] = total_s;
  out["triangulate_fps"] = frames / result->timings.triangulate_s;
  out["track_fps"] = frames / result->timings.track_s;
  out["dense_fit_fps"] = frames / result->timings.dense_s;
  out["skull_origin_rms_mm"] = std::sqrt(sq_t / n_pose);
  out["skull_origin_max_mm"] = max_t;
  out["skull_rotation_rms_deg"] = std::sqrt(sq_r / n_pose);
  out["skull_rotation_max_deg"] = max_r;
  out["sample_rms_mm"] = std::sqrt(sq_sample / n_sample);
  out["dynamic_offset_correlation"] = cov / std::sqrt(va * vb);
  out["dynamic_offset_true_rms_mm"] = std::sqrt(sbb / n_offset);
  out["evaluated_from_s"] = 0.5;
  out["skull_deflection_shape"] =
      SkullPoseEstimator(rig, SkullPoseOptions()).deflection_shape_used();
  // The skull pose again from the same labelled markers with each deflection shape
  // (skull_pose.h): RMS error at the origin and in rotation, and what varies over the take
  // (the RMS about the take's mean error, which a constant offset of the skull frame does not
  // enter).
  Json by_shape = Json::object();
  for (const auto& [name, shape] :
       {std::pair{"thickness_squared", DeflectionShape::kThicknessSquared},
        std::pair{"tissue_model", DeflectionShape::kTissueModel},
        std::pair{"tissue_model_rig_reference", DeflectionShape::kTissueModel},
        std::pair{"tissue_model_joint_rotation", DeflectionShape::kTissueModel}}) {
    SkullPoseOptions options;
    options.deflection_shape = shape;
    options.rotation_from_thickness_law = std::string(name) != "tissue_model_joint_rotation";
    options.take_reference = std::string(name) != "tissue_model_rig_reference";
    by_shape[name] = ScoreTakePoses(rig, take, result->tracked, options, skip);
  }
  out["skull_pose_by_deflection_shape"] = by_shape;
  // The jaw through the full pipeline (a smile barely moves it: this is the false-opening figure).
  if (!result->take.skull_from_jaw.empty() && !take.skull_from_jaw.empty()) {
    double sq_jaw = 0.0;
    for (int f = skip; f < take.frame_count(); ++f) {
      const double e = JawHingeAngleRad(rig.jaw, result->take.skull_from_jaw[f]) -
                       JawHingeAngleRad(rig.jaw, take.skull_from_jaw[f]);
      sq_jaw += std::pow(e * 180.0 / M_PI, 2);
    }
    out["jaw_angle_rms_deg"] = std::sqrt(sq_jaw / n_pose);
  }
  return out;
}

// The jaw alone (no dense fit, which does not feed it): detections -> triangulation ->
// tracking -> skull pose -> jaw pose, errors against the simulator's skull_from_jaw.
Json BenchJaw(const facedyn::FaceRig& rig, const std::string& expression, double seconds) {
  facedyn::sim::PerformanceOptions performance;
  performance.expression = expression;
  performance.motion.kind = facedyn::sim::MotionKind::kPlatform;
  performance.motion.platform_hz = 11.0;
  performance.motion.amplitude_mm = 2.0;
  performance.seconds = seconds;
  performance.fps = 128.0;
  Json out;
  const auto take = facedyn::sim::SimulatePerformance(rig, performance);
  if (!take.ok()) {
    out["error"] = take.status().message();
    return out;
  }
  const std::vector<Camera> cameras = MakeFaceCameraRing(8);
  std::mt19937 rng(3);
  MarkerTracker tracker(rig, TrackingOptions());
  for (int f = 0; f < take->frame_count(); ++f) {
    const Eigen::Matrix3Xd skin = take->FramePositions(f);
    const MarkerViews views =
        ProjectMarkers(cameras, MarkerPositions(rig, skin), MarkerNormals(rig, skin), 0.2, &rng);
    (void)tracker.AddFrame(
        TriangulateDetections(cameras, views.detections, CorrespondenceOptions()));
  }
  const std::vector<TrackedFrame> tracked = tracker.Finish();
  const SkullPoseEstimator skull(rig, SkullPoseOptions());
  std::vector<facedyn::Rigid3> poses;
  for (const TrackedFrame& frame : tracked) poses.push_back(skull.Estimate(frame).world_from_skull);
  const JawPoseEstimator jaw(rig, JawPoseOptions());
  if (!jaw.status().ok() || !jaw.has_jaw()) {
    out["error"] = jaw.status().ok() ? "the rig has no jaw" : jaw.status().message();
    return out;
  }
  const auto start = Clock::now();
  const JawSequence sequence = EstimateJawSequence(jaw, tracked, poses);
  const double jaw_s = Seconds(start);
  double sq_a = 0, sq_p = 0, sq_c = 0, max_a = 0, max_p = 0, max_c = 0, true_max = 0;
  int carried = 0;
  const int frames = take->frame_count();
  for (int f = 0; f < frames; ++f) {
    const JawPoseDifference d =
        CompareJawPoses(rig.jaw, jaw.reference_point_in_skull(), sequence.skull_from_jaw[f],
                        take->skull_from_jaw[f]);
    const double a = std::abs(d.angle_rad) * 180.0 / M_PI;
    sq_a += a * a;
    sq_p += d.pivot_mm * d.pivot_mm;
    sq_c += d.point_mm * d.point_mm;
    max_a = std::max(max_a, a);
    max_p = std::max(max_p, d.pivot_mm);
    max_c = std::max(max_c, d.point_mm);
    true_max = std::max(
        true_max, std::abs(JawHingeAngleRad(rig.jaw, take->skull_from_jaw[f])) * 180.0 / M_PI);
    carried += sequence.carried[f] ? 1 : 0;
  }
  out["frames"] = frames;
  out["platform_hz"] = 11.0;
  out["detection_noise_px"] = 0.2;
  out["jaw_markers"] = jaw.jaw_markers().size();
  out["true_angle_max_deg"] = true_max;
  out["angle_rms_deg"] = std::sqrt(sq_a / frames);
  out["angle_max_deg"] = max_a;
  out["pivot_rms_mm"] = std::sqrt(sq_p / frames);
  out["pivot_max_mm"] = max_p;
  out["chin_rms_mm"] = std::sqrt(sq_c / frames);
  out["chin_max_mm"] = max_c;
  out["frames_carried_over"] = carried;
  out["jaw_fps"] = frames / std::max(jaw_s, 1e-9);
  return out;
}

// Where a constant skull-pose offset comes from (issue 20: the demo's filmed take showed 0.26 mm
// constant against 0.02 mm varying). The 11 Hz smile reconstructed four ways, each scored with
// eval::ScoreSkullPoses, and each with the triangulated markers' bias against the simulator's
// markers in the true skull frame (mean over frames of observed markers, all markers and the
// skull pose's stable ones; "normal" is the component along the skin's outward normal):
//   projected centres through the true cameras / through the calibrated cameras (the
//   calibration's share), filmed (rendered, dots detected) through the true cameras (the
//   detector's share) / through the calibrated cameras (what the demo does).
Json MarkerBias(const facedyn::FaceRig& rig, const facedyn::Take& take,
                const Reconstruction& result, const std::vector<int>& stable, int skip) {
  const int markers = static_cast<int>(rig.markers.size());
  std::vector<Eigen::Vector3d> sum(markers, Eigen::Vector3d::Zero());
  std::vector<double> normal_sum(markers, 0.0);
  std::vector<int> count(markers, 0);
  double sq = 0.0;
  long n = 0;
  for (int f = skip; f < take.frame_count() && f < static_cast<int>(result.tracked.size()); ++f) {
    const TrackedFrame& frame = result.tracked[f];
    const Eigen::Matrix3Xd skin = take.FramePositions(f);
    const Eigen::Matrix3Xd truth = MarkerPositions(rig, skin), normals = MarkerNormals(rig, skin);
    const Eigen::Matrix3d skull_from_world = take.world_from_skull[f].Inverse().RotationMatrix();
    for (int i = 0; i < markers; ++i) {
      if (frame.states[i] != MarkerState::kObserved) continue;
      const Eigen::Vector3d e = frame.positions_in_world.col(i) - truth.col(i);
      sum[i] += skull_from_world * e;
      normal_sum[i] += e.dot(normals.col(i));
      ++count[i];
      sq += e.squaredNorm();
      ++n;
    }
  }
  auto summarise = [&](const std::vector<int>& which) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    double normal = 0.0, per_marker_sq = 0.0;
    int used = 0;
    for (int i : which) {
      if (count[i] == 0) continue;
      mean += sum[i] / count[i];
      normal += normal_sum[i] / count[i];
      per_marker_sq += (sum[i] / count[i]).squaredNorm();
      ++used;
    }
    if (used == 0) return Json{{"markers", 0}};
    mean /= used;
    return Json{{"markers", used},
                {"mean_in_true_skull_mm", {mean.x(), mean.y(), mean.z()}},
                {"mean_along_normal_mm", normal / used},
                {"per_marker_mean_rms_mm", std::sqrt(per_marker_sq / used)}};
  };
  std::vector<int> all(markers);
  for (int i = 0; i < markers; ++i) all[i] = i;
  return {{"observed_rms_mm", n ? std::sqrt(sq / n) : 0.0},
          {"all_markers", summarise(all)},
          {"stable_markers", summarise(stable)}};
}

Json BenchSkullOffset(const facedyn::FaceRig& rig, const facedyn::Take& take) {
  Json out;
  const auto cameras = facedyn::eval::CalibrateSimulatedCameraRig(60, 2020);
  if (!cameras.ok()) {
    out["error"] = cameras.status().message();
    return out;
  }
  facedyn::eval::SimulatedCameraRig true_cameras = *cameras;
  true_cameras.calibration.cameras = cameras->truth;
  const int skip = static_cast<int>(std::lround(0.5 * take.info.fps));
  const facedyn::dynamics::FrameRange scored{skip, take.frame_count()};
  const SkullPoseEstimator estimator(rig, SkullPoseOptions());
  out["frames"] = take.frame_count();
  out["calibration_worst_centre_error_mm"] = cameras->worst_centre_error_mm;
  for (const auto& [name, filmed, calibrated] :
       {std::tuple{"projected_true_cameras", false, false},
        std::tuple{"projected_calibrated_cameras", false, true},
        std::tuple{"filmed_true_cameras", true, false},
        std::tuple{"filmed_calibrated_cameras", true, true}}) {
    const facedyn::eval::SimulatedCameraRig& used = calibrated ? *cameras : true_cameras;
    const auto result = filmed ? facedyn::eval::FilmSimulatedTake(rig, used, take, 2021)
                               : facedyn::eval::ReconstructSimulatedTake(rig, used, take, 2);
    if (!result.ok()) {
      out[name] = {{"error", result.status().message()}};
      continue;
    }
    SkullPoseOptions rig_reference;
    rig_reference.take_reference = false;
    out[name] = {{"skull_pose", facedyn::eval::SkullPoseErrorJson(facedyn::eval::ScoreSkullPoses(
                                    result->take.world_from_skull, take.world_from_skull, scored))},
                 {"skull_pose_rig_reference",
                  ScoreTakePoses(rig, take, result->tracked, rig_reference, skip)},
                 {"skull_reference", result->take.info.metadata.value("skull_reference", Json())},
                 {"marker_bias", MarkerBias(rig, take, *result, estimator.stable_markers(), skip)}};
  }
  return out;
}

Json BenchCalibration(const std::string& shared) {
  Json out;
  const std::string dir = shared + "/assets/opencv-calib";
  if (!std::filesystem::is_directory(dir)) {
    out["opencv_photographs"] = "not present (" + dir + ")";
  } else {
    const BoardSpec board = *BoardSpec::Parse("chessboard:9x6:1");
    CalibrationInput input;
    input.board = board;
    input.cameras.push_back({"left", 640, 480});
    std::vector<std::vector<cv::Point3f>> object_points;
    std::vector<std::vector<cv::Point2f>> image_points;
    for (int i = 1; i <= 14; ++i) {
      char name[32];
      std::snprintf(name, sizeof(name), "/left%02d.jpg", i);
      const cv::Mat gray = cv::imread(dir + name, cv::IMREAD_GRAYSCALE);
      if (gray.empty()) continue;
      const auto corners = DetectBoard(gray, board);
      if (!corners.ok()) continue;
      input.view_names.push_back(name + 1);
      input.observations.push_back({0, static_cast<int>(input.view_names.size()) - 1, *corners});
      object_points.emplace_back();
      image_points.emplace_back();
      for (int k = 0; k < corners->size(); ++k) {
        const Eigen::Vector3d p = board.CornerInBoard(corners->corner_ids[k]);
        object_points.back().emplace_back(p.x(), p.y(), 0.0f);
        image_points.back().emplace_back(corners->pixels[k].x(), corners->pixels[k].y());
      }
    }
    const auto start = Clock::now();
    CalibrationSummary summary;
    const auto result = Calibrate(input, CalibrationOptions(), &summary);
    const double ours_s = Seconds(start);
    cv::Mat k, distortion;
    std::vector<cv::Mat> rvecs, tvecs;
    const auto cv_start = Clock::now();
    const double cv_rms = cv::calibrateCamera(object_points, image_points, cv::Size(640, 480), k,
                                              distortion, rvecs, tvecs);
    const double cv_s = Seconds(cv_start);
    Json photos;
    photos["images"] = input.view_names.size();
    if (result.ok()) {
      const Camera& c = result->cameras[0];
      photos["rms_px"] = result->rms_px;
      photos["outliers"] = summary.outliers;
      photos["fx"] = c.fx();
      photos["fy"] = c.fy();
      photos["cx"] = c.cx();
      photos["cy"] = c.cy();
      photos["seconds"] = ours_s;
      photos["fx_rel_diff_vs_opencv"] = (c.fx() - k.at<double>(0, 0)) / k.at<double>(0, 0);
      photos["cx_rel_diff_vs_opencv"] = (c.cx() - k.at<double>(0, 2)) / k.at<double>(0, 2);
      photos["cy_rel_diff_vs_opencv"] = (c.cy() - k.at<double>(1, 2)) / k.at<double>(1, 2);
    } else {
      photos["error"] = result.status().message();
    }
    photos["opencv"] = {{"rms_px", cv_rms},         {"fx", k.at<double>(0, 0)},
                        {"fy", k.at<double>(1, 1)}, {"cx", k.at<double>(0, 2)},
                        {"cy", k.at<double>(1, 2)}, {"seconds", cv_s}};
    out["opencv_photographs"] = photos;
  }
  // Synthetic 4-camera rig, 40 ChArUco views, 0.3 px noise per axis.
  CameraRingOptions ring;
  ring.camera_count = 4;
  ring.focal_px = 1800.0;
  ring.radius_mm = 700.0;
  ring.arc_deg = 90.0;
  std::vector<Camera> cameras = MakeCameraRing(ring);
  CalibrationInput input;
  input.board = *BoardSpec::Parse("charuco:10x7:25:18");
  for (const Camera& c : cameras) input.cameras.push_back({c.name, c.width_px, c.height_px});
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.3);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  double sq = 0.0;
  int n = 0;
  for (int v = 0; v < 40; ++v) {
    const facedyn::Rigid3 world_from_board =
        facedyn::Rigid3::FromTranslation(
            Eigen::Vector3d(80 * uniform(rng), 60 * uniform(rng), 80 * uniform(rng))) *
        facedyn::Rigid3::FromAxisAngle(
            Eigen::Vector3d(uniform(rng), uniform(rng), 0.3 * uniform(rng)).normalized(),
            0.6 * std::abs(uniform(rng))) *
        facedyn::Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), M_PI) *
        facedyn::Rigid3::FromTranslation(-Eigen::Vector3d(137.5, 100, 0));
    input.view_names.push_back("v" + std::to_string(v));
    for (int c = 0; c < 4; ++c) {
      BoardObservation o;
      for (int id = 0; id < input.board.corner_count(); ++id) {
        const Eigen::Vector3d p = world_from_board * input.board.CornerInBoard(id);
        if (world_from_board.RotateVector(-Eigen::Vector3d::UnitZ())
                .dot(cameras[c].CenterInWorld() - p) <= 0)
          continue;
        Eigen::Vector2d pixel;
        if (!cameras[c].Project(p, &pixel) || !cameras[c].InImage(pixel, 5)) continue;
        const Eigen::Vector2d e(noise(rng), noise(rng));
        sq += e.squaredNorm();
        ++n;
        o.corner_ids.push_back(id);
        o.pixels.push_back(pixel + e);
      }
      if (o.size() > 0) input.observations.push_back({c, v, o});
    }
  }
  const auto start = Clock::now();
  const auto result = Calibrate(input, CalibrationOptions());
  Json rig;
  rig["cameras"] = 4;
  rig["views"] = 40;
  rig["injected_rms_px"] = std::sqrt(sq / n);
  if (result.ok()) {
    rig["rms_px"] = result->rms_px;
    rig["seconds"] = Seconds(start);
    Eigen::Matrix3Xd a(3, 4), b(3, 4);
    for (int c = 0; c < 4; ++c) {
      a.col(c) = result->cameras[c].CenterInWorld();
      b.col(c) = cameras[c].CenterInWorld();
    }
    const Eigen::Matrix4d b_from_a = Eigen::umeyama(a, b, false);
    double worst = 0.0;
    for (int c = 0; c < 4; ++c) {
      worst = std::max(worst, (b_from_a.topLeftCorner<3, 3>() * a.col(c) +
                               b_from_a.topRightCorner<3, 1>() - b.col(c))
                                  .norm());
    }
    rig["worst_centre_error_mm_after_rigid_alignment"] = worst;
  } else {
    rig["error"] = result.status().message();
  }
  out["synthetic_rig"] = rig;
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::string shared = std::string(FACEDYN_SOURCE_DIR) + "/../shared";
  int frames = 10;
  double seconds = 1.5;
  std::string stage = "all";
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--shared" && i + 1 < argc) {
      shared = argv[++i];
    } else if (arg == "--frames" && i + 1 < argc) {
      frames = std::max(1, static_cast<int>(facedyn::bench::FlagInteger("reconstruct_bench",
                                                                        "--frames", argv[++i])));
    } else if (arg == "--seconds" && i + 1 < argc) {
      seconds =
          std::max(0.75, facedyn::bench::FlagNumber("reconstruct_bench", "--seconds", argv[++i]));
    } else if (arg == "--stage" && i + 1 < argc) {
      stage = argv[++i];
      if (stage != "all" && stage != "detection" && stage != "pipeline" && stage != "jaw" &&
          stage != "calibration" && stage != "skull_offset") {
        std::fprintf(stderr,
                     "reconstruct_bench: --stage must be all, detection, pipeline, jaw, "
                     "skull_offset or calibration, not '%s'\n",
                     stage.c_str());
        return 2;
      }
    } else {
      std::fprintf(stderr,
                   "usage: reconstruct_bench [--shared DIR] [--frames N] [--seconds S] "
                   "[--stage all|detection|pipeline|jaw|skull_offset|calibration]\n");
      return 2;
    }
  }
  facedyn::SetDefaultProgressMode(facedyn::ProgressMode::kSilent);
  const auto rig = facedyn::sim::MakeProceduralFace(facedyn::sim::ProceduralFaceOptions());
  if (!rig.ok()) {
    std::fprintf(stderr, "%s\n", rig.status().message().c_str());
    return 1;
  }
  facedyn::sim::PerformanceOptions performance;
  performance.expression = "smile";
  performance.motion.kind = facedyn::sim::MotionKind::kPlatform;
  performance.motion.platform_hz = 11.0;
  performance.motion.amplitude_mm = 2.0;
  performance.seconds = seconds;
  performance.fps = 128.0;
  const auto take = facedyn::sim::SimulatePerformance(*rig, performance);
  if (!take.ok()) {
    std::fprintf(stderr, "%s\n", take.status().message().c_str());
    return 1;
  }
  Json out;
  out["machine"] = {{"hardware_threads", std::thread::hardware_concurrency()}};
  const auto wanted = [&](const char* name) { return stage == "all" || stage == name; };
  if (wanted("detection")) {
    out["detection_triangulation_1_thread"] = BenchDetection(*rig, *take, frames, 1);
    out["detection_triangulation"] =
        BenchDetection(*rig, *take, frames, static_cast<int>(std::thread::hardware_concurrency()));
  }
  if (wanted("pipeline")) out["pipeline_11hz_smile"] = BenchPipeline(*rig, *take);
  if (wanted("jaw")) {
    out["jaw"] = {{"jaw_open_11hz", BenchJaw(*rig, "jaw_open", seconds)},
                  {"speech_11hz", BenchJaw(*rig, "speech", std::max(seconds, 2.0))}};
  }
  if (wanted("skull_offset")) out["skull_offset_11hz_smile"] = BenchSkullOffset(*rig, *take);
  if (wanted("calibration")) out["calibration"] = BenchCalibration(shared);
  std::printf("%s\n", out.dump(2).c_str());
  return 0;
}
