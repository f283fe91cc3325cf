#include "reconstruct/skull_pose.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <mutex>
#include <set>

#include "core/log.h"
#include "core/mesh.h"
#include "physics/inertial_deflection.h"
#include "reconstruct/rigid_fit.h"

namespace facedyn::reconstruct {
namespace {

// FNV-1a over the bytes the tissue model's shapes depend on: the skin and its faces, the skull,
// the regions and the markers' surface points.
uint64_t RigShapeKey(const FaceRig& rig) {
  uint64_t h = 1469598103934665603ull;
  auto mix = [&h](const void* data, size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 1099511628211ull;
  };
  mix(rig.neutral.positions_mm.data(), sizeof(double) * rig.neutral.positions_mm.size());
  mix(rig.skull.positions_mm.data(), sizeof(double) * rig.skull.positions_mm.size());
  mix(rig.neutral.corner_vertices.data(), sizeof(int) * rig.neutral.corner_vertices.size());
  for (const auto& [name, vertices] : rig.regions) {
    mix(name.data(), name.size());
    mix(vertices.data(), sizeof(vertices[0]) * vertices.size());
  }
  for (const Marker& marker : rig.markers) {
    mix(marker.point.vertices.data(), sizeof(marker.point.vertices));
    mix(marker.point.weights.data(), sizeof(marker.point.weights));
  }
  return h;
}

// The tissue model's shapes, computed once per rig in a process (a factorisation of the
// flesh's stiffness, seconds): a demo reconstructs dozens of takes of one face.
StatusOr<Eigen::MatrixXd> TissueDeflectionBasis(const FaceRig& rig) {
  static std::mutex mutex;
  static std::map<uint64_t, StatusOr<Eigen::MatrixXd>> cache;
  const uint64_t key = RigShapeKey(rig);
  std::lock_guard<std::mutex> lock(mutex);
  const auto found = cache.find(key);
  if (found != cache.end()) return found->second;
  StatusOr<Eigen::MatrixXd> basis =
      physics::MarkerInertialDeflectionBasis(rig, TissueModelDeflectionOptions());
  cache.emplace(key, basis);
  return basis;
}

// The take-level reference leaves out a marker's samples farther than this (or 6 robust
// standard deviations, whichever is more) from their median: a jiggle of a millimetre stays in.
constexpr double kTakeReferenceMinBoundMm = 1.0;

}  // namespace

physics::InertialDeflectionOptions TissueModelDeflectionOptions() {
  physics::InertialDeflectionOptions options;
  options.angular = false;
  options.krylov_blocks = 2;
  return options;
}

Status SkullPoseOptions::Check() const {
  if (!(huber_mm > 0)) return InvalidArgumentError("huber_mm must be > 0");
  if (iterations < 1) return InvalidArgumentError("iterations must be >= 1");
  if (min_markers < 3) return InvalidArgumentError("min_markers must be >= 3");
  return Status::Ok();
}

SkullPoseEstimator::SkullPoseEstimator(const FaceRig& rig, const SkullPoseOptions& options)
    : options_(options) {
  status_ = options.Check().WithContext("skull pose options");
  if (!status_.ok()) return;
  std::set<int> stable_vertices;
  for (const std::string& name : rig.stable_regions) {
    const auto region = rig.regions.find(name);
    if (region == rig.regions.end()) continue;
    stable_vertices.insert(region->second.begin(), region->second.end());
  }
  for (int m = 0; m < static_cast<int>(rig.markers.size()); ++m) {
    const SurfacePoint& p = rig.markers[m].point;
    bool stable = true;
    for (int k = 0; k < 3; ++k) {
      stable = stable && (p.weights[k] == 0.0 || stable_vertices.count(p.vertices[k]) > 0);
    }
    if (stable) stable_markers_.push_back(m);
  }
  const Eigen::Index basis_rows = options.deflection_basis.rows();
  if (options.deflection_basis.size() > 0 &&
      (basis_rows != 3 * static_cast<Eigen::Index>(rig.markers.size()) ||
       !options.deflection_basis.allFinite())) {
    status_ = InvalidArgumentError(
        "skull pose options: deflection_basis has " + std::to_string(basis_rows) + " rows for " +
        std::to_string(rig.markers.size()) + " markers (3 per marker, finite)");
    return;
  }
  if (!options.deflection_model) {
    deflection_shape_used_ = "none";
  } else if (options.deflection_basis.size() > 0) {
    deflection_basis_ = options.deflection_basis;
    deflection_shape_used_ = "explicit basis";
  } else if (options.deflection_shape == DeflectionShape::kTissueModel &&
             stable_markers_.size() >= static_cast<size_t>(options.min_markers)) {
    if (rig.skull.vertex_count() != rig.neutral.vertex_count()) {
      deflection_shape_used_ =
          "thickness_squared (the rig's skull does not share the skin's topology, so it has no "
          "tissue model)";
    } else {
      StatusOr<Eigen::MatrixXd> basis = TissueDeflectionBasis(rig);
      if (basis.ok()) {
        deflection_basis_ = std::move(*basis);
        deflection_shape_used_ = "tissue_model";
      } else {
        deflection_shape_used_ =
            "thickness_squared (tissue model: " + basis.status().message() + ")";
      }
    }
    if (deflection_basis_.size() == 0) {
      spdlog::warn("skull pose: deflection shape {}", deflection_shape_used_);
    }
  } else {
    deflection_shape_used_ = "thickness_squared";
  }
  if (static_cast<int>(stable_markers_.size()) < options.min_markers) {
    status_ =
        FailedPreconditionError("the face rig has " + std::to_string(stable_markers_.size()) +
                                " markers on its stable regions; the skull pose needs at least " +
                                std::to_string(options.min_markers));
    return;
  }
  const int n = static_cast<int>(stable_markers_.size());
  rest_in_skull_.resize(3, n);
  normal_in_skull_.resize(3, n);
  thickness_mm_.resize(n);
  const Eigen::Matrix3Xd normals = VertexNormals(rig.neutral, rig.neutral.positions_mm);
  // Tissue thickness: distance from the skin point to the skull beneath it. When the skull
  // shares the skin's topology (as FaceRigs from physics/face_anatomy.h do) that is the same
  // surface point on the skull; otherwise the nearest skull vertex.
  const bool paired = rig.skull.vertex_count() == rig.neutral.vertex_count();
  for (int k = 0; k < n; ++k) {
    const SurfacePoint& p = rig.markers[stable_markers_[k]].point;
    const Eigen::Vector3d skin = p.Evaluate(rig.neutral.positions_mm);
    rest_in_skull_.col(k) = skin;
    const Eigen::Vector3d normal = p.Evaluate(normals);
    normal_in_skull_.col(k) =
        normal.norm() > 1e-12 ? Eigen::Vector3d(normal.normalized()) : Eigen::Vector3d::UnitZ();
    double thickness = 5.0;
    if (paired) {
      thickness = (skin - p.Evaluate(rig.skull.positions_mm)).norm();
    } else if (rig.skull.vertex_count() > 0) {
      thickness =
          std::sqrt((rig.skull.positions_mm.colwise() - skin).colwise().squaredNorm().minCoeff());
    }
    thickness_mm_[k] = std::max(0.5, thickness);
  }
  const double thinnest = thickness_mm_.minCoeff();
  prior_weights_ = options.thickness_prior
                       ? Eigen::VectorXd((thinnest / thickness_mm_.array())
                                             .pow(options.thickness_weight_power))
                       : Eigen::VectorXd::Ones(n);
}

SkullPoseResult SkullPoseEstimator::Estimate(const Eigen::Matrix3Xd& markers_in_world,
                                             const std::vector<MarkerState>& states,
                                             const std::vector<double>& confidence,
                                             const Rigid3& initial) const {
  SkullPoseResult result;
  result.world_from_skull = initial;
  if (!status_.ok()) return result;
  std::vector<int> used;
  for (int k = 0; k < static_cast<int>(stable_markers_.size()); ++k) {
    const int m = stable_markers_[k];
    if (states[m] != MarkerState::kMissing && confidence[m] > 0) used.push_back(k);
  }
  if (static_cast<int>(used.size()) < options_.min_markers) return result;
  const int n = static_cast<int>(used.size());
  Eigen::Matrix3Xd src(3, n), dst(3, n);
  Eigen::VectorXd base(n);
  for (int i = 0; i < n; ++i) {
    src.col(i) = rest_in_skull_.col(used[i]);
    dst.col(i) = markers_in_world.col(stable_markers_[used[i]]);
    base[i] = prior_weights_[used[i]] * confidence[stable_markers_[used[i]]];
  }
  // Squared thickness per used marker, normalised: the inertial deflection model's shape.
  Eigen::VectorXd shape(n);
  for (int i = 0; i < n; ++i) shape[i] = std::pow(thickness_mm_[used[i]] / 5.0, 2);
  Eigen::Vector3d deflection = Eigen::Vector3d::Zero();  // d, skull frame, mm at 5 mm tissue
  // The basis's rows of the used markers (3n x K), when the options carry one.
  const bool basis = deflection_basis_.size() > 0;
  Eigen::MatrixXd used_basis;
  if (basis) {
    used_basis.resize(3 * n, deflection_basis_.cols());
    for (int i = 0; i < n; ++i) {
      used_basis.middleRows<3>(3 * i) =
          deflection_basis_.middleRows<3>(3 * stable_markers_[used[i]]);
    }
  }
  Rigid3 pose = FitRigid(src, dst, base);
  Eigen::VectorXd weights = base;
  Eigen::Matrix3Xd deflected = src;
  for (int iteration = 0; iteration < options_.iterations; ++iteration) {
    for (int i = 0; i < n; ++i) {
      const double e = (pose * Eigen::Vector3d(deflected.col(i)) - dst.col(i)).norm();
      weights[i] = base[i] * (e > options_.huber_mm ? options_.huber_mm / e : 1.0);
    }
    if (options_.deflection_model) {
      // d given T: weighted least squares of shape_i d = skull_from_world dst_i - rest_i.
      const Rigid3 skull_from_world = pose.Inverse();
      Eigen::Vector3d numerator = Eigen::Vector3d::Zero();
      double denominator = 0.0;
      for (int i = 0; i < n; ++i) {
        numerator +=
            weights[i] * shape[i] * (skull_from_world * Eigen::Vector3d(dst.col(i)) - src.col(i));
        denominator += weights[i] * shape[i] * shape[i];
      }
      deflection = numerator / denominator;
      for (int i = 0; i < n; ++i) deflected.col(i) = src.col(i) + shape[i] * deflection;
    }
    const Rigid3 next = FitRigid(deflected, dst, weights);
    const bool settled = next.IsApprox(pose, 1e-10);
    pose = next;
    if (settled && iteration > 2) break;
  }
  if (options_.deflection_model && basis) {
    // Pose and coefficients c together by Gauss-Newton with Huber reweighting, from the t^2
    // law's pose above: the residual of marker i is T (rest_i + B_i c) - dst_i; a pose update
    // is a small rotation w and a translation v applied in the world frame,
    // x <- x + w x x + v, so its Jacobian is [-[x]_x, I, R B_i] (w held at zero when the
    // rotation is the law's). Alternating c and T (as for d above) converges slowly when the
    // shapes are close to a rigid motion on the stable markers; the joint step does not.
    const Eigen::Index k = used_basis.cols();
    const Eigen::Index unknowns = 6 + k;
    Eigen::VectorXd coefficients = Eigen::VectorXd::Zero(k);
    deflected = src;
    for (int iteration = 0; iteration < 4 * options_.iterations; ++iteration) {
      const Eigen::Matrix3d rotation = pose.RotationMatrix();
      Eigen::MatrixXd normal_matrix = Eigen::MatrixXd::Zero(unknowns, unknowns);
      Eigen::VectorXd rhs = Eigen::VectorXd::Zero(unknowns);
      Eigen::Matrix<double, 3, Eigen::Dynamic> jacobian(3, unknowns);
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d x = pose * Eigen::Vector3d(deflected.col(i));
        const Eigen::Vector3d r = x - dst.col(i);
        const double e = r.norm();
        weights[i] = base[i] * (e > options_.huber_mm ? options_.huber_mm / e : 1.0);
        jacobian.leftCols<3>() << 0, x.z(), -x.y(), -x.z(), 0, x.x(), x.y(), -x.x(), 0;
        jacobian.middleCols<3>(3).setIdentity();
        jacobian.rightCols(k) = rotation * used_basis.middleRows<3>(3 * i);
        normal_matrix.noalias() += weights[i] * jacobian.transpose() * jacobian;
        rhs.noalias() -= weights[i] * jacobian.transpose() * r;
      }
      if (options_.rotation_from_thickness_law) {
        normal_matrix.topRows<3>().setZero();
        normal_matrix.leftCols<3>().setZero();
        normal_matrix.topLeftCorner<3, 3>().setIdentity();
        rhs.head<3>().setZero();
      }
      // A ridge of 1e-9 of the trace for directions no marker constrains. (A prior on c, a
      // ridge of 1e-4 to 1e-1 of the markers' total weight, was no better in skull_pose_bench.)
      normal_matrix.diagonal().array() += 1e-9 * normal_matrix.trace() / unknowns + 1e-300;
      const Eigen::VectorXd step = normal_matrix.ldlt().solve(rhs);
      const Eigen::Vector3d w = step.head<3>();
      const Rigid3 update = Rigid3::FromAxisAngle(
          w.norm() > 0 ? Eigen::Vector3d(w.normalized()) : Eigen::Vector3d::UnitX(), w.norm(),
          step.segment<3>(3));
      pose = update * pose;
      coefficients += step.tail(k);
      for (int i = 0; i < n; ++i) {
        deflected.col(i) = src.col(i) + used_basis.middleRows<3>(3 * i) * coefficients;
      }
      if (step.head<6>().norm() < 1e-10 && iteration > 1) break;
    }
  }
  if (options_.translation_from_normals) {
    // T <- T (I, v): skull_from_world x_i moves by -v, so the normal residual against the rest
    // position (a tangential deflection has no normal part; d above has one, so it is not used)
    // e_i = n_i . (T^-1 dst_i - rest_i) becomes e_i - n_i . v; weighted least squares in v.
    for (int iteration = 0; iteration < 3; ++iteration) {
      const Rigid3 skull_from_world = pose.Inverse();
      Eigen::Matrix3d normal_matrix = Eigen::Matrix3d::Zero();
      Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d normal = normal_in_skull_.col(used[i]);
        // With a basis the deflection's normal part is modelled, so it is kept.
        const Eigen::Vector3d reference = basis ? deflected.col(i) : src.col(i);
        const double e = normal.dot(skull_from_world * Eigen::Vector3d(dst.col(i)) - reference);
        normal_matrix += weights[i] * normal * normal.transpose();
        rhs += weights[i] * normal * e;
      }
      // Directions no normal covers keep their translation (a small ridge).
      normal_matrix += 1e-9 * normal_matrix.trace() * Eigen::Matrix3d::Identity();
      const Eigen::Vector3d v = normal_matrix.ldlt().solve(rhs);
      pose = pose * Rigid3::FromTranslation(v);
      if (v.norm() < 1e-9) break;
    }
  }
  double sq = 0.0;
  for (int i = 0; i < n; ++i) {
    sq += weights[i] * (pose * Eigen::Vector3d(deflected.col(i)) - dst.col(i)).squaredNorm();
  }
  result.deflection_mm = deflection;
  result.world_from_skull = pose;
  result.markers_used = n;
  result.rms_mm = std::sqrt(sq / weights.sum());
  result.ok = true;
  return result;
}

std::vector<SkullPoseResult> SkullPoseEstimator::EstimateTake(
    const std::vector<TrackedFrame>& frames, TakeReferenceResult* reference) const {
  std::vector<SkullPoseResult> results;
  results.reserve(frames.size());
  for (const TrackedFrame& frame : frames) results.push_back(Estimate(frame));
  TakeReferenceResult local;
  TakeReferenceResult& report = reference != nullptr ? *reference : local;
  report = TakeReferenceResult();
  if (!options_.take_reference) {
    report.reason = "off (SkullPoseOptions::take_reference)";
    return results;
  }
  if (!status_.ok()) {
    report.reason = status_.message();
    return results;
  }
  int posed = 0;
  for (const SkullPoseResult& r : results) posed += r.ok ? 1 : 0;
  if (posed < options_.take_reference_min_frames) {
    report.reason = "the take has " + std::to_string(posed) + " posed frames, fewer than " +
                    std::to_string(options_.take_reference_min_frames);
    return results;
  }
  const int n = static_cast<int>(stable_markers_.size());
  std::vector<int> refined;
  Eigen::Matrix3Xd means(3, n);
  std::vector<Rigid3> skull_from_world(frames.size());  // inverted once per frame
  for (size_t f = 0; f < frames.size(); ++f) {
    if (results[f].ok) skull_from_world[f] = results[f].world_from_skull.Inverse();
  }
  std::vector<double> samples[3];
  for (int k = 0; k < n; ++k) {
    const int m = stable_markers_[k];
    for (auto& s : samples) s.clear();
    for (size_t f = 0; f < frames.size(); ++f) {
      if (!results[f].ok || frames[f].states[m] != MarkerState::kObserved ||
          !(frames[f].confidence[m] > 0)) {
        continue;
      }
      const Eigen::Vector3d in_skull =
          skull_from_world[f] * Eigen::Vector3d(frames[f].positions_in_world.col(m));
      for (int axis = 0; axis < 3; ++axis) samples[axis].push_back(in_skull[axis]);
    }
    if (4 * static_cast<int>(samples[0].size()) < posed) continue;
    for (int axis = 0; axis < 3; ++axis) {
      // The mean, not the median: the jiggle's mean over a take is the static response to the
      // take's mean load, which the median of a skewed response (the impacts of a run) is not
      // (skull_pose_bench seed 1, run in place: 0.127 mm with the median, 0.053 with the mean,
      // 0.051 per frame).
      // Samples far from the median (a mislabelled frame) are left out.
      std::vector<double>& s = samples[axis];
      auto middle = s.begin() + s.size() / 2;
      std::nth_element(s.begin(), middle, s.end());
      const double median = *middle;
      std::vector<double> deviation(s.size());
      for (size_t i = 0; i < s.size(); ++i) deviation[i] = std::abs(s[i] - median);
      auto mid = deviation.begin() + deviation.size() / 2;
      std::nth_element(deviation.begin(), mid, deviation.end());
      const double bound = std::max(kTakeReferenceMinBoundMm, 6.0 * 1.4826 * *mid);
      double sum = 0.0;
      int kept = 0;
      for (double x : s) {
        if (std::abs(x - median) > bound) continue;
        sum += x;
        ++kept;
      }
      means(axis, static_cast<int>(refined.size())) = sum / kept;
    }
    refined.push_back(k);
  }
  if (static_cast<int>(refined.size()) < std::max(options_.min_markers, 3)) {
    report.reason = "only " + std::to_string(refined.size()) +
                    " stable markers were observed on a quarter of the posed frames";
    return results;
  }
  const int r = static_cast<int>(refined.size());
  Eigen::Matrix3Xd measured = means.leftCols(r), rig_reference(3, r);
  Eigen::VectorXd weights(r);
  for (int i = 0; i < r; ++i) {
    rig_reference.col(i) = rest_in_skull_.col(refined[i]);
    weights[i] = prior_weights_[refined[i]];
  }
  // The means are in the first poses' skull frame, which is off by a constant rigid motion
  // (what this step removes): align them to the rig's reference.
  const Rigid3 reference_from_measured = FitRigid(measured, rig_reference, weights);
  SkullPoseEstimator refined_estimator = *this;
  double sq = 0.0;
  for (int i = 0; i < r; ++i) {
    const Eigen::Vector3d updated = reference_from_measured * Eigen::Vector3d(measured.col(i));
    const double correction = (updated - rig_reference.col(i)).norm();
    sq += correction * correction;
    report.correction_max_mm = std::max(report.correction_max_mm, correction);
    refined_estimator.rest_in_skull_.col(refined[i]) = updated;
  }
  report.applied = true;
  report.markers_refined = r;
  report.correction_rms_mm = std::sqrt(sq / r);
  for (size_t f = 0; f < frames.size(); ++f) {
    results[f] = refined_estimator.Estimate(frames[f]);
  }
  return results;
}

}  // namespace facedyn::reconstruct
