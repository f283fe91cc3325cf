#include "physics/twin_targeting.h"

#include <ceres/ceres.h>
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

// Residual of the twin fit: the held equilibrium skin at `vertices` minus the observation. Every
// evaluation re-linearises the flesh about the candidate expression (SetReference), whose jaw
// follows the jaw-opening weight.
class HeldSkinResidual : public ceres::CostFunction {
 public:
  HeldSkinResidual(SoftTissueModel* model, const std::vector<int>* vertices,
                   Eigen::VectorXd observed, const Eigen::Vector3d& gravity_change, int shapes,
                   int jaw_open, double jaw_open_rad)
      : model_(model),
        vertices_(vertices),
        observed_(std::move(observed)),
        gravity_change_(gravity_change),
        jaw_open_(jaw_open),
        jaw_open_rad_(jaw_open_rad) {
    set_num_residuals(static_cast<int>(observed_.size()));
    mutable_parameter_block_sizes()->assign(1, shapes);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int shapes = parameter_block_sizes()[0];
    const Eigen::VectorXd w = Eigen::Map<const Eigen::VectorXd>(parameters[0], shapes);
    const double jaw = jaw_open_ >= 0 ? w[jaw_open_] * jaw_open_rad_ : 0.0;
    if (!model_->SetReference(w, jaw, model_->options().max_step_s).ok()) return false;
    auto held = model_->HeldSkinWithJacobian(gravity_change_, *vertices_);
    if (!held.ok()) return false;
    Eigen::Map<Eigen::VectorXd>(residuals, observed_.size()) = held->skin_mm - observed_;
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      Eigen::MatrixXd jacobian = held->jacobian.leftCols(shapes);
      if (jaw_open_ >= 0) jacobian.col(jaw_open_) += jaw_open_rad_ * held->jacobian.col(shapes);
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          jacobians[0], observed_.size(), shapes) = jacobian;
    }
    return true;
  }

 private:
  SoftTissueModel* model_;
  const std::vector<int>* vertices_;
  Eigen::VectorXd observed_;
  Eigen::Vector3d gravity_change_;
  int jaw_open_;
  double jaw_open_rad_;
};

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
  if (options.max_iterations < 1 || !(options.function_tolerance > 0)) {
    return InvalidArgumentError(
        fmt::format("twin targeting: max_iterations must be >= 1 and function_tolerance > 0, got "
                    "{} and {}",
                    options.max_iterations, options.function_tolerance));
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
  Eigen::VectorXd weights = plain.weights;
  ceres::Problem problem;
  problem.AddResidualBlock(
      new HeldSkinResidual(&model, &vertices, observed, gravity_change_in_skull, shapes, jaw_open,
                           jaw_open_rad),
      nullptr, weights.data());
  for (int k = 0; k < shapes; ++k) {
    problem.SetParameterLowerBound(weights.data(), k, 0.0);
    problem.SetParameterUpperBound(weights.data(), k, 1.0);
  }
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.function_tolerance = options.function_tolerance;
  solver_options.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  if (!summary.IsSolutionUsable()) return InternalError("twin targeting: " + summary.message);
  // Leave the model at the solution and read its residual and flesh there.
  result.twin.weights = weights;
  result.twin.jaw_angle_rad = jaw_of(weights);
  FACEDYN_RETURN_IF_ERROR(
      model.SetReference(weights, result.twin.jaw_angle_rad, model.options().max_step_s).status());
  FACEDYN_ASSIGN_OR_RETURN(const HeldExpressionSkin held,
                           model.HeldSkinWithJacobian(gravity_change_in_skull, vertices));
  result.twin.rms_mm = RmsDistance(held.skin_mm - observed);
  result.twin.flesh_volume_change = held.flesh_volume_mm3 / neutral_volume - 1;
  result.twin.iterations = static_cast<int>(summary.iterations.size());
  result.twin.seconds = Seconds(start);
  return result;
}

}  // namespace facedyn::physics
