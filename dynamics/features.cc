#include "dynamics/features.h"

#include <cmath>
#include <limits>
#include <string>

#include <Eigen/LU>

namespace facedyn::dynamics {

int WindowFrames(double window_s, double fps) {
  return static_cast<int>(std::lround(window_s * fps));
}

Status FeatureConfig::Check() const {
  if (!std::isfinite(fps) || fps <= 0.0) {
    return InvalidArgumentError("FeatureConfig.fps must be > 0, got " + std::to_string(fps));
  }
  if (!std::isfinite(window_s) || window_s < 0.0 || window_s > 1.0) {
    return InvalidArgumentError("FeatureConfig.window_s must be in [0, 1] s, got " +
                                std::to_string(window_s));
  }
  if (!std::isfinite(stretch_step_mm) || stretch_step_mm <= 0.0 || stretch_step_mm > 50.0) {
    return InvalidArgumentError("FeatureConfig.stretch_step_mm must be in (0, 50] mm, got " +
                                std::to_string(stretch_step_mm));
  }
  return Status::Ok();
}

Status CheckTakeMatchesConfig(const Take& take, const FeatureConfig& config) {
  if (std::abs(take.info.fps - config.fps) > 1e-6 * config.fps) {
    return FailedPreconditionError("take has " + std::to_string(take.info.fps) +
                                   " fps but the feature configuration expects " +
                                   std::to_string(config.fps) + " fps");
  }
  return Status::Ok();
}

Eigen::MatrixXd SkullLandmarkVelocities(const std::vector<Rigid3>& world_from_skull,
                                        const std::vector<Eigen::Vector3d>& landmarks_in_skull,
                                        double fps) {
  FACEDYN_CHECK(fps > 0.0, "fps must be positive");
  FACEDYN_CHECK(!world_from_skull.empty(), "no poses");
  const int frame_count = static_cast<int>(world_from_skull.size());
  const int landmark_count = static_cast<int>(landmarks_in_skull.size());
  Eigen::MatrixXd velocities = Eigen::MatrixXd::Zero(3 * landmark_count, frame_count);
  for (int t = 1; t < frame_count; ++t) {
    // skull(t)_from_skull(t-1) = T(t)^-1 T(t-1); Eq. (2): (b - T(t)^-1 T(t-1) b) / dt.
    const Rigid3 now_from_before = world_from_skull[t].Inverse() * world_from_skull[t - 1];
    for (int i = 0; i < landmark_count; ++i) {
      const Eigen::Vector3d& b = landmarks_in_skull[i];
      velocities.block<3, 1>(3 * i, t) = (b - now_from_before * b) * fps;
    }
  }
  return velocities;
}

StatusOr<Eigen::MatrixXd> SkullDescriptors(const std::vector<Rigid3>& world_from_skull,
                                           const std::vector<SkullLandmark>& landmarks,
                                           const FeatureConfig& config) {
  FACEDYN_RETURN_IF_ERROR(config.Check());
  if (world_from_skull.empty()) return FailedPreconditionError("skull descriptors: take has no frames");
  if (landmarks.empty()) return FailedPreconditionError("skull descriptors: no skull landmarks");
  std::vector<Eigen::Vector3d> points(landmarks.size());
  for (size_t i = 0; i < landmarks.size(); ++i) points[i] = landmarks[i].position_in_skull;
  const Eigen::MatrixXd velocities = SkullLandmarkVelocities(world_from_skull, points, config.fps);
  const int frame_count = static_cast<int>(world_from_skull.size());
  const int landmark_count = static_cast<int>(points.size());
  const int w = config.window_frames();
  const int length = config.window_length();
  Eigen::MatrixXd descriptors(config.SkullDescriptorSize(landmark_count), frame_count);
  for (int t = 0; t < frame_count; ++t) {
    for (int j = -w; j <= w; ++j) {
      const int k = t + j;
      const bool inside = k >= 1 && k < frame_count;  // zero velocity outside (end policy)
      for (int i = 0; i < landmark_count; ++i) {
        auto out = descriptors.block<3, 1>((i * length + j + w) * 3, t);
        if (inside) {
          out = velocities.block<3, 1>(3 * i, k);
        } else {
          out.setZero();
        }
      }
    }
  }
  return descriptors;
}

namespace {

Status CheckPointsInRange(const std::vector<SurfacePoint>& points, int vertex_count,
                          const std::string& what) {
  for (size_t i = 0; i < points.size(); ++i) {
    for (int v : points[i].vertices) {
      if (v < 0 || v >= vertex_count) {
        return FailedPreconditionError(what + " " + std::to_string(i) + " uses vertex " +
                                       std::to_string(v) + " but the mesh has " +
                                       std::to_string(vertex_count) + " vertices");
      }
    }
  }
  return Status::Ok();
}

}  // namespace

StatusOr<Eigen::MatrixXd> StabilisedPointPositions(const Take& take,
                                                   const std::vector<SurfacePoint>& points) {
  const int frame_count = take.frame_count();
  if (frame_count == 0) return FailedPreconditionError("take has no frames");
  if (static_cast<int>(take.world_from_skull.size()) != frame_count) {
    return FailedPreconditionError("take has " + std::to_string(frame_count) + " frames but " +
                                   std::to_string(take.world_from_skull.size()) + " skull poses");
  }
  FACEDYN_RETURN_IF_ERROR(CheckPointsInRange(points, take.positions.vertex_count, "sample"));
  const int point_count = static_cast<int>(points.size());
  Eigen::MatrixXd stabilised(3 * point_count, frame_count);
  for (int t = 0; t < frame_count; ++t) {
    const Eigen::Map<const Eigen::Matrix3Xf> frame = take.positions.Frame(t);
    const Eigen::Matrix3d skull_from_world_rotation =
        take.world_from_skull[t].RotationMatrix().transpose();
    const Eigen::Vector3d translation = take.world_from_skull[t].translation();
    for (int i = 0; i < point_count; ++i) {
      const Eigen::Vector3d x_in_world = points[i].Evaluate(frame);
      stabilised.block<3, 1>(3 * i, t) = skull_from_world_rotation * (x_in_world - translation);
    }
  }
  return stabilised;
}

Eigen::MatrixXd StabilisedVelocities(const Eigen::MatrixXd& positions_in_skull, double fps) {
  FACEDYN_CHECK(fps > 0.0, "fps must be positive");
  Eigen::MatrixXd velocities(positions_in_skull.rows(), positions_in_skull.cols());
  if (velocities.cols() == 0) return velocities;
  velocities.col(0).setZero();
  for (Eigen::Index t = 1; t < velocities.cols(); ++t) {
    velocities.col(t) = (positions_in_skull.col(t) - positions_in_skull.col(t - 1)) * fps;
  }
  return velocities;
}

StatusOr<Eigen::MatrixXd> SkinDescriptors(const Take& take, const std::vector<SurfacePoint>& samples,
                                          const FeatureConfig& config) {
  FACEDYN_RETURN_IF_ERROR(config.Check());
  FACEDYN_RETURN_IF_ERROR(CheckTakeMatchesConfig(take, config));
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd stabilised, StabilisedPointPositions(take, samples));
  const Eigen::MatrixXd velocities = StabilisedVelocities(stabilised, config.fps);
  const int frame_count = take.frame_count();
  const int sample_count = static_cast<int>(samples.size());
  const int w = config.window_frames();
  Eigen::MatrixXd descriptors(config.SkinDescriptorSize(),
                              static_cast<Eigen::Index>(frame_count) * sample_count);
  for (int t = 0; t < frame_count; ++t) {
    for (int j = -w; j <= w; ++j) {
      const int k = t + j;
      const bool inside = k >= 1 && k < frame_count;
      for (int i = 0; i < sample_count; ++i) {
        auto out = descriptors.block<3, 1>((j + w) * 3, static_cast<Eigen::Index>(t) * sample_count + i);
        if (inside) {
          out = velocities.block<3, 1>(3 * i, k);
        } else {
          out.setZero();
        }
      }
    }
  }
  return descriptors;
}

namespace {

// Finds the triangle of `triangles` whose uv triangle contains `uv`; returns the surface
// point, or false. Linear search: the stencil is built once per rig.
bool LocateInUv(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix2Xd& vertex_uvs,
                const Eigen::Vector2d& uv, SurfacePoint* point, int* triangle_out) {
  constexpr double kTolerance = 1e-9;
  for (Eigen::Index f = 0; f < triangles.cols(); ++f) {
    const Eigen::Vector2d a = vertex_uvs.col(triangles(0, f));
    const Eigen::Vector2d b = vertex_uvs.col(triangles(1, f));
    const Eigen::Vector2d c = vertex_uvs.col(triangles(2, f));
    const Eigen::Vector2d e1 = b - a;
    const Eigen::Vector2d e2 = c - a;
    const double det = e1.x() * e2.y() - e1.y() * e2.x();
    if (!std::isfinite(det) || std::abs(det) < 1e-18) continue;
    const Eigen::Vector2d d = uv - a;
    const double w1 = (d.x() * e2.y() - d.y() * e2.x()) / det;
    const double w2 = (e1.x() * d.y() - e1.y() * d.x()) / det;
    const double w0 = 1.0 - w1 - w2;
    if (w0 >= -kTolerance && w1 >= -kTolerance && w2 >= -kTolerance) {
      point->vertices = {triangles(0, f), triangles(1, f), triangles(2, f)};
      point->weights = Eigen::Vector3d(w0, w1, w2);
      if (triangle_out != nullptr) *triangle_out = static_cast<int>(f);
      return true;
    }
  }
  return false;
}

}  // namespace

StatusOr<StretchStencil> BuildStretchStencil(const FaceRig& rig,
                                             const std::vector<SurfacePoint>& samples,
                                             double step_mm) {
  if (!std::isfinite(step_mm) || step_mm <= 0.0) {
    return InvalidArgumentError("stretch step must be > 0 mm, got " + std::to_string(step_mm));
  }
  if (!rig.neutral.has_uvs()) {
    return FailedPreconditionError("face rig '" + rig.name + "' neutral mesh has no UVs; stretch "
                                   "features (Eq. 8) need them");
  }
  const int vertex_count = rig.vertex_count();
  FACEDYN_RETURN_IF_ERROR(CheckPointsInRange(samples, vertex_count, "skin sample"));
  const Eigen::Matrix2Xd vertex_uvs = rig.neutral.VertexUvs();
  const Eigen::Matrix3Xi triangles = rig.neutral.Triangles();
  const Eigen::Matrix3Xd& neutral = rig.neutral.positions_mm;

  StretchStencil stencil;
  stencil.vertex_count = vertex_count;
  const size_t sample_count = samples.size();
  stencil.u_minus.resize(sample_count);
  stencil.u_plus.resize(sample_count);
  stencil.v_minus.resize(sample_count);
  stencil.v_plus.resize(sample_count);
  stencil.rest_length_mm.resize(2, static_cast<Eigen::Index>(sample_count));
  for (size_t i = 0; i < sample_count; ++i) {
    const SurfacePoint& sample = samples[i];
    Eigen::Vector2d uv = Eigen::Vector2d::Zero();
    for (int k = 0; k < 3; ++k) uv += sample.weights[k] * vertex_uvs.col(sample.vertices[k]);
    if (!uv.allFinite()) {
      return FailedPreconditionError("skin sample " + std::to_string(i) + " touches a vertex without a uv");
    }
    SurfacePoint located;
    int triangle = -1;
    if (!LocateInUv(triangles, vertex_uvs, uv, &located, &triangle)) {
      return FailedPreconditionError("skin sample " + std::to_string(i) + " is outside the uv chart");
    }
    // Local Jacobian d(position)/d(uv) of the containing triangle.
    Eigen::Matrix2d edges_uv;
    Eigen::Matrix<double, 3, 2> edges_mm;
    for (int e = 0; e < 2; ++e) {
      edges_uv.col(e) = vertex_uvs.col(triangles(e + 1, triangle)) - vertex_uvs.col(triangles(0, triangle));
      edges_mm.col(e) = neutral.col(triangles(e + 1, triangle)) - neutral.col(triangles(0, triangle));
    }
    const Eigen::Matrix<double, 3, 2> jacobian = edges_mm * edges_uv.inverse();
    for (int axis = 0; axis < 2; ++axis) {
      const double speed_mm = jacobian.col(axis).norm();
      if (!std::isfinite(speed_mm) || speed_mm < 1e-12) {
        return FailedPreconditionError("skin sample " + std::to_string(i) +
                                       " sits on a degenerate uv triangle");
      }
      SurfacePoint* sides[2] = {axis == 0 ? &stencil.u_minus[i] : &stencil.v_minus[i],
                                axis == 0 ? &stencil.u_plus[i] : &stencil.v_plus[i]};
      for (int side = 0; side < 2; ++side) {
        double step_uv = step_mm / speed_mm;
        bool found = false;
        for (int attempt = 0; attempt < 5 && !found; ++attempt, step_uv *= 0.5) {
          Eigen::Vector2d query = uv;
          query[axis] += (side == 0 ? -step_uv : step_uv);
          found = LocateInUv(triangles, vertex_uvs, query, sides[side], nullptr);
        }
        if (!found) *sides[side] = sample;  // one-sided difference at the chart's edge
      }
      const double rest = (sides[1]->Evaluate(neutral) - sides[0]->Evaluate(neutral)).norm();
      if (!(rest > 1e-9)) {
        return FailedPreconditionError("skin sample " + std::to_string(i) +
                                       " has no uv neighbourhood for the stretch stencil");
      }
      stencil.rest_length_mm(axis, static_cast<Eigen::Index>(i)) = rest;
    }
  }
  return stencil;
}

void EvaluateStretch(const StretchStencil& stencil,
                     const Eigen::Ref<const Eigen::Matrix3Xf>& positions_mm, double* stretch_out) {
  FACEDYN_CHECK(positions_mm.cols() == stencil.vertex_count, "stretch: vertex count differs");
  const int sample_count = stencil.sample_count();
  for (int i = 0; i < sample_count; ++i) {
    const double du = (stencil.u_plus[i].Evaluate(positions_mm) -
                       stencil.u_minus[i].Evaluate(positions_mm)).norm();
    const double dv = (stencil.v_plus[i].Evaluate(positions_mm) -
                       stencil.v_minus[i].Evaluate(positions_mm)).norm();
    stretch_out[2 * i] = (du - stencil.rest_length_mm(0, i)) / stencil.rest_length_mm(0, i);
    stretch_out[2 * i + 1] = (dv - stencil.rest_length_mm(1, i)) / stencil.rest_length_mm(1, i);
  }
}

StatusOr<Eigen::MatrixXd> StretchFeatures(const Take& take, const StretchStencil& stencil) {
  if (take.positions.vertex_count != stencil.vertex_count) {
    return FailedPreconditionError("stretch stencil was built for " +
                                   std::to_string(stencil.vertex_count) + " vertices, take has " +
                                   std::to_string(take.positions.vertex_count));
  }
  Eigen::MatrixXd stretch(2 * stencil.sample_count(), take.frame_count());
  for (int t = 0; t < take.frame_count(); ++t) {
    EvaluateStretch(stencil, take.positions.Frame(t), stretch.col(t).data());
  }
  return stretch;
}

}  // namespace facedyn::dynamics
