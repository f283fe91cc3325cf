#include "eval/simulated_stage.h"

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <utility>

#include "reconstruct/calibration.h"
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

StatusOr<Reconstruction> ReconstructSimulatedTake(const FaceRig& face,
                                                  const SimulatedCameraRig& cameras,
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

}  // namespace facedyn::eval
