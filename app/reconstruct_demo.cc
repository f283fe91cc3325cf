#include "app/reconstruct_demo.h"

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <random>
#include <utility>

#include "core/file_util.h"
#include "eval/skull_frame.h"
#include "reconstruct/calibration.h"
#include "reconstruct/pipeline.h"
#include "reconstruct/synthetic_views.h"

namespace facedyn::app {

using namespace facedyn::reconstruct;

Status RunReconstructDemoStage(const FaceRig& face, const Take& simulated,
                               const std::string& out_dir, bool quick, Json* metrics,
                               eval::SimulatedCameraRig* cameras, Take* reconstructed) {
  if (simulated.frame_count() == 0) return InvalidArgumentError("the simulated take is empty");
  const std::string stage_dir = JoinPath(out_dir, "reconstruct");
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(stage_dir));
  FACEDYN_ASSIGN_OR_RETURN(const eval::SimulatedCameraRig rig, eval::CalibrateSimulatedCameraRig(quick ? 30 : 60, 2020));
  const RigCalibration& calibration = rig.calibration;
  const double worst_centre_mm = rig.worst_centre_error_mm;
  FACEDYN_RETURN_IF_ERROR(SaveCalibration(calibration, JoinPath(stage_dir, "calibration.yaml")));
  // Filmed for real: rendered by the 8 cameras and the dots detected (the held-out take every
  // later stage scores removal on), as every take the demo reconstructs.
  eval::FilmOptions film;
  film.progress = true;
  std::printf("Filming the %d-frame take with 8 simulated cameras (rendered, dots detected)\n",
              simulated.frame_count());
  std::fflush(stdout);
  FACEDYN_ASSIGN_OR_RETURN(Reconstruction result,
                           eval::FilmSimulatedTake(face, rig, simulated, 2021, film));
  FACEDYN_RETURN_IF_ERROR(SaveTake(result.take, JoinPath(out_dir, "takes/reconstructed")));

  // Errors against the simulator's truth, after the motion's fade-in.
  const int skip = std::min(simulated.frame_count() - 1,
                            static_cast<int>(std::lround(0.5 * simulated.info.fps)));
  const auto quasistatic = simulated.channels.find("quasistatic");
  double sq_t = 0, sq_r = 0, max_t = 0, max_r = 0, sq_s = 0;
  long n_pose = 0, n_sample = 0;
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
  const dynamics::FrameRange scored{skip, frame_count};
  if (!scored.empty()) {
    const eval::SkullPoseError summary =
        eval::ScoreSkullPoses(result.take.world_from_skull, simulated.world_from_skull, scored);
    m["skull_origin_constant_mm"] = summary.origin_constant_mm;
    m["skull_origin_varying_rms_mm"] = summary.origin_varying_rms_mm;
    m["skull_rotation_varying_rms_deg"] = summary.rotation_varying_rms_deg;
  }
  // The skull pose again from the same labelled markers with each deflection shape of
  // reconstruct/skull_pose.h (the default is the tissue model's), scored the same way.
  Json by_shape = Json::object();
  for (const auto& [name, shape] :
       {std::pair{"thickness_squared", DeflectionShape::kThicknessSquared},
        std::pair{"tissue_model", DeflectionShape::kTissueModel}}) {
    SkullPoseOptions options = ReconstructionOptions().skull;
    options.deflection_shape = shape;
    const SkullPoseEstimator estimator(face, options);
    std::vector<Rigid3> poses;
    for (const SkullPoseResult& r : estimator.EstimateTake(result.tracked))
      poses.push_back(r.world_from_skull);
    const dynamics::FrameRange posed{
        skip, std::min(frame_count, static_cast<int>(result.tracked.size()))};
    by_shape[name] =
        eval::SkullPoseErrorJson(eval::ScoreSkullPoses(poses, simulated.world_from_skull, posed));
    by_shape[name]["shape_used"] = estimator.deflection_shape_used();
  }
  m["skull_pose_by_deflection_shape"] = by_shape;
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
      "\nReconstruction of the simulated take filmed by 8 simulated cameras (rendered, dots "
      "detected):\n"
      "  calibration RMS %.3f px, worst camera centre %.3f mm\n"
      "  skull pose error: origin %.3f mm RMS (max %.3f), rotation %.4f deg RMS (max %.4f);\n"
      "    less its mean over the take (%.3f mm): origin %.3f mm RMS, rotation %.4f deg RMS\n"
      "    with the t^2 law's deflection instead: origin %.3f mm RMS (constant %.3f, varying "
      "%.3f)\n"
      "  jaw hinge angle error %s deg RMS\n"
      "  344 skin samples: %.3f mm RMS; dynamic offsets recovered with correlation %s\n"
      "  triangulation %.0f frames/s, dense fit %.1f frames/s -> %s\n",
      calibration.rms_px, worst_centre_mm, m["skull_origin_rms_mm"].get<double>(), max_t,
      m["skull_rotation_rms_deg"].get<double>(), max_r, m.value("skull_origin_constant_mm", 0.0),
      m.value("skull_origin_varying_rms_mm", 0.0), m.value("skull_rotation_varying_rms_deg", 0.0),
      by_shape["thickness_squared"].value("origin_rms_mm", 0.0),
      by_shape["thickness_squared"].value("origin_constant_mm", 0.0),
      by_shape["thickness_squared"].value("origin_varying_rms_mm", 0.0),
      n_jaw > 0 ? std::to_string(m["jaw_angle_rms_deg"].get<double>()).substr(0, 5).c_str() : "n/a",
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
