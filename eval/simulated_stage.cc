#include "eval/simulated_stage.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <opencv2/core.hpp>
#include <optional>
#include <random>
#include <string>
#include <utility>

#include "core/parallel_for.h"
#include "core/progress.h"
#include "reconstruct/calibration.h"
#include "reconstruct/marker_detection.h"
#include "reconstruct/pipeline.h"
#include "reconstruct/synthetic_views.h"

namespace facedyn::eval {

using namespace facedyn::reconstruct;

StatusOr<SimulatedCameraRig> CalibrateSimulatedCameraRig(int board_views, uint64_t seed) {
  if (board_views < 3) {
    return InvalidArgumentError("calibration needs at least 3 board views, got " +
                                std::to_string(board_views));
  }
  std::mt19937 rng(static_cast<std::mt19937::result_type>(seed));
  SimulatedCameraRig rig;
  rig.truth = MakeFaceCameraRing(8);
  const std::vector<Camera>& truth = rig.truth;
  CalibrationInput input;
  input.board = *BoardSpec::Parse("charuco:10x7:25:18");
  for (const Camera& c : truth) input.cameras.push_back({c.name, c.width_px, c.height_px});
  std::normal_distribution<double> noise(0.0, 0.2);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const Eigen::Vector3d board_centre(137.5, 100.0, 0.0);
  for (int v = 0; v < board_views; ++v) {
    // In front of the face, facing the cameras, tilted up to ~35 degrees.
    const Rigid3 world_from_board =
        Rigid3::FromTranslation(
            Eigen::Vector3d(60 * uniform(rng), -15 + 50 * uniform(rng), 60 + 60 * uniform(rng))) *
        Rigid3::FromAxisAngle(
            Eigen::Vector3d(uniform(rng), uniform(rng), 0.3 * uniform(rng)).normalized(),
            0.6 * std::abs(uniform(rng))) *
        Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), M_PI) *
        Rigid3::FromTranslation(-board_centre);
    input.view_names.push_back("view" + std::to_string(v));
    const Eigen::Vector3d normal = world_from_board.RotateVector(-Eigen::Vector3d::UnitZ());
    for (size_t c = 0; c < truth.size(); ++c) {
      BoardObservation observation;
      for (int id = 0; id < input.board.corner_count(); ++id) {
        const Eigen::Vector3d p = world_from_board * input.board.CornerInBoard(id);
        if (normal.dot(truth[c].CenterInWorld() - p) <= 0) continue;
        Eigen::Vector2d pixel;
        if (!truth[c].Project(p, &pixel) || !truth[c].InImage(pixel, 5)) continue;
        observation.corner_ids.push_back(id);
        observation.pixels.push_back(pixel + Eigen::Vector2d(noise(rng), noise(rng)));
      }
      if (observation.size() > 0)
        input.observations.push_back({static_cast<int>(c), v, observation});
    }
  }
  FACEDYN_ASSIGN_OR_RETURN(rig.calibration, Calibrate(input, CalibrationOptions()));
  RigCalibration& calibration = rig.calibration;
  Eigen::Matrix3Xd a(3, truth.size()), b(3, truth.size());
  for (size_t c = 0; c < truth.size(); ++c) {
    a.col(c) = calibration.cameras[c].CenterInWorld();
    b.col(c) = truth[c].CenterInWorld();
  }
  const Eigen::Matrix4d m = Eigen::umeyama(a, b, false);
  const Rigid3 stage_from_calibration = Rigid3::FromMatrix4(m);
  rig.worst_centre_error_mm = 0.0;
  for (size_t c = 0; c < truth.size(); ++c) {
    calibration.cameras[c].cam_from_world =
        calibration.cameras[c].cam_from_world * stage_from_calibration.Inverse();
    rig.worst_centre_error_mm =
        std::max(rig.worst_centre_error_mm,
                 (calibration.cameras[c].CenterInWorld() - truth[c].CenterInWorld()).norm());
  }
  return rig;
}

namespace {

Status CheckSimulatedTake(const FaceRig& face, const Take& simulated) {
  if (simulated.frame_count() == 0) return InvalidArgumentError("the simulated take is empty");
  if (simulated.vertex_count() != face.vertex_count()) {
    return FailedPreconditionError("the simulated take has " +
                                   std::to_string(simulated.vertex_count()) +
                                   " vertices, the face " + std::to_string(face.vertex_count()));
  }
  return Status::Ok();
}

// The reconstruction pipeline on a simulated take's detections through the calibrated
// cameras; the result carries what a capture session records about its take, and `source`
// (how the detections were made) in its metadata.
StatusOr<Reconstruction> ReconstructDetections(
    const FaceRig& face, const SimulatedCameraRig& cameras, const Take& simulated,
    const std::vector<std::vector<std::vector<ImageObservation>>>& detections,
    const std::string& source) {
  FACEDYN_ASSIGN_OR_RETURN(Reconstruction result,
                           ReconstructTake(face, cameras.calibration.cameras, detections,
                                           simulated.info.fps, ReconstructionOptions()));
  result.take.info.subject = simulated.info.subject;
  result.take.info.expression = simulated.info.expression;
  result.take.info.motion = simulated.info.motion;
  result.take.info.platform_hz = simulated.info.platform_hz;
  // When the expression is held is what a capture session records about its take (the sweep
  // step's prompt and settle), not something reconstruction estimates: carried over.
  result.take.info.hold_start_s = simulated.info.hold_start_s;
  result.take.info.metadata["reconstructed_from"] = source;
  return result;
}

}  // namespace

StatusOr<Reconstruction> ReconstructSimulatedTake(const FaceRig& face,
                                                  const SimulatedCameraRig& cameras,
                                                  const Take& simulated, uint64_t seed) {
  FACEDYN_RETURN_IF_ERROR(CheckSimulatedTake(face, simulated));
  std::mt19937 rng(static_cast<std::mt19937::result_type>(seed));
  std::vector<std::vector<std::vector<ImageObservation>>> detections;
  detections.reserve(simulated.frame_count());
  for (int f = 0; f < simulated.frame_count(); ++f) {
    const Eigen::Matrix3Xd skin = simulated.FramePositions(f);
    detections.push_back(ProjectMarkers(cameras.truth, MarkerPositions(face, skin),
                                        MarkerNormals(face, skin), 0.2, &rng)
                             .detections);
  }
  return ReconstructDetections(
      face, cameras, simulated, detections,
      "projected marker centres: the simulated markers' true centres projected into 8 simulated "
      "cameras with 0.2 px Gaussian noise (no rendered images, no marker detection)");
}

StatusOr<Reconstruction> FilmSimulatedTake(const FaceRig& face, const SimulatedCameraRig& cameras,
                                           const Take& simulated, uint64_t seed,
                                           const FilmOptions& options) {
  FACEDYN_RETURN_IF_ERROR(CheckSimulatedTake(face, simulated));
  if (face.markers.empty()) return FailedPreconditionError("the face has no painted markers");
  FACEDYN_RETURN_IF_ERROR(options.render.Check().WithContext("film render options"));
  sim::RenderOptions render = options.render;
  render.seed = seed;
  const sim::FaceRenderer renderer(face, render);
  // The detector is tuned to the dots' diameter in the images: the face's markers at their
  // mean depth in camera 0 on the first frame (what an operator reads off one image).
  const Eigen::Matrix3Xd first = simulated.FramePositions(0);
  double depth = 0.0, diameter_mm = 0.0;
  for (const Marker& marker : face.markers) {
    depth += (cameras.truth[0].cam_from_world * marker.point.Evaluate(first)).z();
    diameter_mm += marker.diameter_mm;
  }
  depth /= face.markers.size();
  diameter_mm /= face.markers.size();
  const double diameter_px = diameter_mm * cameras.truth[0].fx() / depth;
  const MarkerDetectionOptions detection = MarkerDetectionOptionsForDiameter(diameter_px);
  const int camera_count = static_cast<int>(cameras.truth.size());
  std::vector<sim::RenderWorkspace> workspaces(camera_count);
  std::vector<std::vector<std::vector<ImageObservation>>> detections(simulated.frame_count());
  std::vector<cv::Mat> images(camera_count);  // reused: create() keeps the buffers per frame
  std::optional<Progress> progress;
  if (options.progress) progress.emplace("film", simulated.frame_count());
  FilmTimings timings;
  const auto SecondsSince = [](std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  for (int f = 0; f < simulated.frame_count(); ++f) {
    if (progress) progress->Advance();
    const Eigen::Matrix3Xd skin = simulated.FramePositions(f);
    auto start = std::chrono::steady_clock::now();
    FACEDYN_RETURN_IF_ERROR(ParallelFor(camera_count, options.threads, [&](int c) -> Status {
      const Camera& camera = cameras.truth[c];
      images[c].create(camera.height_px, camera.width_px, CV_8UC1);
      renderer.Render(camera, skin, (uint64_t{static_cast<uint64_t>(c)} << 40) ^ uint64_t(f),
                      &workspaces[c], images[c].data);
      return Status::Ok();
    }));
    timings.render_s += SecondsSince(start);
    start = std::chrono::steady_clock::now();
    const auto found = DetectMarkersInImages(images, detection, options.threads);
    timings.detect_s += SecondsSince(start);
    detections[f].resize(camera_count);
    for (int c = 0; c < camera_count; ++c) {
      if (!found[c].ok()) {
        return found[c].status().WithContext("frame " + std::to_string(f) + ", camera " +
                                             cameras.truth[c].name);
      }
      for (const MarkerDetection& d : *found[c]) {
        ImageObservation o;  // as reconstruct/session_input.cc builds them
        o.camera = c;
        o.detection = static_cast<int>(detections[f][c].size());
        o.pixel = d.center_px;
        o.weight = d.quality;
        detections[f][c].push_back(o);
      }
    }
  }
  if (progress) progress->Finish();
  const auto start = std::chrono::steady_clock::now();
  StatusOr<Reconstruction> result = ReconstructDetections(
      face, cameras, simulated, detections,
      "filmed: every frame rendered by 8 simulated cameras (shaded skin, painted dots, blur, "
      "noise, distortion) and the dots detected in the images");
  timings.reconstruct_s = SecondsSince(start);
  if (options.timings) *options.timings = timings;
  return result;
}

}  // namespace facedyn::eval
