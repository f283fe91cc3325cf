#include "physics/twin_targeting.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <utility>

#include "physics/skull_kinematics.h"
#include "physics/twin.h"

namespace facedyn::physics {
namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

int JawOpenShape(const FaceRig& rig) {
  const int k = rig.BlendshapeIndex("jaw_open");
  return k >= 0 ? k : rig.BlendshapeIndex("jawOpen");
}

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// One fit's unknowns: the weights and, with alignment, a rigid correction of the skull frame
// about the observation's centroid c: a point x of the model is seen at R (x - c) + c + t.
struct FitState {
  Eigen::VectorXd weights;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
};

// The model at a state against the observation: residual, cost and, with the Jacobian,
// d residual / d(weights) and d residual / d(rotation increment, translation).
struct Evaluation {
  Eigen::VectorXd residual;
  Eigen::MatrixXd jacobian_weights;  // 3n x K, empty without
  Eigen::MatrixXd jacobian_rigid;    // 3n x 6, empty without
  double cost = 0.0;                 // 1/2 |residual|^2, or the robust cost
  Eigen::VectorXd row_weight;        // per residual row: sqrt of its marker's IRLS weight
  double flesh_volume_mm3 = 0.0;     // the twin's only
};

class Targeter {
 public:
  Targeter(SoftTissueModel& model, const FaceRig& rig, const std::vector<int>& vertices,
           const Eigen::Matrix3Xd& observed, const Eigen::Vector3d& gravity_change,
           double robust_scale_mm)
      : model_(model),
        rig_(rig),
        vertices_(vertices),
        observed_(observed),
        centroid_(observed.rowwise().mean()),
        gravity_change_(gravity_change),
        jaw_open_(JawOpenShape(rig)),
        jaw_open_rad_(FittedJawOpenAngleRad(rig)),
        robust_scale_mm_(robust_scale_mm),
        neutral_volume_mm3_(model.FleshVolumeMm3(model.NodeTargets(
            Eigen::VectorXd::Zero(static_cast<int>(rig.blendshape_deltas_mm.size())), 0.0))) {}

  double JawOf(const Eigen::VectorXd& w) const {
    return jaw_open_ >= 0 ? w[jaw_open_] * jaw_open_rad_ : 0.0;
  }

  // `sag`: the twin's held equilibrium; otherwise the blendshape skin (no model needed).
  StatusOr<Evaluation> Evaluate(const FitState& state, bool sag, bool with_jacobian) const {
    const int n = static_cast<int>(vertices_.size());
    const int shapes = static_cast<int>(state.weights.size());
    Eigen::VectorXd skin(3 * n);
    Eigen::MatrixXd jacobian;
    Evaluation e;
    if (sag) {
      FACEDYN_RETURN_IF_ERROR(
          model_.SetStaticReference(state.weights, JawOf(state.weights)).status());
      FACEDYN_ASSIGN_OR_RETURN(
          HeldExpressionSkin held,
          model_.HeldSkinWithJacobian(gravity_change_, vertices_, with_jacobian));
      skin = std::move(held.skin_mm);
      e.flesh_volume_mm3 = held.flesh_volume_mm3;
      if (with_jacobian) {
        jacobian = held.jacobian.leftCols(shapes);
        if (jaw_open_ >= 0) jacobian.col(jaw_open_) += jaw_open_rad_ * held.jacobian.col(shapes);
      }
    } else {
      if (with_jacobian) jacobian.resize(3 * n, shapes);
      for (int i = 0; i < n; ++i) {
        const int v = vertices_[i];
        Eigen::Vector3d x = rig_.neutral.positions_mm.col(v);
        for (int k = 0; k < shapes; ++k) {
          x += state.weights[k] * rig_.blendshape_deltas_mm[k].col(v);
          if (with_jacobian) jacobian.block<3, 1>(3 * i, k) = rig_.blendshape_deltas_mm[k].col(v);
        }
        skin.segment<3>(3 * i) = x;
      }
    }
    e.residual.resize(3 * n);
    if (with_jacobian) {
      e.jacobian_weights.resize(3 * n, shapes);
      e.jacobian_rigid.resize(3 * n, 6);
    }
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d arm = state.rotation * (skin.segment<3>(3 * i) - centroid_);
      e.residual.segment<3>(3 * i) = arm + centroid_ + state.translation - observed_.col(i);
      if (with_jacobian) {
        e.jacobian_weights.middleRows<3>(3 * i) = state.rotation * jacobian.middleRows<3>(3 * i);
        e.jacobian_rigid.block<3, 3>(3 * i, 0) = -Skew(arm);  // R <- exp([d]x) R
        e.jacobian_rigid.block<3, 3>(3 * i, 3).setIdentity();
      }
    }
    e.cost = 0;
    e.row_weight.resize(3 * n);
    for (int i = 0; i < n; ++i) {
      const double squared = e.residual.segment<3>(3 * i).squaredNorm();
      if (robust_scale_mm_ > 0) {
        // Cauchy: rho(s) = c^2/2 ln(1 + s/c^2); its IRLS weight 1 / (1 + s/c^2).
        const double c2 = robust_scale_mm_ * robust_scale_mm_;
        e.cost += 0.5 * c2 * std::log1p(squared / c2);
        e.row_weight.segment<3>(3 * i).setConstant(std::sqrt(1.0 / (1.0 + squared / c2)));
      } else {
        e.cost += 0.5 * squared;
        e.row_weight.segment<3>(3 * i).setOnes();
      }
    }
    return e;
  }

  // Projected Gauss-Newton from `state`: each step solves the linearised problem with the
  // weights in their box exactly (UnitBoxLeastSquares; with alignment the rigid increment is
  // eliminated first by projecting onto the complement of its columns, which it enters
  // unbounded), and is halved until the cost decreases, so the cost never rises.
  Status Run(FitState* state, bool sag, bool align, const TargetingOptions& options,
             ExpressionTargetingFit* fit) const {
    FACEDYN_ASSIGN_OR_RETURN(Evaluation current, Evaluate(*state, sag, true));
    fit->cost_history = {current.cost};
    fit->termination = "reached max_iterations";
    for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
      // With a robust loss, each marker's rows weighted by its IRLS weight at the current point.
      const Eigen::VectorXd& sqrt_w = current.row_weight;
      const Eigen::MatrixXd jacobian_weights = sqrt_w.asDiagonal() * current.jacobian_weights;
      const Eigen::VectorXd residual = sqrt_w.cwiseProduct(current.residual);
      Eigen::MatrixXd a = jacobian_weights;
      Eigen::VectorXd b = a * state->weights - residual;
      Eigen::HouseholderQR<Eigen::MatrixXd> rigid_qr;
      Eigen::MatrixXd q;
      if (align) {
        rigid_qr.compute(sqrt_w.asDiagonal() * current.jacobian_rigid);
        q = rigid_qr.householderQ() * Eigen::MatrixXd::Identity(a.rows(), 6);
        a -= q * (q.transpose() * a);
        b -= q * (q.transpose() * b);
      }
      FACEDYN_ASSIGN_OR_RETURN(const Eigen::VectorXd target,
                               UnitBoxLeastSquares(a, b, state->weights));
      const Eigen::VectorXd step = target - state->weights;
      Eigen::VectorXd rigid_step = Eigen::VectorXd::Zero(6);
      if (align) {
        rigid_step = -rigid_qr.solve(Eigen::VectorXd(jacobian_weights * step + residual));
      }
      bool accepted = false;
      for (double scale = 1.0; scale > 1.0 / 64 && !accepted; scale /= 2) {
        FitState trial = *state;
        trial.weights += scale * step;
        if (align) {
          const Eigen::Vector3d angle = scale * rigid_step.head<3>();
          if (angle.norm() > 0)
            trial.rotation =
                Eigen::AngleAxisd(angle.norm(), angle.normalized()).toRotationMatrix() *
                state->rotation;
          trial.translation += scale * rigid_step.tail<3>();
        }
        FACEDYN_ASSIGN_OR_RETURN(Evaluation candidate, Evaluate(trial, sag, true));
        if (candidate.cost < current.cost) {
          const double decrease = (current.cost - candidate.cost) / current.cost;
          const double moved = (scale * step).cwiseAbs().maxCoeff();
          *state = std::move(trial);
          current = std::move(candidate);
          accepted = true;
          fit->cost_history.push_back(current.cost);
          if (decrease < options.function_tolerance || moved < options.parameter_tolerance) {
            fit->termination = fmt::format(
                "converged: the last step lowered the cost by {:.2e} of itself and moved no "
                "weight by more than {:.2e}",
                decrease, moved);
            iteration = options.max_iterations;
          }
        }
      }
      if (!accepted) {
        fit->termination = "converged: no step along the Gauss-Newton direction lowers the cost";
        break;
      }
    }
    fit->iterations = static_cast<int>(fit->cost_history.size()) - 1;
    // The model is left at the last evaluation; put it back at the solution.
    FACEDYN_ASSIGN_OR_RETURN(const Evaluation final_state, Evaluate(*state, sag, false));
    fit->weights = state->weights;
    fit->jaw_angle_rad = JawOf(state->weights);
    fit->rms_mm = std::sqrt(final_state.residual.squaredNorm() / vertices_.size());
    fit->marker_distance_mm = MarkerDistances(final_state.residual);
    fit->outlier_markers = 0;
    if (robust_scale_mm_ > 0) {
      for (size_t i = 0; i < vertices_.size(); ++i)
        fit->outlier_markers +=
            final_state.residual.segment<3>(3 * i).norm() > 3 * robust_scale_mm_;
    }
    fit->skull_rotation_deg = Eigen::AngleAxisd(state->rotation).angle() * 180 / M_PI;
    fit->skull_translation_mm = state->translation.norm();
    if (sag) fit->flesh_volume_change = final_state.flesh_volume_mm3 / NeutralVolume() - 1;
    return Status::Ok();
  }

  static Eigen::VectorXd MarkerDistances(const Eigen::VectorXd& residual) {
    Eigen::VectorXd distance(residual.size() / 3);
    for (Eigen::Index i = 0; i < distance.size(); ++i)
      distance[i] = residual.segment<3>(3 * i).norm();
    return distance;
  }

  // The flesh volume of the neutral's targets, against which both fits' change is reported.
  double NeutralVolume() const { return neutral_volume_mm3_; }

 private:
  SoftTissueModel& model_;
  const FaceRig& rig_;
  const std::vector<int>& vertices_;
  const Eigen::Matrix3Xd& observed_;
  const Eigen::Vector3d centroid_;
  const Eigen::Vector3d gravity_change_;
  const int jaw_open_;
  const double jaw_open_rad_;
  const double robust_scale_mm_;  // 0: least squares
  const double neutral_volume_mm3_;
};

}  // namespace

StatusOr<ExpressionTargeting> TargetHeldExpression(SoftTissueModel& model, const FaceRig& rig,
                                                   const std::vector<int>& vertices,
                                                   const Eigen::Matrix3Xd& positions_in_skull,
                                                   const Eigen::Vector3d& gravity_change_in_skull,
                                                   const TargetingOptions& options) {
  if (!gravity_change_in_skull.allFinite()) {
    return InvalidArgumentError("twin targeting: the gravity change is not finite");
  }
  if (!(options.robust_scale_mm >= 0) || !std::isfinite(options.robust_scale_mm)) {
    return InvalidArgumentError(
        fmt::format("twin targeting: robust_scale_mm must be >= 0 (0: least squares), got {}",
                    options.robust_scale_mm));
  }
  if (options.max_iterations < 1 || !(options.function_tolerance > 0) ||
      !(options.parameter_tolerance > 0)) {
    return InvalidArgumentError(fmt::format(
        "twin targeting: max_iterations must be >= 1 and the tolerances > 0, got {}, {} and {}",
        options.max_iterations, options.function_tolerance, options.parameter_tolerance));
  }
  const int shapes = static_cast<int>(rig.blendshape_deltas_mm.size());
  if (model.blendshape_count() != shapes || model.skin_vertex_count() != rig.vertex_count()) {
    return FailedPreconditionError(fmt::format(
        "twin targeting: the tissue model has {} blendshapes and {} skin vertices, face rig '{}' "
        "{} and {}",
        model.blendshape_count(), model.skin_vertex_count(), rig.name, shapes, rig.vertex_count()));
  }
  // The plain blendshape fit checks the sizes, the vertices and the positions.
  ExpressionTargeting result;
  auto start = Clock::now();
  FACEDYN_ASSIGN_OR_RETURN(const BlendshapeFit plain,
                           FitBlendshapeWeights(rig, vertices, positions_in_skull));
  const Targeter targeter(model, rig, vertices, positions_in_skull, gravity_change_in_skull,
                          options.robust_scale_mm);
  FitState state;
  state.weights = plain.weights;
  if (options.align_skull || options.robust_scale_mm > 0) {
    FACEDYN_RETURN_IF_ERROR(
        targeter.Run(&state, false, options.align_skull, options, &result.blendshape));
  } else {
    result.blendshape.weights = plain.weights;
    result.blendshape.jaw_angle_rad = targeter.JawOf(plain.weights);
    result.blendshape.rms_mm = plain.rms_mm;
    FACEDYN_ASSIGN_OR_RETURN(const Evaluation at_plain, targeter.Evaluate(state, false, false));
    result.blendshape.marker_distance_mm = Targeter::MarkerDistances(at_plain.residual);
  }
  // The blendshape fit's flesh is its targets (no sag).
  result.blendshape.flesh_volume_change =
      model.FleshVolumeMm3(
          model.NodeTargets(result.blendshape.weights, result.blendshape.jaw_angle_rad)) /
          targeter.NeutralVolume() -
      1;
  result.blendshape.seconds = Seconds(start);

  // The twin, from the blendshape fit (and its alignment).
  start = Clock::now();
  FACEDYN_RETURN_IF_ERROR(targeter.Run(&state, true, options.align_skull, options, &result.twin));
  result.twin.seconds = Seconds(start);

  // Both fits' residual on the markers neither treats as a gross error.
  const Eigen::Index n = result.twin.marker_distance_mm.size();
  const double inlier_mm = options.robust_scale_mm > 0 ? 3 * options.robust_scale_mm
                                                       : std::numeric_limits<double>::infinity();
  double plain_sq = 0.0, twin_sq = 0.0;
  int inliers = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double a = result.blendshape.marker_distance_mm[i];
    const double b = result.twin.marker_distance_mm[i];
    if (a > inlier_mm || b > inlier_mm) continue;
    plain_sq += a * a;
    twin_sq += b * b;
    ++inliers;
  }
  for (ExpressionTargetingFit* fit : {&result.blendshape, &result.twin}) {
    fit->common_inlier_markers = inliers;
    fit->common_inlier_rms_mm =
        std::sqrt((fit == &result.twin ? twin_sq : plain_sq) / std::max(inliers, 1));
  }
  return result;
}

StatusOr<HeldWindow> MeanHeldWindow(const Take& take, const std::vector<int>& vertices, int first,
                                    int end) {
  if (first < 0 || end > take.frame_count() || first >= end) {
    return InvalidArgumentError(fmt::format("held window: frames [{}, {}) of a take with {} frames",
                                            first, end, take.frame_count()));
  }
  if (static_cast<int>(take.world_from_skull.size()) != take.frame_count()) {
    return FailedPreconditionError("held window: the take has no skull pose per frame");
  }
  for (int v : vertices) {
    if (v < 0 || v >= take.vertex_count()) {
      return InvalidArgumentError(fmt::format(
          "held window: vertex {} is not on the take's {} vertices", v, take.vertex_count()));
    }
  }
  HeldWindow window;
  window.frames = end - first;
  window.positions_in_skull.setZero(3, vertices.size());
  const double share = 1.0 / window.frames;
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();
  for (int f = first; f < end; ++f) {
    const Rigid3 skull_from_world = take.world_from_skull[f].Inverse();
    const auto frame = take.positions.Frame(f);
    for (size_t i = 0; i < vertices.size(); ++i) {
      window.positions_in_skull.col(i) +=
          share * (skull_from_world * Eigen::Vector3d(frame.col(vertices[i]).cast<double>()));
    }
    gravity += share * (skull_from_world.rotation() * kGravityInWorld);
  }
  window.gravity_change_in_skull = gravity - kGravityInWorld;
  return window;
}

}  // namespace facedyn::physics
