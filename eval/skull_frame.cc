#include "eval/skull_frame.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "core/check.h"

namespace facedyn::eval {

Rigid3 FixedSkullOffset(const std::vector<Rigid3>& world_from_estimated_skull,
                        const std::vector<Rigid3>& world_from_true_skull,
                        dynamics::FrameRange frames) {
  if (frames.empty()) return Rigid3();
  Eigen::Vector4d quaternion_sum = Eigen::Vector4d::Zero();
  Eigen::Vector3d translation_sum = Eigen::Vector3d::Zero();
  const Eigen::Quaterniond first =
      (world_from_estimated_skull[frames.begin].Inverse() * world_from_true_skull[frames.begin])
          .rotation();
  for (int t = frames.begin; t < frames.end; ++t) {
    const Rigid3 offset = world_from_estimated_skull[t].Inverse() * world_from_true_skull[t];
    Eigen::Quaterniond q = offset.rotation();
    if (q.coeffs().dot(first.coeffs()) < 0) q.coeffs() *= -1;  // one hemisphere
    quaternion_sum += q.coeffs();
    translation_sum += offset.translation();
  }
  Eigen::Quaterniond mean;
  mean.coeffs() = quaternion_sum.normalized();
  return Rigid3(mean, translation_sum / frames.size());
}

double SkullFrameMeanDistance(const PointCache& predicted_world,
                              const std::vector<Rigid3>& world_from_estimated_skull,
                              const PointCache& truth_world,
                              const std::vector<Rigid3>& world_from_true_skull,
                              const std::vector<int>& vertices, dynamics::FrameRange frames) {
  FACEDYN_CHECK(predicted_world.vertex_count == truth_world.vertex_count &&
                    predicted_world.frame_count() == truth_world.frame_count(),
                fmt::format("SkullFrameMeanDistance: {} vs {} vertices, {} vs {} frames",
                            predicted_world.vertex_count, truth_world.vertex_count,
                            predicted_world.frame_count(), truth_world.frame_count()));
  FACEDYN_CHECK(static_cast<int>(world_from_estimated_skull.size()) == truth_world.frame_count() &&
                    static_cast<int>(world_from_true_skull.size()) == truth_world.frame_count() &&
                    frames.begin >= 0 && frames.end <= truth_world.frame_count(),
                "SkullFrameMeanDistance: poses or frames do not match the caches");
  const Rigid3 offset = FixedSkullOffset(world_from_estimated_skull, world_from_true_skull, frames);
  double sum = 0.0;
  long count = 0;
  for (int t = frames.begin; t < frames.end; ++t) {
    const Rigid3 estimated_from_world = world_from_estimated_skull[t].Inverse();
    const Rigid3 estimated_from_truth_world = offset * world_from_true_skull[t].Inverse();
    const auto predicted = predicted_world.Frame(t);
    const auto truth = truth_world.Frame(t);
    for (int v : vertices) {
      FACEDYN_CHECK(v >= 0 && v < truth_world.vertex_count, "SkullFrameMeanDistance: vertex");
      const Eigen::Vector3d a = estimated_from_world * predicted.col(v).cast<double>();
      const Eigen::Vector3d b = estimated_from_truth_world * truth.col(v).cast<double>();
      sum += (a - b).norm();
    }
    count += static_cast<long>(vertices.size());
  }
  return count > 0 ? sum / count : 0.0;
}

SkullPoseError ScoreSkullPoses(const std::vector<Rigid3>& world_from_estimated_skull,
                               const std::vector<Rigid3>& world_from_true_skull,
                               dynamics::FrameRange frames) {
  FACEDYN_CHECK(frames.begin >= 0 &&
                    frames.end <= static_cast<int>(world_from_estimated_skull.size()) &&
                    frames.end <= static_cast<int>(world_from_true_skull.size()),
                fmt::format("ScoreSkullPoses: frames [{}, {}) outside {} estimated / {} true poses",
                            frames.begin, frames.end, world_from_estimated_skull.size(),
                            world_from_true_skull.size()));
  SkullPoseError error;
  error.frames = frames.size();
  if (frames.empty()) return error;
  constexpr double kDegrees = 180.0 / M_PI;
  std::vector<Eigen::Vector3d> origin, rotation;  // per frame: mm, rotation vector (rad)
  for (int t = frames.begin; t < frames.end; ++t) {
    const Rigid3 d = world_from_true_skull[t].Inverse() * world_from_estimated_skull[t];
    const Eigen::AngleAxisd axis_angle(d.RotationMatrix());
    origin.push_back(d.translation());
    rotation.push_back(axis_angle.axis() * axis_angle.angle());
  }
  const double n = static_cast<double>(origin.size());
  Eigen::Vector3d mean_t = Eigen::Vector3d::Zero(), mean_r = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < origin.size(); ++i) {
    mean_t += origin[i] / n;
    mean_r += rotation[i] / n;
  }
  double sq_t = 0, sq_r = 0, var_t = 0, var_r = 0;
  for (size_t i = 0; i < origin.size(); ++i) {
    sq_t += origin[i].squaredNorm();
    sq_r += rotation[i].squaredNorm();
    var_t += (origin[i] - mean_t).squaredNorm();
    var_r += (rotation[i] - mean_r).squaredNorm();
    error.origin_max_mm = std::max(error.origin_max_mm, origin[i].norm());
    error.rotation_max_deg = std::max(error.rotation_max_deg, rotation[i].norm() * kDegrees);
  }
  error.origin_rms_mm = std::sqrt(sq_t / n);
  error.origin_constant_mm = mean_t.norm();
  error.origin_varying_rms_mm = std::sqrt(var_t / n);
  error.rotation_rms_deg = std::sqrt(sq_r / n) * kDegrees;
  error.rotation_constant_deg = mean_r.norm() * kDegrees;
  error.rotation_varying_rms_deg = std::sqrt(var_r / n) * kDegrees;
  error.origin_mean_mm = mean_t;
  return error;
}

Json SkullPoseErrorJson(const SkullPoseError& error) {
  return {{"frames", error.frames},
          {"origin_rms_mm", error.origin_rms_mm},
          {"origin_constant_mm", error.origin_constant_mm},
          {"origin_varying_rms_mm", error.origin_varying_rms_mm},
          {"origin_max_mm", error.origin_max_mm},
          {"origin_mean_in_true_skull_mm",
           {error.origin_mean_mm.x(), error.origin_mean_mm.y(), error.origin_mean_mm.z()}},
          {"rotation_rms_deg", error.rotation_rms_deg},
          {"rotation_constant_deg", error.rotation_constant_deg},
          {"rotation_varying_rms_deg", error.rotation_varying_rms_deg},
          {"rotation_max_deg", error.rotation_max_deg}};
}

PointCache RemoveExactOffsets(const Take& reconstructed, const PointCache& exact_offsets_in_skull) {
  FACEDYN_CHECK(exact_offsets_in_skull.vertex_count == reconstructed.positions.vertex_count &&
                    exact_offsets_in_skull.frame_count() == reconstructed.frame_count(),
                "RemoveExactOffsets: offsets do not match the take");
  PointCache result = reconstructed.positions;
  for (int t = 0; t < result.frame_count(); ++t) {
    const Eigen::Matrix3f rotation =
        reconstructed.world_from_skull[t].RotationMatrix().cast<float>();
    result.Frame(t) -= rotation * exact_offsets_in_skull.Frame(t);
  }
  return result;
}

}  // namespace facedyn::eval
