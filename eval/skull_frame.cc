#include "eval/skull_frame.h"

#include <fmt/format.h>

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
