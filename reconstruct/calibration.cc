#include "reconstruct/calibration.h"

#include <ceres/ceres.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/persistence.hpp>
#include <set>

namespace facedyn::reconstruct {
namespace {

// Half-turn of the board about its centre: what findChessboardCorners' reversed order means.
Rigid3 BoardHalfTurn(const BoardSpec& board) {
  const double center_x = 0.5 * (board.inner_cols() + 1) * board.square_mm;
  const double center_y = 0.5 * (board.inner_rows() + 1) * board.square_mm;
  return Rigid3(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ())),
                Eigen::Vector3d(2.0 * center_x, 2.0 * center_y, 0.0));
}

struct Obs {
  int camera = 0;
  int view = 0;
  std::vector<Eigen::Vector2d> pixels;
  std::vector<Eigen::Vector3d> points;  // board points for the ids as detected
  std::vector<bool> inlier;
  bool flipped = false;        // ids read as the board turned by 180 degrees
  PoseBlock cam_from_board{};  // per-camera stage, for the ids as detected
};

Eigen::Vector3d EffectivePoint(const Obs& obs, int i, const Rigid3& half_turn) {
  return obs.flipped ? Eigen::Vector3d(half_turn * obs.points[i]) : obs.points[i];
}

struct Term {
  Obs* obs;
  double* intrinsics;
  double* cam_from_world;
  double* world_from_board;
};

double ResidualNorm(const Obs& obs, int i, const Rigid3& half_turn, const double* intrinsics,
                    const double* cam_from_world, const double* world_from_board) {
  const BoardCornerResidual functor(obs.pixels[i], EffectivePoint(obs, i, half_turn));
  double residual[2];
  functor(intrinsics, cam_from_world, world_from_board, residual);
  const double norm = std::hypot(residual[0], residual[1]);
  return std::isfinite(norm) ? norm : std::numeric_limits<double>::infinity();
}

struct SolveSettings {
  std::set<const double*> constant;
  bool intrinsics_constant = false;
  bool estimate_k3 = true;
  int max_iterations = 200;
};

ceres::Solver::Summary SolveOnce(const std::vector<Term>& terms, const Rigid3& half_turn,
                                 const SolveSettings& settings, double huber_px) {
  ceres::Problem problem;
  std::set<double*> intrinsic_blocks;
  for (const Term& term : terms) {
    for (int i = 0; i < static_cast<int>(term.obs->pixels.size()); ++i) {
      if (!term.obs->inlier[i]) continue;
      auto* cost = new ceres::AutoDiffCostFunction<BoardCornerResidual, 2, kIntrinsicCount, 6, 6>(
          new BoardCornerResidual(term.obs->pixels[i], EffectivePoint(*term.obs, i, half_turn)));
      problem.AddResidualBlock(cost, huber_px > 0 ? new ceres::HuberLoss(huber_px) : nullptr,
                               term.intrinsics, term.cam_from_world, term.world_from_board);
      intrinsic_blocks.insert(term.intrinsics);
    }
  }
  for (const Term& term : terms) {
    for (double* block : {term.cam_from_world, term.world_from_board}) {
      if (settings.constant.count(block) && problem.HasParameterBlock(block)) {
        problem.SetParameterBlockConstant(block);
      }
    }
  }
  for (double* block : intrinsic_blocks) {
    if (settings.intrinsics_constant) {
      problem.SetParameterBlockConstant(block);
    } else if (!settings.estimate_k3) {
      problem.SetManifold(block, new ceres::SubsetManifold(kIntrinsicCount, {8}));
    }
  }
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_SCHUR;
  solver_options.max_num_iterations = settings.max_iterations;
  solver_options.function_tolerance = 1e-12;
  solver_options.gradient_tolerance = 1e-12;
  solver_options.parameter_tolerance = 1e-12;
  solver_options.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  return summary;
}

// Huber solves with outlier rejection, then a plain least-squares solve on the inliers.
void RobustAdjust(const std::vector<Term>& terms, const Rigid3& half_turn,
                  const SolveSettings& settings, const CalibrationOptions& options,
                  CalibrationSummary* summary) {
  auto accumulate = [&](const ceres::Solver::Summary& s, bool last) {
    summary->iterations += static_cast<int>(s.iterations.size());
    if (last) {
      summary->final_cost = s.final_cost;
      summary->converged = s.termination_type == ceres::CONVERGENCE;
    }
  };
  for (int round = 0; round < options.outlier_rounds; ++round) {
    const ceres::Solver::Summary s = SolveOnce(terms, half_turn, settings, options.huber_px);
    if (round == 0) summary->initial_cost = s.initial_cost;
    accumulate(s, false);
    std::vector<double> norms;
    for (const Term& term : terms) {
      for (int i = 0; i < static_cast<int>(term.obs->pixels.size()); ++i) {
        norms.push_back(ResidualNorm(*term.obs, i, half_turn, term.intrinsics, term.cam_from_world,
                                     term.world_from_board));
      }
    }
    if (norms.empty()) return;
    std::vector<double> sorted = norms;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    // The median of |e| for isotropic Gaussian noise of sigma per axis is sigma sqrt(2 ln 2).
    const double sigma = sorted[sorted.size() / 2] / std::sqrt(2.0 * std::log(2.0));
    const double threshold = std::max(options.outlier_min_px, options.outlier_sigmas * sigma);
    size_t k = 0;
    for (const Term& term : terms) {
      for (size_t i = 0; i < term.obs->pixels.size(); ++i) {
        term.obs->inlier[i] = norms[k++] <= threshold;
      }
    }
  }
  accumulate(SolveOnce(terms, half_turn, settings, 0.0), true);
}

StatusOr<Intrinsics> InitialIntrinsics(const std::vector<Obs*>& observations,
                                       const CalibrationInput::CameraInfo& camera) {
  std::vector<std::vector<cv::Point3f>> object_points;
  std::vector<std::vector<cv::Point2f>> image_points;
  for (const Obs* obs : observations) {
    object_points.emplace_back();
    image_points.emplace_back();
    for (size_t i = 0; i < obs->pixels.size(); ++i) {
      object_points.back().emplace_back(obs->points[i].x(), obs->points[i].y(), 0.0f);
      image_points.back().emplace_back(obs->pixels[i].x(), obs->pixels[i].y());
    }
  }
  cv::Mat k;
  try {
    k = cv::initCameraMatrix2D(object_points, image_points,
                               cv::Size(camera.width_px, camera.height_px), 1.0);
  } catch (const cv::Exception& e) {
    return FailedPreconditionError("camera " + camera.name +
                                   ": no initial focal length from the board views (" + e.what() +
                                   ")");
  }
  const double fx = k.at<double>(0, 0), fy = k.at<double>(1, 1);
  if (!(fx > 0) || !(fy > 0) || !std::isfinite(fx) || !std::isfinite(fy)) {
    return FailedPreconditionError("camera " + camera.name +
                                   ": the board views give no focal length (all fronto-parallel "
                                   "or degenerate?); tilt the board between views");
  }
  return Intrinsics{fx, fy, k.at<double>(0, 2), k.at<double>(1, 2), 0, 0, 0, 0, 0};
}

Status PnP(const Intrinsics& intrinsics, Obs* obs, const std::string& camera_name,
           const std::string& view_name) {
  std::vector<cv::Point3f> object_points;
  std::vector<cv::Point2f> image_points;
  for (size_t i = 0; i < obs->pixels.size(); ++i) {
    object_points.emplace_back(obs->points[i].x(), obs->points[i].y(), 0.0f);
    image_points.emplace_back(obs->pixels[i].x(), obs->pixels[i].y());
  }
  const cv::Matx33d k(intrinsics[0], 0, intrinsics[2], 0, intrinsics[1], intrinsics[3], 0, 0, 1);
  cv::Vec3d rvec, tvec;
  bool ok = false;
  try {
    ok = cv::solvePnP(object_points, image_points, k, cv::noArray(), rvec, tvec, false,
                      cv::SOLVEPNP_ITERATIVE);
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok || !(tvec[2] > 0)) {
    return FailedPreconditionError("camera " + camera_name + ", view " + view_name +
                                   ": no board pose (PnP failed)");
  }
  obs->cam_from_board = {rvec[0], rvec[1], rvec[2], tvec[0], tvec[1], tvec[2]};
  return Status::Ok();
}

Rigid3 EffectiveCamFromBoard(const Obs& obs, const Rigid3& half_turn) {
  const Rigid3 cam_from_board = FromPoseBlock(obs.cam_from_board);
  return obs.flipped ? cam_from_board * half_turn : cam_from_board;
}

double ObservationRms(const Obs& obs, const Rigid3& half_turn, const Intrinsics& intrinsics,
                      const Rigid3& cam_from_board, bool flipped) {
  Obs copy = obs;
  copy.flipped = flipped;
  const PoseBlock identity = ToPoseBlock(Rigid3::Identity());
  const PoseBlock pose = ToPoseBlock(cam_from_board);
  double sum = 0.0;
  for (size_t i = 0; i < obs.pixels.size(); ++i) {
    const double e = ResidualNorm(copy, static_cast<int>(i), half_turn, intrinsics.data(),
                                  identity.data(), pose.data());
    sum += std::min(e * e, 1e6);
  }
  return std::sqrt(sum / std::max<size_t>(1, obs.pixels.size()));
}

}  // namespace

PoseBlock ToPoseBlock(const Rigid3& transform) {
  const Eigen::Quaterniond& q = transform.rotation();
  const double quaternion[4] = {q.w(), q.x(), q.y(), q.z()};
  PoseBlock block{};
  ceres::QuaternionToAngleAxis(quaternion, block.data());
  for (int k = 0; k < 3; ++k) block[3 + k] = transform.translation()[k];
  return block;
}

Rigid3 FromPoseBlock(const PoseBlock& block) {
  double quaternion[4];
  ceres::AngleAxisToQuaternion(block.data(), quaternion);
  return Rigid3(Eigen::Quaterniond(quaternion[0], quaternion[1], quaternion[2], quaternion[3]),
                Eigen::Vector3d(block[3], block[4], block[5]));
}

Status CalibrationOptions::Check() const {
  if (!(huber_px > 0)) return InvalidArgumentError("huber_px must be > 0");
  if (!(outlier_min_px > 0)) return InvalidArgumentError("outlier_min_px must be > 0");
  if (!(outlier_sigmas >= 2)) return InvalidArgumentError("outlier_sigmas must be >= 2");
  if (outlier_rounds < 0 || outlier_rounds > 10) {
    return InvalidArgumentError("outlier_rounds must be in [0, 10]");
  }
  if (min_corners_per_view < 4) return InvalidArgumentError("min_corners_per_view must be >= 4");
  if (min_views_per_camera < 1) return InvalidArgumentError("min_views_per_camera must be >= 1");
  if (max_iterations < 1) return InvalidArgumentError("max_iterations must be >= 1");
  return Status::Ok();
}

StatusOr<RigCalibration> Calibrate(const CalibrationInput& input, const CalibrationOptions& options,
                                   CalibrationSummary* summary_out) {
  FACEDYN_RETURN_IF_ERROR(options.Check().WithContext("calibration options"));
  FACEDYN_RETURN_IF_ERROR(input.board.Check().WithContext("board"));
  CalibrationSummary local_summary;
  CalibrationSummary& summary = summary_out ? *summary_out : local_summary;
  summary = CalibrationSummary();
  const int camera_count = static_cast<int>(input.cameras.size());
  const int view_count = static_cast<int>(input.view_names.size());
  if (camera_count == 0) return InvalidArgumentError("calibration needs at least one camera");
  for (const auto& camera : input.cameras) {
    if (camera.width_px <= 0 || camera.height_px <= 0) {
      return InvalidArgumentError("camera " + camera.name + " has no image size");
    }
  }
  const Rigid3 half_turn = BoardHalfTurn(input.board);
  const bool can_flip = input.board.kind == BoardSpec::Kind::kChessboard;

  std::vector<Obs> observations;
  for (const auto& in : input.observations) {
    if (in.camera < 0 || in.camera >= camera_count || in.view < 0 || in.view >= view_count) {
      return InvalidArgumentError("observation with camera " + std::to_string(in.camera) +
                                  " / view " + std::to_string(in.view) + " out of range");
    }
    if (in.corners.size() < options.min_corners_per_view) {
      summary.dropped.push_back("camera " + input.cameras[in.camera].name + ", view " +
                                input.view_names[in.view] + ": only " +
                                std::to_string(in.corners.size()) + " corners");
      continue;
    }
    Obs obs;
    obs.camera = in.camera;
    obs.view = in.view;
    for (int i = 0; i < in.corners.size(); ++i) {
      const int id = in.corners.corner_ids[i];
      if (id < 0 || id >= input.board.corner_count()) {
        return InvalidArgumentError("corner id " + std::to_string(id) + " out of range");
      }
      obs.pixels.push_back(in.corners.pixels[i]);
      obs.points.push_back(input.board.CornerInBoard(id));
    }
    obs.inlier.assign(obs.pixels.size(), true);
    observations.push_back(std::move(obs));
  }

  // (1) Per camera.
  std::vector<Intrinsics> intrinsics(camera_count);
  const PoseBlock identity_block = ToPoseBlock(Rigid3::Identity());
  for (int c = 0; c < camera_count; ++c) {
    std::vector<Obs*> mine;
    for (Obs& obs : observations) {
      if (obs.camera == c) mine.push_back(&obs);
    }
    if (static_cast<int>(mine.size()) < options.min_views_per_camera) {
      return FailedPreconditionError("camera " + input.cameras[c].name +
                                     ": the board was found in " + std::to_string(mine.size()) +
                                     " usable images, need at least " +
                                     std::to_string(options.min_views_per_camera));
    }
    FACEDYN_ASSIGN_OR_RETURN(intrinsics[c], InitialIntrinsics(mine, input.cameras[c]));
    std::vector<Term> terms;
    PoseBlock camera_identity = identity_block;
    for (Obs* obs : mine) {
      FACEDYN_RETURN_IF_ERROR(
          PnP(intrinsics[c], obs, input.cameras[c].name, input.view_names[obs->view]));
      terms.push_back(
          {obs, intrinsics[c].data(), camera_identity.data(), obs->cam_from_board.data()});
    }
    SolveSettings settings;
    settings.constant.insert(camera_identity.data());
    settings.estimate_k3 = options.estimate_k3;
    settings.max_iterations = options.max_iterations;
    RobustAdjust(terms, half_turn, settings, options, &summary);
    if (!std::isfinite(intrinsics[c][0]) || !(intrinsics[c][0] > 0)) {
      return InternalError("camera " + input.cameras[c].name + ": intrinsics diverged");
    }
  }

  // (2) Extrinsics by breadth-first search from camera 0.
  std::vector<std::optional<Rigid3>> cam_from_world(camera_count);
  cam_from_world[0] = Rigid3::Identity();
  std::vector<std::vector<Obs*>> by_view(view_count);
  for (Obs& obs : observations) by_view[obs.view].push_back(&obs);
  auto known_obs_in_view = [&](int view) -> Obs* {
    Obs* best = nullptr;
    for (Obs* obs : by_view[view]) {
      if (cam_from_world[obs->camera] && (!best || obs->pixels.size() > best->pixels.size())) {
        best = obs;
      }
    }
    return best;
  };
  for (int placed = 1; placed < camera_count; ++placed) {
    int best_camera = -1;
    int best_shared = 0;
    for (int c = 0; c < camera_count; ++c) {
      if (cam_from_world[c]) continue;
      int shared = 0;
      for (Obs& obs : observations) {
        if (obs.camera == c && known_obs_in_view(obs.view)) ++shared;
      }
      if (shared > best_shared) {
        best_shared = shared;
        best_camera = c;
      }
    }
    if (best_camera < 0) {
      std::string missing;
      for (int c = 0; c < camera_count; ++c) {
        if (!cam_from_world[c]) missing += (missing.empty() ? "" : ", ") + input.cameras[c].name;
      }
      return FailedPreconditionError("cameras " + missing + " share no board view with camera " +
                                     input.cameras[0].name +
                                     " or the cameras linked to it; the rig is not connected");
    }
    const int c = best_camera;
    std::vector<Obs*> shared;
    for (Obs& obs : observations) {
      if (obs.camera == c && known_obs_in_view(obs.view)) shared.push_back(&obs);
    }
    double best_score = std::numeric_limits<double>::infinity();
    Rigid3 best_pose;
    for (Obs* candidate_obs : shared) {
      const Obs* reference = known_obs_in_view(candidate_obs->view);
      for (int flip = 0; flip <= (can_flip ? 1 : 0); ++flip) {
        Obs probe = *candidate_obs;
        probe.flipped = flip == 1;
        const Rigid3 candidate = EffectiveCamFromBoard(probe, half_turn) *
                                 EffectiveCamFromBoard(*reference, half_turn).Inverse() *
                                 *cam_from_world[reference->camera];
        std::vector<double> scores;
        for (Obs* other : shared) {
          const Obs* other_reference = known_obs_in_view(other->view);
          const Rigid3 world_from_board = cam_from_world[other_reference->camera]->Inverse() *
                                          EffectiveCamFromBoard(*other_reference, half_turn);
          double rms =
              ObservationRms(*other, half_turn, intrinsics[c], candidate * world_from_board, false);
          if (can_flip) {
            rms = std::min(rms, ObservationRms(*other, half_turn, intrinsics[c],
                                               candidate * world_from_board, true));
          }
          scores.push_back(rms);
        }
        std::nth_element(scores.begin(), scores.begin() + scores.size() / 2, scores.end());
        const double score = scores[scores.size() / 2];
        if (score < best_score) {
          best_score = score;
          best_pose = candidate;
        }
      }
    }
    cam_from_world[c] = best_pose;
    if (can_flip) {
      for (Obs* other : shared) {
        const Obs* other_reference = known_obs_in_view(other->view);
        if (other_reference->camera == c) continue;
        const Rigid3 world_from_board = cam_from_world[other_reference->camera]->Inverse() *
                                        EffectiveCamFromBoard(*other_reference, half_turn);
        other->flipped =
            ObservationRms(*other, half_turn, intrinsics[c], best_pose * world_from_board, true) <
            ObservationRms(*other, half_turn, intrinsics[c], best_pose * world_from_board, false);
      }
    }
    spdlog::debug("calibration: placed camera {} (median shared-view RMS {:.2f} px)",
                  input.cameras[c].name, best_score);
  }

  // (3) Joint bundle adjustment.
  std::vector<PoseBlock> camera_blocks(camera_count);
  for (int c = 0; c < camera_count; ++c) camera_blocks[c] = ToPoseBlock(*cam_from_world[c]);
  std::vector<PoseBlock> board_blocks(view_count);
  std::vector<bool> view_used(view_count, false);
  for (int v = 0; v < view_count; ++v) {
    const Obs* reference = known_obs_in_view(v);
    if (!reference) continue;
    view_used[v] = true;
    board_blocks[v] = ToPoseBlock(cam_from_world[reference->camera]->Inverse() *
                                  EffectiveCamFromBoard(*reference, half_turn));
  }
  if (camera_count > 1) {
    std::vector<Term> terms;
    for (Obs& obs : observations) {
      std::fill(obs.inlier.begin(), obs.inlier.end(), true);
      terms.push_back({&obs, intrinsics[obs.camera].data(), camera_blocks[obs.camera].data(),
                       board_blocks[obs.view].data()});
    }
    SolveSettings settings;
    settings.constant.insert(camera_blocks[0].data());
    settings.intrinsics_constant = !options.refine_intrinsics_in_rig;
    settings.estimate_k3 = options.estimate_k3;
    settings.max_iterations = options.max_iterations;
    RobustAdjust(terms, half_turn, settings, options, &summary);
  }

  // Errors.
  RigCalibration result;
  result.board = input.board.ToString();
  result.view_names = input.view_names;
  result.camera_rms_px.assign(camera_count, 0.0);
  result.camera_corners.assign(camera_count, 0);
  result.world_from_board.resize(view_count);
  for (int c = 0; c < camera_count; ++c) {
    Camera camera;
    camera.name = input.cameras[c].name;
    camera.width_px = input.cameras[c].width_px;
    camera.height_px = input.cameras[c].height_px;
    camera.intrinsics = intrinsics[c];
    camera.cam_from_world = camera_count > 1 ? FromPoseBlock(camera_blocks[c]) : Rigid3::Identity();
    result.cameras.push_back(camera);
  }
  double total_sq = 0.0;
  int total = 0;
  for (const Obs& obs : observations) {
    const double* world_from_board =
        camera_count > 1 ? board_blocks[obs.view].data() : obs.cam_from_board.data();
    ViewError error;
    error.camera = obs.camera;
    error.view = obs.view;
    double sq = 0.0;
    for (size_t i = 0; i < obs.pixels.size(); ++i) {
      if (!obs.inlier[i]) {
        ++error.outliers;
        continue;
      }
      const double e =
          ResidualNorm(obs, static_cast<int>(i), half_turn, intrinsics[obs.camera].data(),
                       camera_count > 1 ? camera_blocks[obs.camera].data() : identity_block.data(),
                       world_from_board);
      sq += e * e;
      ++error.corners;
    }
    error.rms_px = error.corners ? std::sqrt(sq / error.corners) : 0.0;
    result.camera_rms_px[obs.camera] += sq;
    result.camera_corners[obs.camera] += error.corners;
    total_sq += sq;
    total += error.corners;
    summary.outliers += error.outliers;
    result.view_errors.push_back(error);
    if (camera_count > 1) {
      result.world_from_board[obs.view] = FromPoseBlock(board_blocks[obs.view]);
    } else {
      result.world_from_board[obs.view] = FromPoseBlock(obs.cam_from_board);
    }
  }
  for (int c = 0; c < camera_count; ++c) {
    result.camera_rms_px[c] = result.camera_corners[c]
                                  ? std::sqrt(result.camera_rms_px[c] / result.camera_corners[c])
                                  : 0.0;
  }
  result.rms_px = total ? std::sqrt(total_sq / total) : 0.0;
  summary.corners = total;
  summary.rms_px = result.rms_px;
  for (const Camera& camera : result.cameras) {
    const Status check = camera.Check();
    if (!check.ok()) {
      return InternalError("calibration of camera " + camera.name +
                           " produced invalid values: " + check.message());
    }
  }
  return result;
}

Status SaveCalibration(const RigCalibration& calibration, const std::string& path) {
  for (const Camera& camera : calibration.cameras) {
    FACEDYN_RETURN_IF_ERROR(camera.Check().WithContext("calibration for " + path));
  }
  const std::string temporary = path + ".tmp.yaml";
  try {
    cv::FileStorage fs(temporary, cv::FileStorage::WRITE);
    if (!fs.isOpened()) return NotFoundError("cannot write calibration file " + path);
    // The camera part is capture/camera_model.h's layout, so ReadCameraModels reads this file.
    fs << "camera_count" << static_cast<int>(calibration.cameras.size());
    fs << "cameras"
       << "[";
    for (size_t c = 0; c < calibration.cameras.size(); ++c) {
      const Camera& camera = calibration.cameras[c];
      const cv::Mat k = (cv::Mat_<double>(3, 3) << camera.fx(), 0, camera.cx(), 0, camera.fy(),
                         camera.cy(), 0, 0, 1);
      cv::Mat distortion(1, 5, CV_64F);
      for (int i = 0; i < 5; ++i) distortion.at<double>(0, i) = camera.intrinsics[4 + i];
      cv::Mat pose(4, 4, CV_64F);
      const Eigen::Matrix4d m = camera.cam_from_world.ToMatrix4();
      for (int r = 0; r < 4; ++r) {
        for (int col = 0; col < 4; ++col) pose.at<double>(r, col) = m(r, col);
      }
      fs << "{";
      fs << "name" << camera.name << "image_width" << camera.width_px << "image_height"
         << camera.height_px << "camera_matrix" << k << "distortion_coefficients" << distortion
         << "cam_from_world" << pose;
      fs << "rms_px" << (c < calibration.camera_rms_px.size() ? calibration.camera_rms_px[c] : 0.0);
      fs << "corners"
         << (c < calibration.camera_corners.size() ? calibration.camera_corners[c] : 0);
      fs << "}";
    }
    fs << "]";
    fs << "facedyn_calibration_version" << 1;
    fs << "board" << calibration.board;
    fs << "rms_px" << calibration.rms_px;
    fs << "views"
       << "[";
    for (const ViewError& error : calibration.view_errors) {
      fs << "{"
         << "view" << calibration.view_names.at(error.view) << "camera"
         << calibration.cameras.at(error.camera).name << "corners" << error.corners << "outliers"
         << error.outliers << "rms_px" << error.rms_px << "}";
    }
    fs << "]";
    fs.release();
  } catch (const cv::Exception& e) {
    std::remove(temporary.c_str());
    return InternalError("writing calibration file " + path + ": " + e.what());
  }
  if (std::rename(temporary.c_str(), path.c_str()) != 0) {
    std::remove(temporary.c_str());
    return InternalError("cannot move " + temporary + " to " + path);
  }
  return Status::Ok();
}

StatusOr<RigCalibration> LoadCalibration(const std::string& path) {
  RigCalibration calibration;
  FACEDYN_ASSIGN_OR_RETURN(calibration.cameras, capture::ReadCameraModels(path));
  try {
    cv::FileStorage fs(path, cv::FileStorage::READ);
    if (!fs.isOpened()) return NotFoundError("cannot open calibration file " + path);
    if (!fs["board"].empty()) fs["board"] >> calibration.board;
    if (!fs["rms_px"].empty()) fs["rms_px"] >> calibration.rms_px;
    for (const cv::FileNode& node : fs["cameras"]) {
      calibration.camera_rms_px.push_back(
          node["rms_px"].empty() ? 0.0 : static_cast<double>(node["rms_px"]));
      calibration.camera_corners.push_back(
          node["corners"].empty() ? 0 : static_cast<int>(node["corners"]));
    }
  } catch (const cv::Exception& e) {
    return DataLossError("calibration file " + path + " is corrupt: " + e.what());
  }
  return calibration;
}

}  // namespace facedyn::reconstruct
