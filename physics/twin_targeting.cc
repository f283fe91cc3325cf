#include "physics/twin_targeting.h"

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <utility>

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

// The held equilibrium at weights w (the jaw following the jaw-opening weight) against the
// observation: residual, cost and, with the Jacobian, d residual / dw.
struct Evaluation {
  Eigen::VectorXd residual;
  Eigen::MatrixXd jacobian;  // empty without
  double cost = 0.0;         // 1/2 |residual|^2
  double flesh_volume_mm3 = 0.0;
};

StatusOr<Evaluation> EvaluateHeld(SoftTissueModel& model, const std::vector<int>& vertices,
                                  const Eigen::VectorXd& observed, const Eigen::Vector3d& dg,
                                  const Eigen::VectorXd& w, int jaw_open, double jaw_open_rad,
                                  bool with_jacobian) {
  const double jaw = jaw_open >= 0 ? w[jaw_open] * jaw_open_rad : 0.0;
  FACEDYN_RETURN_IF_ERROR(model.SetStaticReference(w, jaw).status());
  FACEDYN_ASSIGN_OR_RETURN(const HeldExpressionSkin held,
                           model.HeldSkinWithJacobian(dg, vertices, with_jacobian));
  Evaluation e;
  e.residual = held.skin_mm - observed;
  e.cost = 0.5 * e.residual.squaredNorm();
  e.flesh_volume_mm3 = held.flesh_volume_mm3;
  if (with_jacobian) {
    const int shapes = static_cast<int>(w.size());
    e.jacobian = held.jacobian.leftCols(shapes);
    if (jaw_open >= 0) e.jacobian.col(jaw_open) += jaw_open_rad * held.jacobian.col(shapes);
  }
  return e;
}

double RmsDistance(const Eigen::VectorXd& residual) {
  return std::sqrt(residual.squaredNorm() / (residual.size() / 3));
}

}  // namespace

StatusOr<ExpressionTargeting> TargetHeldExpression(SoftTissueModel& model, const FaceRig& rig,
                                                   const std::vector<int>& vertices,
                                                   const Eigen::Matrix3Xd& positions_in_skull,
                                                   const Eigen::Vector3d& gravity_change_in_skull,
                                                   const TargetingOptions& options) {
  if (!gravity_change_in_skull.allFinite()) {
    return InvalidArgumentError("twin targeting: the gravity change is not finite");
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
  // The blendshape fit checks the sizes, the vertices and the positions.
  ExpressionTargeting result;
  auto start = Clock::now();
  FACEDYN_ASSIGN_OR_RETURN(const BlendshapeFit plain,
                           FitBlendshapeWeights(rig, vertices, positions_in_skull));
  const int jaw_open = JawOpenShape(rig);
  const double jaw_open_rad = FittedJawOpenAngleRad(rig);
  const auto jaw_of = [&](const Eigen::VectorXd& w) {
    return jaw_open >= 0 ? w[jaw_open] * jaw_open_rad : 0.0;
  };
  const double neutral_volume =
      model.FleshVolumeMm3(model.NodeTargets(Eigen::VectorXd::Zero(shapes), 0.0));
  result.blendshape.weights = plain.weights;
  result.blendshape.jaw_angle_rad = jaw_of(plain.weights);
  result.blendshape.rms_mm = plain.rms_mm;
  result.blendshape.flesh_volume_change =
      model.FleshVolumeMm3(model.NodeTargets(plain.weights, result.blendshape.jaw_angle_rad)) /
          neutral_volume -
      1;
  result.blendshape.seconds = Seconds(start);

  start = Clock::now();
  const Eigen::VectorXd observed =
      Eigen::Map<const Eigen::VectorXd>(positions_in_skull.data(), positions_in_skull.size());
  // Projected Gauss-Newton with backtracking: each step solves the linearised problem within
  // the weights' box exactly (UnitBoxLeastSquares), and is halved until the cost decreases, so
  // the cost never rises. The sag depends weakly on the expression, so from the blendshape fit
  // a few steps suffice.
  Eigen::VectorXd weights = plain.weights;
  FACEDYN_ASSIGN_OR_RETURN(Evaluation current,
                           EvaluateHeld(model, vertices, observed, gravity_change_in_skull, weights,
                                        jaw_open, jaw_open_rad, true));
  result.twin.cost_history.push_back(current.cost);
  result.twin.termination = "reached max_iterations";
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    FACEDYN_ASSIGN_OR_RETURN(
        const Eigen::VectorXd target,
        UnitBoxLeastSquares(current.jacobian, current.jacobian * weights - current.residual,
                            weights));
    const Eigen::VectorXd step = target - weights;
    bool accepted = false;
    for (double scale = 1.0; scale > 1.0 / 64 && !accepted; scale /= 2) {
      const Eigen::VectorXd trial = weights + scale * step;
      FACEDYN_ASSIGN_OR_RETURN(Evaluation candidate,
                               EvaluateHeld(model, vertices, observed, gravity_change_in_skull,
                                            trial, jaw_open, jaw_open_rad, true));
      if (candidate.cost < current.cost) {
        const double decrease = (current.cost - candidate.cost) / current.cost;
        weights = trial;
        current = std::move(candidate);
        accepted = true;
        result.twin.cost_history.push_back(current.cost);
        const double moved = (scale * step).cwiseAbs().maxCoeff();
        if (decrease < options.function_tolerance || moved < options.parameter_tolerance) {
          result.twin.termination = fmt::format(
              "converged: the last step lowered the cost by {:.2e} of itself and moved no weight "
              "by more than {:.2e}",
              decrease, moved);
          iteration = options.max_iterations;
        }
      }
    }
    if (!accepted) {
      result.twin.termination =
          "converged: no step along the Gauss-Newton direction lowers the cost";
      break;
    }
  }
  result.twin.iterations = static_cast<int>(result.twin.cost_history.size()) - 1;
  // The model is left at the last evaluation; put it back at the solution.
  result.twin.weights = weights;
  result.twin.jaw_angle_rad = jaw_of(weights);
  FACEDYN_ASSIGN_OR_RETURN(const Evaluation final_state,
                           EvaluateHeld(model, vertices, observed, gravity_change_in_skull, weights,
                                        jaw_open, jaw_open_rad, false));
  result.twin.rms_mm = RmsDistance(final_state.residual);
  result.twin.flesh_volume_change = final_state.flesh_volume_mm3 / neutral_volume - 1;
  result.twin.seconds = Seconds(start);
  return result;
}

}  // namespace facedyn::physics
