#include "app/reconstruct_demo.h"

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <random>
#include <utility>

#include "core/file_util.h"
#include "reconstruct/calibration.h"
#include "reconstruct/pipeline.h"
#include "reconstruct/synthetic_views.h"

namespace facedyn::app {

using namespace facedyn::reconstruct;

StatusOr<DemoCameraRig> CalibrateDemoCameraRig(int board_views, uint64_t seed) {
  if (board_views < 3) {
    return InvalidArgumentError("calibration needs at least 3 board views, got " +
                                std::to_string(board_views));
  }
  std::mt19937 rng(static_cast<std::mt19937::result_type>(seed));
  DemoCameraRig rig;
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

StatusOr<Reconstruction> ReconstructSimulatedTake(const FaceRig& face, const DemoCameraRig& cameras,
                                                  const Take& simulated, uint64_t seed) {
  if (simulated.frame_count() == 0) return InvalidArgumentError("the simulated take is empty");
  if (simulated.vertex_count() != face.vertex_count()) {
    return FailedPreconditionError("the simulated take has " +
                                   std::to_string(simulated.vertex_count()) +
                                   " vertices, the face " + std::to_string(face.vertex_count()));
  }
  std::mt19937 rng(static_cast<std::mt19937::result_type>(seed));
  std::vector<std::vector<std::vector<ImageObservation>>> detections;
  detections.reserve(simulated.frame_count());
  for (int f = 0; f < simulated.frame_count(); ++f) {
    const Eigen::Matrix3Xd skin = simulated.FramePositions(f);
    detections.push_back(ProjectMarkers(cameras.truth, MarkerPositions(face, skin),
                                        MarkerNormals(face, skin), 0.2, &rng)
                             .detections);
  }
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
  result.take.info.metadata["reconstructed_from"] =
      "projected marker centres: the simulated markers' true centres projected into 8 simulated "
      "cameras with 0.2 px Gaussian noise (no rendered images, no marker detection)";
  return result;
}

Status RunReconstructDemoStage(const FaceRig& face, const Take& simulated,
                               const std::string& out_dir, bool quick, Json* metrics,
                               DemoCameraRig* cameras, Take* reconstructed) {
  if (simulated.frame_count() == 0) return InvalidArgumentError("the simulated take is empty");
  const std::string stage_dir = JoinPath(out_dir, "reconstruct");
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(stage_dir));
  FACEDYN_ASSIGN_OR_RETURN(const DemoCameraRig rig, CalibrateDemoCameraRig(quick ? 30 : 60, 2020));
  const RigCalibration& calibration = rig.calibration;
  const double worst_centre_mm = rig.worst_centre_error_mm;
  FACEDYN_RETURN_IF_ERROR(SaveCalibration(calibration, JoinPath(stage_dir, "calibration.yaml")));
  FACEDYN_ASSIGN_OR_RETURN(Reconstruction result,
                           ReconstructSimulatedTake(face, rig, simulated, 2021));
  FACEDYN_RETURN_IF_ERROR(SaveTake(result.take, JoinPath(out_dir, "takes/reconstructed")));

  // Errors against the simulator's truth, after the motion's fade-in.
  const int skip = std::min(simulated.frame_count() - 1,
                            static_cast<int>(std::lround(0.5 * simulated.info.fps)));
  const auto quasistatic = simulated.channels.find("quasistatic");
  double sq_t = 0, sq_r = 0, max_t = 0, max_r = 0, sq_s = 0;
  long n_pose = 0, n_sample = 0;
  // Per scored frame, the pose error's translation (mm) and rotation vector (rad), skull frame.
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> pose_errors;
  double sa = 0, sb = 0, sab = 0, saa = 0, sbb = 0;
  long n_offset = 0;
  Json frames = Json::array();
  for (int f = 0; f < simulated.frame_count(); ++f) {
    const auto& q = result.quality[f];
    frames.push_back({{"frame", f},
                      {"points", q.points},
                      {"labelled", q.labelled},
                      {"reprojection_rms_px", q.reprojection_rms_px},
                      {"fit_marker_rms_mm", q.fit_marker_rms_mm},
                      {"problem", q.problem}});
    if (f < skip) continue;
    const Rigid3 d = simulated.world_from_skull[f].Inverse() * result.take.world_from_skull[f];
    const double t = d.translation().norm(), r = d.AngleRad() * 180.0 / M_PI;
    const Eigen::AngleAxisd axis_angle(d.RotationMatrix());
    pose_errors.push_back({d.translation(), axis_angle.axis() * axis_angle.angle()});
    sq_t += t * t;
    sq_r += r * r;
    max_t = std::max(max_t, t);
    max_r = std::max(max_r, r);
    ++n_pose;
    const Eigen::Matrix3Xd fitted = face.SamplePositions(result.take.FramePositions(f));
    const Eigen::Matrix3Xd dynamic = face.SamplePositions(simulated.FramePositions(f));
    sq_s += (fitted - dynamic).colwise().squaredNorm().sum();
    n_sample += fitted.cols();
    if (quasistatic == simulated.channels.end()) continue;
    const Eigen::Matrix3Xd still =
        face.SamplePositions(quasistatic->second.Frame(f).cast<double>());
    const Eigen::Matrix3d rotation = simulated.world_from_skull[f].Inverse().RotationMatrix();
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
  FACEDYN_RETURN_IF_ERROR(
      WriteJsonFile(JoinPath(stage_dir, "quality.json"), Json{{"frames", frames}}));
  // The jaw (skull_from_jaw) against the simulator's, as the hinge angle and the chin point.
  double sq_jaw_deg = 0, max_jaw_deg = 0, sq_chin = 0;
  long n_jaw = 0;
  if (!simulated.skull_from_jaw.empty() && !result.take.skull_from_jaw.empty()) {
    const JawPoseEstimator estimator(face, ReconstructionOptions().jaw);
    if (estimator.status().ok() && estimator.has_jaw()) {
      for (int f = skip; f < simulated.frame_count(); ++f) {
        const JawPoseDifference d =
            CompareJawPoses(face.jaw, estimator.reference_point_in_skull(),
                            result.take.skull_from_jaw[f], simulated.skull_from_jaw[f]);
        const double deg = std::abs(d.angle_rad) * 180.0 / M_PI;
        sq_jaw_deg += deg * deg;
        max_jaw_deg = std::max(max_jaw_deg, deg);
        sq_chin += d.point_mm * d.point_mm;
        ++n_jaw;
      }
    }
  }
  const int frame_count = simulated.frame_count();
  Json m;
  if (n_jaw > 0) {
    m["jaw_angle_rms_deg"] = std::sqrt(sq_jaw_deg / n_jaw);
    m["jaw_angle_max_deg"] = max_jaw_deg;
    m["jaw_chin_point_rms_mm"] = std::sqrt(sq_chin / n_jaw);
  }
  m["calibration_rms_px"] = calibration.rms_px;
  m["calibration_worst_centre_error_mm"] = worst_centre_mm;
  // Per-camera reprojection RMS over that camera's board corners (the report's bar chart).
  Json per_camera = Json::array();
  for (size_t c = 0; c < calibration.camera_rms_px.size(); ++c) {
    per_camera.push_back(
        {{"camera", "cam" + std::to_string(c)},
         {"rms_px", calibration.camera_rms_px[c]},
         {"corners", c < calibration.camera_corners.size() ? calibration.camera_corners[c] : 0}});
  }
  m["calibration_per_camera"] = per_camera;
  m["skull_origin_rms_mm"] = n_pose ? std::sqrt(sq_t / n_pose) : 0.0;
  m["skull_origin_max_mm"] = max_t;
  m["skull_rotation_rms_deg"] = n_pose ? std::sqrt(sq_r / n_pose) : 0.0;
  m["skull_rotation_max_deg"] = max_r;
  // The same errors less their mean over the take: a constant error (mostly the calibration's
  // and the reference shape's) only renames the skull frame for the whole take, while what
  // varies from frame to frame is what leaks jiggle into every stabilised trajectory (issue 20).
  if (!pose_errors.empty()) {
    Eigen::Vector3d mean_t = Eigen::Vector3d::Zero(), mean_r = Eigen::Vector3d::Zero();
    for (const auto& [t, r] : pose_errors) {
      mean_t += t;
      mean_r += r;
    }
    mean_t /= static_cast<double>(pose_errors.size());
    mean_r /= static_cast<double>(pose_errors.size());
    double var_t = 0, var_r = 0;
    for (const auto& [t, r] : pose_errors) {
      var_t += (t - mean_t).squaredNorm();
      var_r += (r - mean_r).squaredNorm();
    }
    m["skull_origin_constant_mm"] = mean_t.norm();
    m["skull_origin_varying_rms_mm"] = std::sqrt(var_t / pose_errors.size());
    m["skull_rotation_varying_rms_deg"] = std::sqrt(var_r / pose_errors.size()) * 180.0 / M_PI;
  }
  m["sample_rms_mm"] = n_sample ? std::sqrt(sq_s / n_sample) : 0.0;
  if (n_offset > 0) {
    const double cov = sab / n_offset - (sa / n_offset) * (sb / n_offset);
    const double va = saa / n_offset - std::pow(sa / n_offset, 2);
    const double vb = sbb / n_offset - std::pow(sb / n_offset, 2);
    m["dynamic_offset_correlation"] = cov / std::sqrt(va * vb);
  }
  m["triangulate_fps"] = frame_count / std::max(1e-9, result.timings.triangulate_s);
  m["dense_fit_fps"] = frame_count / std::max(1e-9, result.timings.dense_s);
  m["take"] = JoinPath(out_dir, "takes/reconstructed");
  std::printf(
      "\nReconstruction of the simulated take from 8 simulated cameras (0.2 px detection noise):\n"
      "  calibration RMS %.3f px, worst camera centre %.3f mm\n"
      "  skull pose error: origin %.3f mm RMS (max %.3f), rotation %.4f deg RMS (max %.4f);\n"
      "    less its mean over the take (%.3f mm): origin %.3f mm RMS, rotation %.4f deg RMS\n"
      "  jaw hinge angle error %s deg RMS\n"
      "  344 skin samples: %.3f mm RMS; dynamic offsets recovered with correlation %s\n"
      "  triangulation %.0f frames/s, dense fit %.1f frames/s -> %s\n",
      calibration.rms_px, worst_centre_mm, m["skull_origin_rms_mm"].get<double>(), max_t,
      m["skull_rotation_rms_deg"].get<double>(), max_r,
      m.value("skull_origin_constant_mm", 0.0), m.value("skull_origin_varying_rms_mm", 0.0),
      m.value("skull_rotation_varying_rms_deg", 0.0), n_jaw > 0 ? std::to_string(m["jaw_angle_rms_deg"].get<double>()).substr(0, 5).c_str()
                : "n/a",
      m["sample_rms_mm"].get<double>(),
      m.contains("dynamic_offset_correlation")
          ? std::to_string(m["dynamic_offset_correlation"].get<double>()).substr(0, 5).c_str()
          : "n/a",
      m["triangulate_fps"].get<double>(), m["dense_fit_fps"].get<double>(),
      m["take"].get<std::string>().c_str());
  if (metrics) *metrics = m;
  if (cameras) *cameras = rig;
  if (reconstructed) *reconstructed = std::move(result.take);
  return Status::Ok();
}

}  // namespace facedyn::app
