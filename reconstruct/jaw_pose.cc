#include "reconstruct/jaw_pose.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <set>

#include "core/check.h"
#include "reconstruct/synthetic_views.h"

namespace facedyn::reconstruct {
namespace {

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

Eigen::Matrix3d ExpSo3(const Eigen::Vector3d& omega) {
  const double angle = omega.norm();
  if (angle < 1e-12) return Eigen::Matrix3d::Identity() + Skew(omega);
  return Eigen::AngleAxisd(angle, omega / angle).toRotationMatrix();
}

Eigen::Vector3d LogSo3(const Eigen::Matrix3d& rotation) {
  const Eigen::AngleAxisd aa(rotation);
  return aa.angle() * aa.axis();
}

// The pure-hinge weighted least-squares angle (see the header): arms s_i (rest minus pivot)
// and d_i (observed minus pivot), 3 x n each.
double HingeAngleClosedForm(const Eigen::Vector3d& axis, const Eigen::Matrix3Xd& s,
                            const Eigen::Matrix3Xd& d, const Eigen::VectorXd& weights) {
  double sine = 0.0, cosine = 0.0;
  for (int i = 0; i < s.cols(); ++i) {
    const Eigen::Vector3d sp = s.col(i) - axis.dot(s.col(i)) * axis;
    const Eigen::Vector3d dp = d.col(i) - axis.dot(d.col(i)) * axis;
    sine += weights[i] * axis.dot(sp.cross(dp));
    cosine += weights[i] * sp.dot(dp);
  }
  return std::atan2(sine, cosine);
}

bool InRegion(const SurfacePoint& p, const std::set<int>& vertices) {
  for (int k = 0; k < 3; ++k) {
    if (p.weights[k] != 0.0 && vertices.count(p.vertices[k]) == 0) return false;
  }
  return true;
}

}  // namespace

Rigid3 SkullFromJawHinge(const JawModel& jaw, double angle_rad) {
  const Eigen::Quaterniond q(Eigen::AngleAxisd(angle_rad, jaw.axis_in_skull.normalized()));
  return Rigid3(q, jaw.pivot_in_skull - q * jaw.pivot_in_skull);
}

double JawHingeAngleRad(const JawModel& jaw, const Rigid3& skull_from_jaw) {
  const Eigen::Quaterniond& q = skull_from_jaw.rotation();
  double angle = 2.0 * std::atan2(q.vec().dot(jaw.axis_in_skull.normalized()), q.w());
  if (angle > M_PI) angle -= 2.0 * M_PI;
  if (angle <= -M_PI) angle += 2.0 * M_PI;
  return angle;
}

Status JawPoseOptions::Check() const {
  if (min_markers < 2) {
    return InvalidArgumentError(fmt::format("min_markers must be >= 2, got {}", min_markers));
  }
  if (!(huber_mm > 0))
    return InvalidArgumentError(fmt::format("huber_mm must be > 0, got {}", huber_mm));
  if (iterations < 1)
    return InvalidArgumentError(fmt::format("iterations must be >= 1, got {}", iterations));
  if (!(translation_prior_mm >= 0 && std::isfinite(translation_prior_mm))) {
    return InvalidArgumentError(
        fmt::format("translation_prior_mm must be >= 0, got {}", translation_prior_mm));
  }
  if (!(extra_rotation_prior_rad >= 0 && std::isfinite(extra_rotation_prior_rad))) {
    return InvalidArgumentError(
        fmt::format("extra_rotation_prior_rad must be >= 0, got {}", extra_rotation_prior_rad));
  }
  if (deflection_terms < 0 || deflection_terms > 2) {
    return InvalidArgumentError(
        fmt::format("deflection_terms must be 0, 1 or 2, got {}", deflection_terms));
  }
  if (!(normal_deflection_ratio >= 0 && normal_deflection_ratio <= 1)) {
    return InvalidArgumentError(
        fmt::format("normal_deflection_ratio must be in [0, 1], got {}", normal_deflection_ratio));
  }
  return Status::Ok();
}

JawPoseEstimator::JawPoseEstimator(const FaceRig& rig, const JawPoseOptions& options)
    : options_(options), jaw_(rig.jaw) {
  status_ = options.Check().WithContext("jaw pose options");
  if (!status_.ok()) return;
  if (rig.jaw.region.empty()) return;  // no jaw: nothing to estimate, and that is fine
  has_jaw_ = true;
  if (!(rig.jaw.axis_in_skull.norm() > 1e-9) || !rig.jaw.axis_in_skull.allFinite() ||
      !rig.jaw.pivot_in_skull.allFinite()) {
    status_ = InvalidArgumentError(
        "the face rig's jaw hinge axis is zero, or its axis or pivot is not finite");
    return;
  }
  jaw_.axis_in_skull = rig.jaw.axis_in_skull.normalized();
  const auto region = rig.regions.find(rig.jaw.region);
  if (region == rig.regions.end()) {
    status_ = FailedPreconditionError(
        fmt::format("the face rig's jaw region '{}' is not one of its regions", rig.jaw.region));
    return;
  }
  const std::set<int> jaw_vertices(region->second.begin(), region->second.end());
  std::set<int> rigid_vertices;  // jaw AND (chin OR cheeks)
  std::set<int> chin_vertices;
  for (const char* name : {"chin", "cheeks"}) {
    const auto it = rig.regions.find(name);
    if (it == rig.regions.end()) continue;
    for (int v : it->second) {
      if (jaw_vertices.count(v) == 0) continue;
      rigid_vertices.insert(v);
      if (std::string(name) == "chin") chin_vertices.insert(v);
    }
  }
  std::vector<int> on_jaw, on_rigid_part;
  for (int m = 0; m < static_cast<int>(rig.markers.size()); ++m) {
    const SurfacePoint& p = rig.markers[m].point;
    if (!InRegion(p, jaw_vertices)) continue;
    on_jaw.push_back(m);
    if (InRegion(p, rigid_vertices)) on_rigid_part.push_back(m);
  }
  jaw_markers_ =
      static_cast<int>(on_rigid_part.size()) >= options.min_markers ? on_rigid_part : on_jaw;
  if (static_cast<int>(jaw_markers_.size()) < options.min_markers) {
    status_ = FailedPreconditionError(fmt::format(
        "the face rig's jaw region '{}' carries {} markers; the jaw pose needs at least {}",
        rig.jaw.region, jaw_markers_.size(), options.min_markers));
    return;
  }
  const int n = static_cast<int>(jaw_markers_.size());
  rest_in_skull_.resize(3, n);
  thickness_mm_.resize(n);
  // Tissue thickness as in skull_pose.cc: the same surface point on the skull when the skull
  // shares the skin's topology, otherwise the nearest skull vertex, otherwise a nominal 10 mm.
  const bool paired = rig.skull.vertex_count() == rig.neutral.vertex_count();
  for (int k = 0; k < n; ++k) {
    const SurfacePoint& p = rig.markers[jaw_markers_[k]].point;
    const Eigen::Vector3d skin = p.Evaluate(rig.neutral.positions_mm);
    rest_in_skull_.col(k) = skin;
    double thickness = 10.0;
    if (paired) {
      thickness = (skin - p.Evaluate(rig.skull.positions_mm)).norm();
    } else if (rig.skull.vertex_count() > 0) {
      thickness =
          std::sqrt((rig.skull.positions_mm.colwise() - skin).colwise().squaredNorm().minCoeff());
    }
    thickness_mm_[k] = std::max(0.5, thickness);
  }
  // Deflection profiles (see the header): P2_m = (t_m / 10 mm)^2 (I - (1 - r) n_m n_m^T),
  // P4_m = (t_m / 10 mm)^2 P2_m, n_m the skin normal at rest, r = normal_deflection_ratio.
  const Eigen::Matrix3Xd normals = VertexNormals(rig.neutral, rig.neutral.positions_mm);
  profile_t2_.resize(n);
  profile_t4_.resize(n);
  for (int k = 0; k < n; ++k) {
    const SurfacePoint& p = rig.markers[jaw_markers_[k]].point;
    const Eigen::Vector3d normal = p.Evaluate(normals).normalized();
    const double k2 = std::pow(thickness_mm_[k] / 10.0, 2);
    profile_t2_[k] = k2 * (Eigen::Matrix3d::Identity() -
                           (1.0 - options.normal_deflection_ratio) * normal * normal.transpose());
    profile_t4_[k] = k2 * profile_t2_[k];
  }
  const double thinnest = thickness_mm_.minCoeff();
  prior_weights_ = options.thickness_prior
                       ? Eigen::VectorXd((thinnest / thickness_mm_.array()).pow(4))
                       : Eigen::VectorXd::Ones(n);
  if (!chin_vertices.empty()) {
    for (int v : chin_vertices) reference_point_in_skull_ += rig.neutral.positions_mm.col(v);
    reference_point_in_skull_ /= static_cast<double>(chin_vertices.size());
  } else {
    reference_point_in_skull_ = rest_in_skull_.rowwise().mean();
  }
}

JawPoseResult JawPoseEstimator::Estimate(const Eigen::Matrix3Xd& markers_in_skull,
                                         const std::vector<MarkerState>& states,
                                         const std::vector<double>& confidence) const {
  JawPoseResult result;
  if (!status_.ok() || !has_jaw_) return result;
  std::vector<int> used;
  for (int k = 0; k < static_cast<int>(jaw_markers_.size()); ++k) {
    const int m = jaw_markers_[k];
    if (m >= markers_in_skull.cols() || m >= static_cast<int>(states.size()) ||
        m >= static_cast<int>(confidence.size())) {
      continue;
    }
    if (states[m] != MarkerState::kMissing && confidence[m] > 0 &&
        markers_in_skull.col(m).allFinite()) {
      used.push_back(k);
    }
  }
  result.markers_used = static_cast<int>(used.size());
  if (result.markers_used < options_.min_markers) return result;
  const int n = result.markers_used;
  const Eigen::Vector3d& c = jaw_.pivot_in_skull;
  const Eigen::Vector3d& a = jaw_.axis_in_skull;
  Eigen::Matrix3Xd s(3, n), d(3, n);
  Eigen::VectorXd base(n);
  for (int i = 0; i < n; ++i) {
    const int m = jaw_markers_[used[i]];
    s.col(i) = rest_in_skull_.col(used[i]) - c;
    d.col(i) = markers_in_skull.col(m) - c;
    base[i] = prior_weights_[used[i]] * confidence[m];
  }
  // Parameters x = (theta, omega, t, d1, d2); those switched off stay zero. Each deflection
  // term needs markers to spare, or it absorbs the rotation and the noise: with few markers
  // visible the model falls back to fewer terms.
  constexpr int kMarkersPerDeflectionTerm = 6;
  constexpr int kParams = 13;
  std::array<bool, kParams> active{};
  active[0] = true;
  for (int k = 0; k < 3; ++k) {
    active[1 + k] = options_.extra_rotation_prior_rad > 0;
    active[4 + k] = options_.translation_prior_mm > 0;
    active[7 + k] = options_.deflection_terms >= 1 && n >= kMarkersPerDeflectionTerm;
    active[10 + k] = options_.deflection_terms >= 2 && n >= 2 * kMarkersPerDeflectionTerm;
  }
  double theta = 0.0;
  Eigen::Matrix3d extra_rotation = Eigen::Matrix3d::Identity();  // R(omega)
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d d1 = Eigen::Vector3d::Zero(), d2 = Eigen::Vector3d::Zero();
  Eigen::VectorXd weights = base;
  Eigen::Matrix3Xd residual(3, n);
  auto update_residuals = [&] {
    const Eigen::Matrix3d rotation =
        extra_rotation * Eigen::AngleAxisd(theta, a).toRotationMatrix();
    residual = (rotation * s).colwise() + t - d;
    for (int i = 0; i < n; ++i) {
      const int k = used[i];
      residual.col(i) += profile_t2_[k] * d1 + profile_t4_[k] * d2;
    }
  };
  // One Gauss-Newton step on the weighted energy (see the header); returns |step|.
  auto gauss_newton_step = [&] {
    update_residuals();
    Eigen::Matrix<double, kParams, kParams> h = Eigen::Matrix<double, kParams, kParams>::Zero();
    Eigen::Matrix<double, kParams, 1> g = Eigen::Matrix<double, kParams, 1>::Zero();
    const Eigen::Matrix3d hinge = Eigen::AngleAxisd(theta, a).toRotationMatrix();
    Eigen::Matrix<double, 3, kParams> j;
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d u = hinge * s.col(i);
      j.col(0) = extra_rotation * a.cross(u);
      j.block<3, 3>(0, 1) = -Skew(extra_rotation * u);
      j.block<3, 3>(0, 4) = Eigen::Matrix3d::Identity();
      j.block<3, 3>(0, 7) = profile_t2_[used[i]];
      j.block<3, 3>(0, 10) = profile_t4_[used[i]];
      h += weights[i] * j.transpose() * j;
      g += weights[i] * j.transpose() * residual.col(i);
    }
    // Each prior costs as much as one marker of mean weight 1 mm off when the extra motion
    // equals its sigma, whatever the number of markers (see the header). The deflections get
    // a negligible ridge only, so a degenerate layout (equal thicknesses) stays solvable.
    const double scale = weights.sum() / n;
    const Eigen::Vector3d omega = LogSo3(extra_rotation);
    auto add_prior = [&](int first, double lambda, const Eigen::Vector3d& value) {
      for (int k = 0; k < 3; ++k) {
        h(first + k, first + k) += lambda;
        g[first + k] += lambda * value[k];
      }
    };
    if (active[1]) add_prior(1, scale / std::pow(options_.extra_rotation_prior_rad, 2), omega);
    if (active[4]) add_prior(4, scale / std::pow(options_.translation_prior_mm, 2), t);
    if (active[7]) add_prior(7, 1e-6 * scale, d1);
    if (active[10]) add_prior(10, 1e-6 * scale, d2);
    for (int p = 0; p < kParams; ++p) {
      if (active[p]) continue;
      h.row(p).setZero();
      h.col(p).setZero();
      h(p, p) = 1.0;
      g[p] = 0.0;
    }
    const Eigen::Matrix<double, kParams, 1> delta = -h.ldlt().solve(g);
    if (!delta.allFinite()) return 0.0;
    theta += delta[0];
    extra_rotation = ExpSo3(delta.segment<3>(1)) * extra_rotation;
    t += delta.segment<3>(4);
    d1 += delta.segment<3>(7);
    d2 += delta.segment<3>(10);
    return delta.norm();
  };
  const bool pure_hinge = std::count(active.begin(), active.end(), true) == 1;
  theta = HingeAngleClosedForm(a, s, d, weights);
  for (int iteration = 0; iteration < options_.iterations; ++iteration) {
    update_residuals();
    for (int i = 0; i < n; ++i) {
      const double e = residual.col(i).norm();
      weights[i] = base[i] * (e > options_.huber_mm ? options_.huber_mm / e : 1.0);
    }
    double step = 0.0;
    if (pure_hinge) {
      const double next = HingeAngleClosedForm(a, s, d, weights);
      step = std::abs(next - theta);
      theta = next;
    } else {
      // Linear in t and the deflections, nearly so in the angles: two steps per reweighting.
      step = gauss_newton_step();
      step += gauss_newton_step();
    }
    if (iteration > 1 && step < 1e-12) break;
  }
  update_residuals();
  const Eigen::Matrix3d rotation = extra_rotation * Eigen::AngleAxisd(theta, a).toRotationMatrix();
  // q = c + t + R (r - c) = R r + (c + t - R c).
  result.skull_from_jaw = Rigid3(Eigen::Quaterniond(rotation), c + t - rotation * c);
  result.angle_rad = JawHingeAngleRad(jaw_, result.skull_from_jaw);
  result.deflection_t2_mm = d1;
  result.deflection_t4_mm = d2;
  double sq = 0.0;
  for (int i = 0; i < n; ++i) sq += weights[i] * residual.col(i).squaredNorm();
  result.rms_mm = std::sqrt(sq / weights.sum());
  result.ok = std::isfinite(result.angle_rad) && std::isfinite(result.rms_mm);
  if (!result.ok) result.skull_from_jaw = Rigid3();
  return result;
}

JawPoseResult JawPoseEstimator::Estimate(const TrackedFrame& frame,
                                         const Rigid3& world_from_skull) const {
  return Estimate(world_from_skull.Inverse().Apply(frame.positions_in_world), frame.states,
                  frame.confidence);
}

JawSequence EstimateJawSequence(const JawPoseEstimator& estimator,
                                const std::vector<TrackedFrame>& tracked,
                                const std::vector<Rigid3>& world_from_skull) {
  FACEDYN_CHECK(tracked.size() == world_from_skull.size(), "one skull pose per tracked frame");
  JawSequence out;
  Rigid3 last;  // identity: the closed-mouth rest pose, until a frame has an estimate
  int last_frame = -1;
  for (size_t f = 0; f < tracked.size(); ++f) {
    JawPoseResult result = estimator.Estimate(tracked[f], world_from_skull[f]);
    if (result.ok) {
      last = result.skull_from_jaw;
      last_frame = static_cast<int>(f);
    }
    out.skull_from_jaw.push_back(last);
    out.carried.push_back(!result.ok);
    out.carried_from.push_back(last_frame);
    out.results.push_back(result);
  }
  return out;
}

JawPoseDifference CompareJawPoses(const JawModel& jaw, const Eigen::Vector3d& point_in_skull,
                                  const Rigid3& estimate, const Rigid3& reference) {
  JawPoseDifference out;
  double angle = JawHingeAngleRad(jaw, estimate) - JawHingeAngleRad(jaw, reference);
  if (angle > M_PI) angle -= 2.0 * M_PI;
  if (angle <= -M_PI) angle += 2.0 * M_PI;
  out.angle_rad = angle;
  out.pivot_mm = (estimate * jaw.pivot_in_skull - reference * jaw.pivot_in_skull).norm();
  out.point_mm = (estimate * point_in_skull - reference * point_in_skull).norm();
  return out;
}

}  // namespace facedyn::reconstruct
