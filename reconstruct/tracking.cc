#include "reconstruct/tracking.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "reconstruct/assignment.h"
#include "reconstruct/rigid_fit.h"

namespace facedyn::reconstruct {
namespace {

Eigen::Matrix3Xd RestMarkers(const FaceRig& rig) {
  Eigen::Matrix3Xd rest(3, rig.markers.size());
  for (size_t m = 0; m < rig.markers.size(); ++m) {
    rest.col(m) = rig.markers[m].point.Evaluate(rig.neutral.positions_mm);
  }
  return rest;
}

// (3 M) x K: column k = marker displacements of blendshape k, stacked xyz per marker.
Eigen::MatrixXd MarkerBlendshapes(const FaceRig& rig) {
  Eigen::MatrixXd basis(3 * rig.markers.size(), rig.blendshape_deltas_mm.size());
  for (size_t k = 0; k < rig.blendshape_deltas_mm.size(); ++k) {
    for (size_t m = 0; m < rig.markers.size(); ++m) {
      basis.block<3, 1>(3 * m, k) = rig.markers[m].point.Evaluate(rig.blendshape_deltas_mm[k]);
    }
  }
  return basis;
}

Eigen::Matrix3Xd Posed(const Eigen::Matrix3Xd& rest, const Eigen::MatrixXd& basis,
                       const Eigen::VectorXd& weights) {
  Eigen::Matrix3Xd posed = rest;
  if (weights.size() > 0) {
    const Eigen::VectorXd delta = basis * weights;
    posed += Eigen::Map<const Eigen::Matrix3Xd>(delta.data(), 3, rest.cols());
  }
  return posed;
}

// Marker -> point (or -1) by a gated Hungarian assignment on squared distance, each marker
// with its own gate (the cost is normalised by it).
std::vector<int> AssignPoints(const Eigen::Matrix3Xd& predicted, const Eigen::Matrix3Xd& points,
                              const Eigen::VectorXd& gates_mm) {
  const int m = static_cast<int>(predicted.cols()), n = static_cast<int>(points.cols());
  std::vector<int> point_of_marker(m, -1);
  if (m == 0 || n == 0) return point_of_marker;
  Eigen::MatrixXd cost(m, n);
  for (int i = 0; i < m; ++i) {
    cost.row(i) =
        (points.colwise() - predicted.col(i)).colwise().squaredNorm() / (gates_mm[i] * gates_mm[i]);
  }
  const double gate = 1.0;
  if (m <= n) {
    point_of_marker = SolveGatedAssignment(cost, gate);
  } else {
    const std::vector<int> marker_of_point = SolveGatedAssignment(cost.transpose(), gate);
    for (int j = 0; j < n; ++j) {
      if (marker_of_point[j] >= 0) point_of_marker[marker_of_point[j]] = j;
    }
  }
  return point_of_marker;
}
std::vector<int> AssignPoints(const Eigen::Matrix3Xd& predicted, const Eigen::Matrix3Xd& points,
                              double gate_mm) {
  return AssignPoints(predicted, points, Eigen::VectorXd::Constant(predicted.cols(), gate_mm));
}

// Trimmed ICP of the rest markers onto the points; returns the trimmed RMS.
double TrimmedIcp(const Eigen::Matrix3Xd& rest, const Eigen::Matrix3Xd& points, Rigid3* pose) {
  const int m = static_cast<int>(rest.cols());
  std::vector<std::pair<double, int>> distance(m);
  std::vector<int> nearest(m);
  double rms = 0.0;
  for (int iteration = 0; iteration < 40; ++iteration) {
    const Eigen::Matrix3Xd posed = pose->Apply(rest);
    for (int i = 0; i < m; ++i) {
      Eigen::Index j;
      const double d2 = (points.colwise() - posed.col(i)).colwise().squaredNorm().minCoeff(&j);
      nearest[i] = static_cast<int>(j);
      distance[i] = {d2, i};
    }
    std::sort(distance.begin(), distance.end());
    const int keep = std::max(3, static_cast<int>(0.7 * m));
    Eigen::Matrix3Xd src(3, keep), dst(3, keep);
    double sq = 0.0;
    for (int k = 0; k < keep; ++k) {
      src.col(k) = rest.col(distance[k].second);
      dst.col(k) = points.col(nearest[distance[k].second]);
      sq += distance[k].first;
    }
    rms = std::sqrt(sq / keep);
    const Rigid3 next = FitRigid(src, dst);
    const bool settled = next.IsApprox(*pose, 1e-9);
    *pose = next;
    if (settled) break;
  }
  return rms;
}

// Robust (Huber, IRLS) rigid fit of skull-frame positions onto world points.
Rigid3 RobustRigid(const Eigen::Matrix3Xd& in_skull, const Eigen::Matrix3Xd& in_world,
                   const Eigen::VectorXd& weights, double huber_mm) {
  Rigid3 pose = FitRigid(in_skull, in_world, weights);
  for (int iteration = 0; iteration < 4; ++iteration) {
    Eigen::VectorXd w = weights;
    for (int i = 0; i < in_skull.cols(); ++i) {
      const double e = (pose * Eigen::Vector3d(in_skull.col(i)) - in_world.col(i)).norm();
      if (e > huber_mm) w[i] *= huber_mm / e;
    }
    pose = FitRigid(in_skull, in_world, w);
  }
  return pose;
}

// Up to 6 markers nearest to `marker` at rest (within 30 mm) that are observed at frames a
// and b.
std::vector<int> BridgeNeighbours(const std::vector<TrackedFrame>& frames, int marker, int a, int b,
                                  const Eigen::Matrix3Xd& rest) {
  std::vector<std::pair<double, int>> nearest;
  for (int n = 0; n < rest.cols(); ++n) {
    if (n == marker || frames[a].states[n] != MarkerState::kObserved ||
        frames[b].states[n] != MarkerState::kObserved) {
      continue;
    }
    const double d = (rest.col(n) - rest.col(marker)).norm();
    if (d < 30.0) nearest.emplace_back(d, n);
  }
  std::sort(nearest.begin(), nearest.end());
  std::vector<int> result;
  for (size_t k = 0; k < nearest.size() && k < 6; ++k) result.push_back(nearest[k].second);
  return result;
}

}  // namespace

Status TrackingOptions::Check() const {
  if (!(gate_mm > 0)) return InvalidArgumentError("gate_mm must be > 0");
  if (!(first_frame_gate_mm > 0)) return InvalidArgumentError("first_frame_gate_mm must be > 0");
  if (max_bridge_frames < 0) return InvalidArgumentError("max_bridge_frames must be >= 0");
  return Status::Ok();
}

int TrackedFrame::observed() const {
  return static_cast<int>(std::count(states.begin(), states.end(), MarkerState::kObserved));
}

StatusOr<RigFit> FitRigToPoints(const FaceRig& rig, const Eigen::Matrix3Xd& points,
                                const TrackingOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check().WithContext("tracking options"));
  if (rig.markers.empty()) return FailedPreconditionError("the face rig has no markers");
  if (points.cols() < 6) {
    return FailedPreconditionError("only " + std::to_string(points.cols()) +
                                   " points to fit the rig's markers to (need at least 6)");
  }
  const Eigen::Matrix3Xd rest = RestMarkers(rig);
  const Eigen::MatrixXd basis = MarkerBlendshapes(rig);
  std::vector<Rigid3> candidates;
  if (options.initial_world_from_skull) candidates.push_back(*options.initial_world_from_skull);
  if (options.pose_fixed && candidates.empty()) candidates.push_back(Rigid3());
  // Principal axes of both sets.
  auto axes = [](const Eigen::Matrix3Xd& x, Eigen::Vector3d* mean) {
    *mean = x.rowwise().mean();
    const Eigen::Matrix3Xd centred = x.colwise() - *mean;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(centred * centred.transpose());
    Eigen::Matrix3d v = solver.eigenvectors();
    if (v.determinant() < 0) v.col(0) = -v.col(0);
    return v;
  };
  Eigen::Vector3d rest_mean, points_mean;
  const Eigen::Matrix3d rest_axes = axes(rest, &rest_mean);
  const Eigen::Matrix3d point_axes = axes(points, &points_mean);
  for (const Eigen::Vector3d& signs : {Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(1, -1, -1),
                                       Eigen::Vector3d(-1, 1, -1), Eigen::Vector3d(-1, -1, 1)}) {
    if (options.pose_fixed) break;
    const Eigen::Matrix3d r = point_axes * signs.asDiagonal() * rest_axes.transpose();
    candidates.emplace_back(Eigen::Quaterniond(r), points_mean - r * rest_mean);
  }
  Rigid3 best;
  double best_rms = std::numeric_limits<double>::infinity();
  for (Rigid3 pose : candidates) {
    const double rms = options.pose_fixed ? 0.0 : TrimmedIcp(rest, points, &pose);
    if (rms < best_rms) {
      best_rms = rms;
      best = pose;
    }
  }
  RigFit fit;
  fit.world_from_skull = best;
  fit.blendshape_weights = Eigen::VectorXd::Zero(basis.cols());
  for (int iteration = 0; iteration < 6; ++iteration) {
    const Eigen::Matrix3Xd posed = Posed(rest, basis, fit.blendshape_weights);
    fit.point_of_marker =
        AssignPoints(fit.world_from_skull.Apply(posed), points, options.first_frame_gate_mm);
    std::vector<int> markers;
    for (int m = 0; m < static_cast<int>(rest.cols()); ++m) {
      if (fit.point_of_marker[m] >= 0) markers.push_back(m);
    }
    if (markers.size() < 3) break;
    Eigen::Matrix3Xd src(3, markers.size()), dst(3, markers.size());
    for (size_t k = 0; k < markers.size(); ++k) {
      src.col(k) = posed.col(markers[k]);
      dst.col(k) = points.col(fit.point_of_marker[markers[k]]);
    }
    if (!options.pose_fixed) {
      fit.world_from_skull = RobustRigid(src, dst, Eigen::VectorXd::Ones(src.cols()), 2.0);
    }
    if (basis.cols() > 0) {
      // Expression weights from the assigned markers in the skull frame: ridge least squares
      // on sum_k w_k delta_k = skull_from_world p - rest, clamped to [0, 1].
      const Rigid3 skull_from_world = fit.world_from_skull.Inverse();
      Eigen::MatrixXd a(3 * markers.size(), basis.cols());
      Eigen::VectorXd b(3 * markers.size());
      for (size_t k = 0; k < markers.size(); ++k) {
        a.middleRows<3>(3 * k) = basis.middleRows<3>(3 * markers[k]);
        b.segment<3>(3 * k) = skull_from_world * Eigen::Vector3d(dst.col(k)) - rest.col(markers[k]);
      }
      Eigen::MatrixXd normal = a.transpose() * a;
      normal.diagonal().array() += 1.0;  // mm^2: a weight needs ~1 mm of evidence
      fit.blendshape_weights = normal.ldlt().solve(a.transpose() * b).cwiseMax(0.0).cwiseMin(1.0);
    }
  }
  const Eigen::Matrix3Xd posed =
      fit.world_from_skull.Apply(Posed(rest, basis, fit.blendshape_weights));
  fit.point_of_marker = AssignPoints(posed, points, options.first_frame_gate_mm);
  double sq = 0.0;
  fit.assigned = 0;
  for (int m = 0; m < static_cast<int>(rest.cols()); ++m) {
    if (fit.point_of_marker[m] < 0) continue;
    sq += (posed.col(m) - points.col(fit.point_of_marker[m])).squaredNorm();
    ++fit.assigned;
  }
  fit.rms_mm = fit.assigned ? std::sqrt(sq / fit.assigned) : 0.0;
  if (3 * fit.assigned < static_cast<int>(rest.cols())) {
    return FailedPreconditionError("fitting the rig labelled only " + std::to_string(fit.assigned) +
                                   " of " + std::to_string(rest.cols()) +
                                   " markers (is this the right face rig?)");
  }
  return fit;
}

MarkerTracker::MarkerTracker(const FaceRig& rig, const TrackingOptions& options)
    : rig_(rig), options_(options), rest_in_skull_(RestMarkers(rig)) {
  FACEDYN_CHECK(options.Check().ok(), "MarkerTracker: " + options.Check().message());
  last_in_skull_ = rest_in_skull_;
  velocity_in_skull_ = Eigen::Matrix3Xd::Zero(3, rest_in_skull_.cols());
  last_observed_frame_.assign(rest_in_skull_.cols(), -1);
  innovation_rms_mm_ = Eigen::VectorXd::Constant(rest_in_skull_.cols(), 0.25 * options.gate_mm);
}

StatusOr<TrackedFrame> MarkerTracker::AddFrame(const std::vector<TriangulatedPoint>& points) {
  const int m_count = marker_count();
  const int t = static_cast<int>(frames_.size());
  Eigen::Matrix3Xd world(3, points.size());
  for (size_t j = 0; j < points.size(); ++j) world.col(j) = points[j].position_in_world;
  TrackedFrame frame;
  frame.points = static_cast<int>(points.size());
  frame.states.assign(m_count, MarkerState::kMissing);
  frame.confidence.assign(m_count, 0.0);
  frame.point_of_marker.assign(m_count, -1);

  if (!initialised_) {
    if (points.size() >= 6) {
      FACEDYN_ASSIGN_OR_RETURN(const RigFit fit, FitRigToPoints(rig_, world, options_));
      initialised_ = true;
      frame.world_from_skull_tracking = fit.world_from_skull;
      frame.point_of_marker = fit.point_of_marker;
      const Rigid3 skull_from_world = fit.world_from_skull.Inverse();
      for (int m = 0; m < m_count; ++m) {
        const int j = fit.point_of_marker[m];
        if (j < 0) continue;
        last_in_skull_.col(m) = skull_from_world * Eigen::Vector3d(world.col(j));
        last_observed_frame_[m] = t;
        frame.states[m] = MarkerState::kObserved;
        frame.confidence[m] = points[j].confidence;
      }
    } else {
      frame.world_from_skull_tracking = options_.initial_world_from_skull.value_or(Rigid3());
    }
    frame.positions_in_world = frame.world_from_skull_tracking.Apply(last_in_skull_);
  } else {
    const Rigid3& previous = poses_.back();
    const Rigid3 predicted_pose =
        poses_.size() >= 2 ? previous * (poses_[poses_.size() - 2].Inverse() * previous) : previous;
    Eigen::Matrix3Xd predicted_in_skull = last_in_skull_;
    for (int m = 0; m < m_count; ++m) {
      if (last_observed_frame_[m] == t - 1) predicted_in_skull.col(m) += velocity_in_skull_.col(m);
    }
    const Eigen::Matrix3Xd predicted = predicted_pose.Apply(predicted_in_skull);
    // Per-marker gate: 4 times the marker's recent prediction error, within
    // [min(1.5 mm, gate_mm), gate_mm], so a well-predicted marker does not grab a stray point
    // that happens to lie near it while it is hidden.
    Eigen::VectorXd gates(m_count);
    for (int m = 0; m < m_count; ++m) {
      gates[m] = std::clamp(4.0 * innovation_rms_mm_[m], std::min(1.5, options_.gate_mm),
                            options_.gate_mm);
      if (last_observed_frame_[m] != t - 1) gates[m] = options_.gate_mm;
    }
    frame.point_of_marker = AssignPoints(predicted, world, gates);
    std::vector<int> assigned;
    for (int m = 0; m < m_count; ++m) {
      if (frame.point_of_marker[m] >= 0) assigned.push_back(m);
    }
    Rigid3 pose = options_.pose_fixed ? previous : predicted_pose;
    if (assigned.size() >= 3 && !options_.pose_fixed) {
      Eigen::Matrix3Xd src(3, assigned.size()), dst(3, assigned.size());
      Eigen::VectorXd weights(assigned.size());
      for (size_t k = 0; k < assigned.size(); ++k) {
        src.col(k) = predicted_in_skull.col(assigned[k]);
        dst.col(k) = world.col(frame.point_of_marker[assigned[k]]);
        weights[k] = std::max(0.05, points[frame.point_of_marker[assigned[k]]].confidence);
      }
      pose = RobustRigid(src, dst, weights, 1.0);
    }
    frame.world_from_skull_tracking = pose;
    const Rigid3 skull_from_world = pose.Inverse();
    for (int m : assigned) {
      const int j = frame.point_of_marker[m];
      const Eigen::Vector3d q = skull_from_world * Eigen::Vector3d(world.col(j));
      velocity_in_skull_.col(m) = last_observed_frame_[m] == t - 1
                                      ? Eigen::Vector3d(q - last_in_skull_.col(m))
                                      : Eigen::Vector3d::Zero();
      last_in_skull_.col(m) = q;
      last_observed_frame_[m] = t;
      const double innovation_mm = (world.col(j) - predicted.col(m)).norm();
      innovation_rms_mm_[m] = std::sqrt(0.8 * innovation_rms_mm_[m] * innovation_rms_mm_[m] +
                                        0.2 * innovation_mm * innovation_mm);
      const double innovation = innovation_mm / options_.gate_mm;
      frame.states[m] = MarkerState::kObserved;
      frame.confidence[m] = points[j].confidence * std::max(0.0, 1.0 - innovation * innovation);
    }
    frame.positions_in_world = pose.Apply(last_in_skull_);
    for (int m = 0; m < m_count; ++m) {
      if (frame.point_of_marker[m] < 0) {
        frame.positions_in_world.col(m) = pose * Eigen::Vector3d(predicted_in_skull.col(m));
      }
    }
  }
  int labelled = 0;
  for (int j : frame.point_of_marker) labelled += j >= 0 ? 1 : 0;
  frame.unlabelled_points = frame.points - labelled;
  poses_.push_back(frame.world_from_skull_tracking);
  frames_.push_back(frame);
  return frame;
}

std::vector<TrackedFrame> MarkerTracker::Finish() {
  std::vector<TrackedFrame> frames = frames_;
  const int n = static_cast<int>(frames.size());
  // Frames too empty for their own pose (fewer than 3 labelled markers) take the pose
  // interpolated between the nearest frames that had one, instead of the extrapolation.
  std::vector<int> posed;
  for (int t = 0; t < n; ++t) {
    if (frames[t].observed() >= 3) posed.push_back(t);
  }
  for (size_t k = 0; k + 1 < posed.size(); ++k) {
    for (int t = posed[k] + 1; t < posed[k + 1]; ++t) {
      const double s = static_cast<double>(t - posed[k]) / (posed[k + 1] - posed[k]);
      frames[t].world_from_skull_tracking =
          Rigid3::Interpolate(frames[posed[k]].world_from_skull_tracking,
                              frames[posed[k + 1]].world_from_skull_tracking, s);
    }
  }
  for (int m = 0; m < marker_count(); ++m) {
    int last = -1;
    for (int t = 0; t < n; ++t) {
      if (frames[t].states[m] != MarkerState::kObserved) continue;
      const int gap = t - last - 1;
      if (last >= 0 && gap > 0 && gap <= options_.max_bridge_frames) {
        const Eigen::Vector3d qa = frames[last].world_from_skull_tracking.Inverse() *
                                   Eigen::Vector3d(frames[last].positions_in_world.col(m));
        const Eigen::Vector3d qb = frames[t].world_from_skull_tracking.Inverse() *
                                   Eigen::Vector3d(frames[t].positions_in_world.col(m));
        const double confidence = 0.5 *
                                  std::min(frames[last].confidence[m], frames[t].confidence[m]) *
                                  (1.0 - gap / (options_.max_bridge_frames + 1.0));
        // Neighbours observed at both ends: the hidden marker moves (in the skull frame) as
        // they do, blended from both ends; with none, linearly.
        const std::vector<int> neighbours = BridgeNeighbours(frames, m, last, t, rest_in_skull_);
        auto in_skull = [&](int frame, int marker) {
          return Eigen::Vector3d(frames[frame].world_from_skull_tracking.Inverse() *
                                 Eigen::Vector3d(frames[frame].positions_in_world.col(marker)));
        };
        for (int k = last + 1; k < t; ++k) {
          const double s = static_cast<double>(k - last) / (t - last);
          Eigen::Vector3d q = (1 - s) * qa + s * qb;
          std::vector<int> present;
          for (int n2 : neighbours) {
            if (frames[k].states[n2] == MarkerState::kObserved) present.push_back(n2);
          }
          if (present.size() >= 3) {
            Eigen::Vector3d from_a = Eigen::Vector3d::Zero(), from_b = Eigen::Vector3d::Zero();
            for (int n2 : present) {
              from_a += in_skull(k, n2) - in_skull(last, n2);
              from_b += in_skull(k, n2) - in_skull(t, n2);
            }
            q = (1 - s) * (qa + from_a / present.size()) + s * (qb + from_b / present.size());
          }
          frames[k].positions_in_world.col(m) = frames[k].world_from_skull_tracking * q;
          frames[k].states[m] = MarkerState::kBridged;
          frames[k].confidence[m] = confidence;
        }
      }
      last = t;
    }
  }
  return frames;
}

}  // namespace facedyn::reconstruct
