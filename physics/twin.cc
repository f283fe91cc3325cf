#include "physics/twin.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <set>

#include "core/config_node.h"
#include "core/progress.h"
#include "physics/face_anatomy.h"
#include "physics/harmonic_response.h"

namespace facedyn::physics {
namespace {

// Residual of the blendshape fit: skin(w) - observed at the vertices, linear in w.
class BlendshapeResidual : public ceres::CostFunction {
 public:
  BlendshapeResidual(Eigen::MatrixXd basis, Eigen::VectorXd offset)
      : basis_(std::move(basis)), offset_(std::move(offset)) {
    set_num_residuals(static_cast<int>(basis_.rows()));
    mutable_parameter_block_sizes()->assign(1, static_cast<int>(basis_.cols()));
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const Eigen::Map<const Eigen::VectorXd> w(parameters[0], basis_.cols());
    Eigen::Map<Eigen::VectorXd>(residuals, basis_.rows()) = basis_ * w - offset_;
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          jacobians[0], basis_.rows(), basis_.cols()) = basis_;
    }
    return true;
  }

 private:
  Eigen::MatrixXd basis_;   // 3n x K: the shapes' deltas at the vertices
  Eigen::VectorXd offset_;  // 3n: observed minus neutral
};

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}
}  // namespace

std::vector<int> TwinMarkerVertices(const FaceRig& rig) {
  std::vector<int> vertices;
  std::set<int> seen;
  for (const Marker& marker : rig.markers) {
    int best = 0;
    for (int i = 1; i < 3; ++i) {
      if (marker.point.weights[i] > marker.point.weights[best]) best = i;
    }
    const int v = marker.point.vertices[best];
    if (seen.insert(v).second) vertices.push_back(v);
  }
  return vertices;
}

StatusOr<Eigen::VectorXd> UnitBoxLeastSquares(const Eigen::MatrixXd& a, const Eigen::VectorXd& b,
                                              const Eigen::VectorXd& start) {
  if (a.rows() != b.size() || a.cols() != start.size() || a.cols() == 0) {
    return InvalidArgumentError(
        fmt::format("bounded least squares: a {}x{} system, {} values and {} unknowns", a.rows(),
                    a.cols(), b.size(), start.size()));
  }
  if (!a.allFinite() || !b.allFinite())
    return InvalidArgumentError("bounded least squares: non-finite input");
  Eigen::VectorXd x = start.cwiseMax(0.0).cwiseMin(1.0);
  ceres::Problem problem;
  problem.AddResidualBlock(new BlendshapeResidual(a, b), nullptr, x.data());
  for (int j = 0; j < x.size(); ++j) {
    problem.SetParameterLowerBound(x.data(), j, 0.0);
    problem.SetParameterUpperBound(x.data(), j, 1.0);
  }
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solver_options.max_num_iterations = 100;
  solver_options.function_tolerance = 1e-12;
  solver_options.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  if (!summary.IsSolutionUsable())
    return InternalError("bounded least squares: " + summary.message);
  return x;
}

StatusOr<BlendshapeFit> FitBlendshapeWeights(const FaceRig& rig, const std::vector<int>& vertices,
                                             const Eigen::Matrix3Xd& positions_in_skull) {
  const int k = static_cast<int>(rig.blendshape_deltas_mm.size());
  if (k == 0)
    return FailedPreconditionError(
        fmt::format("face rig '{}' has no blendshapes to fit", rig.name));
  if (positions_in_skull.cols() != static_cast<Eigen::Index>(vertices.size()) || vertices.empty()) {
    return InvalidArgumentError(fmt::format("blendshape fit: {} positions for {} vertices",
                                            positions_in_skull.cols(), vertices.size()));
  }
  const int n = static_cast<int>(vertices.size());
  Eigen::MatrixXd basis(3 * n, k);
  Eigen::VectorXd offset(3 * n);
  for (int i = 0; i < n; ++i) {
    const int v = vertices[i];
    if (v < 0 || v >= rig.vertex_count()) {
      return InvalidArgumentError(fmt::format(
          "blendshape fit: vertex {} is not on the rig's {} vertices", v, rig.vertex_count()));
    }
    for (int j = 0; j < k; ++j) basis.block<3, 1>(3 * i, j) = rig.blendshape_deltas_mm[j].col(v);
    offset.segment<3>(3 * i) = positions_in_skull.col(i) - rig.neutral.positions_mm.col(v);
  }
  if (!offset.allFinite()) return InvalidArgumentError("blendshape fit: non-finite positions");
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::VectorXd weights,
                           UnitBoxLeastSquares(basis, offset, Eigen::VectorXd::Zero(k)));
  BlendshapeFit fit;
  fit.weights = weights;
  fit.rms_mm = std::sqrt((basis * weights - offset).squaredNorm() / n);
  return fit;
}

double FittedJawOpenAngleRad(const FaceRig& rig) {
  int k = rig.BlendshapeIndex("jaw_open");
  if (k < 0) k = rig.BlendshapeIndex("jawOpen");
  if (k < 0) return 0.0;
  const std::vector<int> vertices = JawFitVertices(rig);
  if (vertices.size() < 3) return 0.0;
  Eigen::Matrix3Xd points(3, vertices.size()), deltas(3, vertices.size());
  for (size_t i = 0; i < vertices.size(); ++i) {
    points.col(i) = rig.neutral.positions_mm.col(vertices[i]);
    deltas.col(i) = rig.blendshape_deltas_mm[k].col(vertices[i]);
  }
  return FitHingeAngleRad(points, deltas, rig.jaw.axis_in_skull.normalized(),
                          rig.jaw.pivot_in_skull);
}

double FittedJawAngleRad(const FaceRig& rig, const Eigen::VectorXd& weights) {
  int k = rig.BlendshapeIndex("jaw_open");
  if (k < 0) k = rig.BlendshapeIndex("jawOpen");
  if (k < 0 || k >= weights.size() || weights[k] == 0.0) return 0.0;
  return weights[k] * FittedJawOpenAngleRad(rig);
}

std::vector<StiffnessGroup> DefaultStiffnessGroups() {
  return {{"cheeks", {"cheeks", "mouth_corners"}},
          {"mouth", {"upper_lip", "lower_lip", "chin"}},
          {"rest", {}}};
}

StatusOr<Eigen::VectorXi> TetStiffnessGroups(const FaceRig& rig, const TetShell& shell,
                                             const std::vector<StiffnessGroup>& groups) {
  if (groups.empty()) return InvalidArgumentError("stiffness groups: none given");
  std::vector<int> vertex_group(rig.vertex_count(), -1);
  int catch_all = -1;
  for (size_t g = 0; g < groups.size(); ++g) {
    if (groups[g].regions.empty()) {
      if (catch_all >= 0) {
        return InvalidArgumentError(
            fmt::format("stiffness groups '{}' and '{}' both have no regions; only one may",
                        groups[catch_all].name, groups[g].name));
      }
      catch_all = static_cast<int>(g);
      continue;
    }
    for (const std::string& region : groups[g].regions) {
      const auto found = rig.regions.find(region);
      if (found == rig.regions.end()) {
        return InvalidArgumentError(
            fmt::format("stiffness group '{}': face rig '{}' has no region '{}'", groups[g].name,
                        rig.name, region));
      }
      for (int v : found->second) {
        if (vertex_group[v] >= 0 && vertex_group[v] != static_cast<int>(g)) {
          return InvalidArgumentError(
              fmt::format("stiffness groups '{}' and '{}' share region vertices ('{}')",
                          groups[vertex_group[v]].name, groups[g].name, region));
        }
        vertex_group[v] = static_cast<int>(g);
      }
    }
  }
  Eigen::VectorXi tet_group(shell.tets.cols());
  std::vector<int> counts(groups.size(), 0);
  for (int e = 0; e < shell.tets.cols(); ++e) {
    int g = vertex_group[shell.tet_surface_vertex[e]];
    if (g < 0) g = catch_all;
    if (g < 0) {
      return InvalidArgumentError(
          fmt::format("stiffness groups: skin vertex {} is in no group's regions; add a group "
                      "without regions for the rest",
                      shell.tet_surface_vertex[e]));
    }
    tet_group[e] = g;
    ++counts[g];
  }
  for (size_t g = 0; g < groups.size(); ++g) {
    if (counts[g] == 0)
      return InvalidArgumentError(
          fmt::format("stiffness group '{}' has no tissue", groups[g].name));
  }
  return tet_group;
}

Status TwinFitOptions::Check() const {
  FACEDYN_RETURN_IF_ERROR(prior.Check());
  FACEDYN_RETURN_IF_ERROR(fit.Check());
  if (!(same_expression_tolerance >= 0 && same_expression_tolerance < 1)) {
    return InvalidArgumentError("twin fit: same_expression_tolerance must be in [0, 1)");
  }
  if (!(platform_amplitude_mm >= 0 && platform_amplitude_mm <= 50)) {
    return InvalidArgumentError(
        fmt::format("twin fit: platform amplitude {} mm is not in [0, 50] (0: not known)",
                    platform_amplitude_mm));
  }
  return Status::Ok();
}

StatusOr<FittedTwin> FitTwin(const FaceRig& rig,
                             const std::vector<std::pair<std::string, const Take*>>& takes,
                             const TwinFitOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  FACEDYN_RETURN_IF_ERROR(options.Check());
  if (takes.empty()) return InvalidArgumentError("twin fit: no platform takes");
  // Every take is checked before the model is built (seconds on a face).
  for (const auto& [name, take] : takes) {
    if (take == nullptr) return InvalidArgumentError(fmt::format("twin fit: {} is missing", name));
    if (!take->info.platform_hz || !(*take->info.platform_hz > 0)) {
      return InvalidArgumentError(
          fmt::format("twin fit: {} has no platform frequency (platform_hz); only platform "
                      "takes identify the material",
                      name));
    }
    if (take->vertex_count() != rig.vertex_count()) {
      return InvalidArgumentError(fmt::format("twin fit: {} has {} vertices, face rig '{}' has {}",
                                              name, take->vertex_count(), rig.name,
                                              rig.vertex_count()));
    }
    if (static_cast<int>(take->world_from_skull.size()) != take->frame_count() ||
        static_cast<int>(take->time_s.size()) != take->frame_count()) {
      return InvalidArgumentError(
          fmt::format("twin fit: {} lacks a skull pose or a time per frame", name));
    }
    const double hz = *take->info.platform_hz;
    const int first = FirstHeldFrame(*take);
    const int held = take->frame_count() - first;
    const double span = held > 1 ? take->time_s.back() - take->time_s[first] : 0.0;
    if (held < 8 || span * hz < 2.0) {
      return InvalidArgumentError(
          fmt::format("twin fit: {} holds its expression for {} frames ({:.2f} s), need 8 frames "
                      "over two periods of {} Hz",
                      name, held, span, hz));
    }
  }
  FACEDYN_ASSIGN_OR_RETURN(std::unique_ptr<SoftTissueModel> model,
                           SoftTissueModel::Create(rig, options.prior));
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::VectorXi tet_group,
                           TetStiffnessGroups(rig, model->shell(), options.groups));
  const int group_count = static_cast<int>(options.groups.size());
  FittedTwin twin;
  twin.rig_name = rig.name;
  twin.prior = options.prior;
  twin.groups = options.groups;
  // The prior as a continuous-time material: Create calibrates the modulus for Newmark's step
  // (its continuous mode sits above fundamental_hz, physics/soft_tissue.h "Material"); a twin
  // describes the face itself, so its cheek mode is set to the prior's frequency and damping.
  {
    FACEDYN_ASSIGN_OR_RETURN(const DampedMode calibrated, model->CheekMode());
    const double omega = 2 * M_PI * options.prior.fundamental_hz,
                 zeta = options.prior.damping_ratio;
    TissueMaterial prior = model->material();
    prior.youngs_modulus_kpa *= std::pow(omega / calibrated.omega_rad_s, 2);
    prior.rayleigh_mass = 2 * options.prior.mass_damping_share * zeta * omega;
    prior.rayleigh_stiffness = 2 * (1 - options.prior.mass_damping_share) * zeta / omega;
    FACEDYN_RETURN_IF_ERROR(model->SetMaterial(prior));
  }
  FACEDYN_ASSIGN_OR_RETURN(twin.prior_cheek_mode, model->CheekMode());

  // Observed points: the markers' vertices that the tissue moves (not held by bone).
  const std::vector<int> observed = TwinMarkerVertices(rig);
  if (observed.size() < 3)
    return FailedPreconditionError(fmt::format("face rig '{}' has fewer than 3 markers", rig.name));

  Progress progress("twin fit", static_cast<long>(takes.size()) + 2 + group_count);
  struct Prepared {
    TwinTake summary;
    HarmonicSkullMotion motion;
    Eigen::Matrix3Xcd phasors;
  };
  std::vector<Prepared> prepared;
  for (const auto& [name, take] : takes) {
    const double hz = *take->info.platform_hz;
    const int first = FirstHeldFrame(*take);
    const int held = take->frame_count() - first;
    std::vector<double> times;
    std::vector<Rigid3> poses;
    std::vector<Eigen::Matrix3Xd> points;
    Eigen::Matrix3Xd mean = Eigen::Matrix3Xd::Zero(3, observed.size());
    for (int f = first; f < take->frame_count(); ++f) {
      times.push_back(take->time_s[f]);
      poses.push_back(take->world_from_skull[f]);
      const Rigid3 skull_from_world = take->world_from_skull[f].Inverse();
      const Eigen::Matrix3Xf frame = take->positions.Frame(f);
      Eigen::Matrix3Xd in_skull(3, observed.size());
      for (size_t i = 0; i < observed.size(); ++i) {
        in_skull.col(i) = skull_from_world * Eigen::Vector3d(frame.col(observed[i]).cast<double>());
      }
      mean += in_skull / held;
      points.push_back(std::move(in_skull));
    }
    Prepared p;
    p.summary.name = name;
    p.summary.platform_hz = hz;
    p.summary.held_frames = held;
    FACEDYN_ASSIGN_OR_RETURN(const BlendshapeFit expression,
                             FitBlendshapeWeights(rig, observed, mean));
    p.summary.weights = expression.weights;
    p.summary.blendshape_rms_mm = expression.rms_mm;
    FACEDYN_ASSIGN_OR_RETURN(p.motion, FitHarmonicSkullMotion(times, poses, hz));
    FACEDYN_ASSIGN_OR_RETURN(p.phasors, FitHarmonicPhasors(times, points, hz));
    p.summary.marker_amplitude_rms_mm = std::sqrt(p.phasors.cwiseAbs2().sum() / observed.size());
    p.summary.skull_acceleration_mm_s2 = p.motion.uniform_acceleration_in_skull.norm();
    prepared.push_back(std::move(p));
    progress.Advance();
  }

  // One linearisation per distinct held expression: takes join the first cluster whose first
  // member's weights are within the tolerance; each cluster is linearised about its mean.
  std::vector<Eigen::VectorXd> expressions, seeds;
  std::vector<int> members;
  for (Prepared& p : prepared) {
    int found = -1;
    for (size_t e = 0; e < seeds.size() && found < 0; ++e) {
      if ((seeds[e] - p.summary.weights).cwiseAbs().maxCoeff() <
          options.same_expression_tolerance) {
        found = static_cast<int>(e);
      }
    }
    if (found < 0) {
      found = static_cast<int>(seeds.size());
      seeds.push_back(p.summary.weights);
      expressions.push_back(Eigen::VectorXd::Zero(p.summary.weights.size()));
      members.push_back(0);
    }
    expressions[found] += p.summary.weights;
    ++members[found];
    p.summary.linearisation = found;
  }
  for (size_t e = 0; e < expressions.size(); ++e) expressions[e] /= members[e];
  std::vector<std::unique_ptr<HarmonicTissueResponse>> responses;
  double youngs_at_step = 0.0;
  for (const Eigen::VectorXd& weights : expressions) {
    FACEDYN_RETURN_IF_ERROR(
        model->SetReference(weights, FittedJawAngleRad(rig, weights), options.prior.max_step_s)
            .status());
    youngs_at_step = model->material().youngs_modulus_kpa;
    FACEDYN_ASSIGN_OR_RETURN(TissueSystemParts parts, model->SystemParts(tet_group, group_count));
    std::vector<int> free_observed;
    for (int v : observed) {
      if (parts.skin_dof[v] < 0) {
        return FailedPreconditionError(
            fmt::format("face rig '{}': marker vertex {} has no tissue under it", rig.name, v));
      }
      free_observed.push_back(v);
    }
    FACEDYN_ASSIGN_OR_RETURN(std::unique_ptr<HarmonicTissueResponse> response,
                             HarmonicTissueResponse::Create(std::move(parts), free_observed));
    responses.push_back(std::move(response));
  }
  progress.Advance();

  std::vector<PlatformObservation> observations;
  for (const Prepared& p : prepared) {
    PlatformObservation observation;
    observation.name = p.summary.name;
    observation.model = responses[p.summary.linearisation].get();
    observation.motion = p.motion;
    observation.skin_phasors_mm = p.phasors;
    observations.push_back(std::move(observation));
  }
  FACEDYN_ASSIGN_OR_RETURN(twin.fit, FitTissueMaterial(observations, options.fit));
  progress.Advance();

  // The material: the prior's modulus scaled per group, with the fitted damping.
  const Eigen::VectorXd& theta = twin.fit.theta;
  twin.group_scale = theta.head(group_count).array().exp();
  twin.group_scale_log_stddev = twin.fit.theta_stddev.head(group_count);
  twin.rayleigh_mass = std::exp(theta[group_count]);
  twin.rayleigh_stiffness = std::exp(theta[group_count + 1]);
  twin.rayleigh_mass_log_stddev = twin.fit.theta_stddev[group_count];
  twin.rayleigh_stiffness_log_stddev = twin.fit.theta_stddev[group_count + 1];
  auto material_for = [&](const Eigen::VectorXd& scales) {
    TissueMaterial material;
    material.youngs_modulus_kpa = youngs_at_step;
    material.tet_stiffness_scale.resize(tet_group.size());
    for (Eigen::Index e = 0; e < tet_group.size(); ++e)
      material.tet_stiffness_scale[e] = scales[tet_group[e]];
    material.rayleigh_mass = twin.rayleigh_mass;
    material.rayleigh_stiffness = twin.rayleigh_stiffness;
    return material;
  };
  twin.material = material_for(twin.group_scale);
  FACEDYN_RETURN_IF_ERROR(model->SetMaterial(twin.material));
  FACEDYN_ASSIGN_OR_RETURN(twin.cheek_mode, model->CheekMode());

  // Uncertainty of the cheek mode: d omega / d log s_g by finite differences, then
  // zeta = alpha / (2 w) + beta w / 2 to first order, through the fit's covariance.
  const int p = static_cast<int>(theta.size());
  Eigen::MatrixXd jacobian = Eigen::MatrixXd::Zero(2, p);  // rows: omega, zeta
  constexpr double kStep = 1e-3;
  const double omega = twin.cheek_mode.omega_rad_s;
  for (int g = 0; g < group_count; ++g) {
    Eigen::VectorXd scales = twin.group_scale;
    scales[g] *= std::exp(kStep);
    FACEDYN_RETURN_IF_ERROR(model->SetMaterial(material_for(scales)));
    FACEDYN_ASSIGN_OR_RETURN(const DampedMode shifted, model->CheekMode());
    jacobian(0, g) = (shifted.omega_rad_s - omega) / kStep;
    progress.Advance();
  }
  const double dzeta_domega =
      -twin.rayleigh_mass / (2 * omega * omega) + twin.rayleigh_stiffness / 2;
  jacobian.row(1) = dzeta_domega * jacobian.row(0);
  jacobian(1, group_count) = twin.rayleigh_mass / (2 * omega);
  jacobian(1, group_count + 1) = twin.rayleigh_stiffness * omega / 2;
  FACEDYN_RETURN_IF_ERROR(model->SetMaterial(twin.material));
  const Eigen::Matrix2d mode_covariance = jacobian * twin.fit.covariance * jacobian.transpose();
  twin.cheek_hz_stddev = std::sqrt(mode_covariance(0, 0)) / (2 * M_PI);
  twin.cheek_damping_ratio_stddev = std::sqrt(mode_covariance(1, 1));

  for (const Prepared& prep : prepared) twin.takes.push_back(prep.summary);
  twin.marker_count = static_cast<int>(observed.size());
  // The body, from the same takes' skull motion.
  twin.platform_amplitude_mm = options.platform_amplitude_mm;
  if (options.platform_amplitude_mm > 0) {
    BodyFitOptions body_options;
    body_options.platform_amplitude_mm = options.platform_amplitude_mm;
    StatusOr<BodyFit> body = FitBodyTransmissibility(takes, body_options);
    if (body.ok()) {
      twin.body = std::move(*body);
    } else if (body.status().code() == StatusCode::kFailedPrecondition) {
      twin.body_note = "not fitted: " + body.status().message();  // e.g. too few frequencies
    } else {
      return body.status();
    }
  } else {
    twin.body_note = "not fitted: the platform amplitude was not given";
  }
  twin.seconds = Seconds(start);
  progress.Finish(fmt::format("cheeks {:.2f} Hz, damping {:.3f}",
                              twin.cheek_mode.omega_rad_s / (2 * M_PI),
                              twin.cheek_mode.damping_ratio));
  return twin;
}

Json TwinToJson(const FittedTwin& twin) {
  auto finite_or_null = [](double x) { return std::isfinite(x) ? Json(x) : Json(nullptr); };
  Json json;
  json["format"] = "facedyn-twin";
  json["version"] = 1;
  json["face_rig"] = twin.rig_name;
  json["prior"] = {{"fundamental_hz", twin.prior.fundamental_hz},
                   {"damping_ratio", twin.prior.damping_ratio},
                   {"mass_damping_share", twin.prior.mass_damping_share},
                   {"layers", twin.prior.layers},
                   {"poisson_ratio", twin.prior.poisson_ratio},
                   {"density_kg_per_mm3", twin.prior.density_kg_per_mm3},
                   {"muscle_hz", twin.prior.muscle_hz},
                   {"cheek_mode_hz", twin.prior_cheek_mode.omega_rad_s / (2 * M_PI)},
                   {"cheek_mode_damping_ratio", twin.prior_cheek_mode.damping_ratio}};
  Json groups = Json::array();
  for (size_t g = 0; g < twin.groups.size(); ++g) {
    groups.push_back({{"name", twin.groups[g].name},
                      {"regions", twin.groups[g].regions},
                      {"stiffness_scale", twin.group_scale[g]},
                      {"log_stddev", finite_or_null(twin.group_scale_log_stddev[g])}});
  }
  json["stiffness_groups"] = groups;
  json["youngs_modulus_kpa"] = twin.material.youngs_modulus_kpa;
  json["rayleigh_mass_per_s"] = twin.rayleigh_mass;
  json["rayleigh_mass_log_stddev"] = finite_or_null(twin.rayleigh_mass_log_stddev);
  json["rayleigh_stiffness_s"] = twin.rayleigh_stiffness;
  json["rayleigh_stiffness_log_stddev"] = finite_or_null(twin.rayleigh_stiffness_log_stddev);
  json["cheek_mode"] = {{"hz", twin.cheek_mode.omega_rad_s / (2 * M_PI)},
                        {"hz_stddev", finite_or_null(twin.cheek_hz_stddev)},
                        {"damping_ratio", twin.cheek_mode.damping_ratio},
                        {"damping_ratio_stddev", finite_or_null(twin.cheek_damping_ratio_stddev)}};
  json["fit"] = {{"markers", twin.marker_count},
                 {"phasor_rms_initial_mm", twin.fit.rms_initial_mm},
                 {"phasor_rms_final_mm", twin.fit.rms_final_mm},
                 {"iterations", twin.fit.iterations},
                 {"reduction_bases", twin.fit.reductions},
                 {"reduction_error", twin.fit.reduction_error},
                 {"converged", twin.fit.converged},
                 {"solver", twin.fit.message},
                 {"seconds", twin.seconds}};
  Json takes = Json::array();
  for (const TwinTake& take : twin.takes) {
    takes.push_back({{"name", take.name},
                     {"platform_hz", take.platform_hz},
                     {"held_frames", take.held_frames},
                     {"blendshape_rms_mm", take.blendshape_rms_mm},
                     {"marker_amplitude_rms_mm", take.marker_amplitude_rms_mm},
                     {"skull_acceleration_mm_s2", take.skull_acceleration_mm_s2},
                     {"linearisation", take.linearisation}});
  }
  json["takes"] = takes;
  if (twin.body) {
    json["body"] = BodyFitToJson(*twin.body, twin.platform_amplitude_mm);
    json["body"]["fitted"] = true;
  } else {
    json["body"] = {{"fitted", false}, {"note", twin.body_note}};
  }
  return json;
}

StatusOr<LoadedTwin> LoadTwin(const std::string& path, const FaceRig& rig) {
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode root, ConfigNode::ReadFile(path));
  FACEDYN_ASSIGN_OR_RETURN(const std::string format, root.Get<std::string>("format"));
  if (format != "facedyn-twin")
    return root.Error("format", "is '" + format + "', expected 'facedyn-twin'");
  FACEDYN_ASSIGN_OR_RETURN(const int version, root.Get<int>("version"));
  if (version != 1)
    return root.Error("version", fmt::format("{} is not supported (1 is)", version));
  FACEDYN_ASSIGN_OR_RETURN(const std::string rig_name, root.Get<std::string>("face_rig"));
  if (rig_name != rig.name) {
    return root.Error("face_rig", fmt::format("the twin was fitted to face rig '{}', not '{}'",
                                              rig_name, rig.name));
  }
  LoadedTwin twin;
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode prior, root.Child("prior"));
  FACEDYN_ASSIGN_OR_RETURN(twin.tissue.layers, prior.Get<int>("layers"));
  FACEDYN_ASSIGN_OR_RETURN(twin.tissue.poisson_ratio, prior.Get<double>("poisson_ratio"));
  FACEDYN_ASSIGN_OR_RETURN(twin.tissue.density_kg_per_mm3, prior.Get<double>("density_kg_per_mm3"));
  FACEDYN_ASSIGN_OR_RETURN(twin.tissue.muscle_hz, prior.Get<double>("muscle_hz"));
  FACEDYN_ASSIGN_OR_RETURN(twin.tissue.fundamental_hz, prior.Get<double>("fundamental_hz"));
  FACEDYN_ASSIGN_OR_RETURN(twin.tissue.damping_ratio, prior.Get<double>("damping_ratio"));
  if (Status status = twin.tissue.Check(); !status.ok()) return prior.Error(status.message());
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode groups, root.Child("stiffness_groups"));
  if (!groups.IsSequence() || groups.size() == 0)
    return root.Error("stiffness_groups", "must be a non-empty list");
  std::vector<double> scales;
  for (size_t g = 0; g < groups.size(); ++g) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode group, groups.At(g));
    StiffnessGroup entry;
    FACEDYN_ASSIGN_OR_RETURN(entry.name, group.Get<std::string>("name"));
    FACEDYN_ASSIGN_OR_RETURN(entry.regions, group.GetOr<std::vector<std::string>>("regions", {}));
    FACEDYN_ASSIGN_OR_RETURN(const double scale, group.Get<double>("stiffness_scale"));
    if (!(scale > 0)) return group.Error("stiffness_scale", "must be positive");
    twin.groups.push_back(entry);
    scales.push_back(scale);
  }
  FACEDYN_ASSIGN_OR_RETURN(twin.material.youngs_modulus_kpa,
                           root.Get<double>("youngs_modulus_kpa"));
  FACEDYN_ASSIGN_OR_RETURN(twin.material.rayleigh_mass, root.Get<double>("rayleigh_mass_per_s"));
  FACEDYN_ASSIGN_OR_RETURN(twin.material.rayleigh_stiffness,
                           root.Get<double>("rayleigh_stiffness_s"));
  if (!(twin.material.youngs_modulus_kpa > 0))
    return root.Error("youngs_modulus_kpa", "must be positive");
  if (!(twin.material.rayleigh_mass >= 0)) return root.Error("rayleigh_mass_per_s", "must be >= 0");
  if (!(twin.material.rayleigh_stiffness >= 0))
    return root.Error("rayleigh_stiffness_s", "must be >= 0");
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode mode, root.Child("cheek_mode"));
  FACEDYN_ASSIGN_OR_RETURN(const double hz, mode.Get<double>("hz"));
  FACEDYN_ASSIGN_OR_RETURN(twin.cheek_mode.damping_ratio, mode.Get<double>("damping_ratio"));
  twin.cheek_mode.omega_rad_s = 2 * M_PI * hz;
  if (root.Has("body")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode body, root.Child("body"));
    FACEDYN_ASSIGN_OR_RETURN(const bool fitted, body.GetOr<bool>("fitted", false));
    if (fitted) {
      LoadedTwin::Body loaded;
      FACEDYN_ASSIGN_OR_RETURN(loaded.resonance_hz, body.Get<double>("resonance_hz"));
      FACEDYN_ASSIGN_OR_RETURN(loaded.damping_ratio, body.Get<double>("damping_ratio"));
      FACEDYN_ASSIGN_OR_RETURN(loaded.pitch_rad_per_g, body.Get<double>("pitch_rad_per_g"));
      if (!(loaded.resonance_hz > 0)) return body.Error("resonance_hz", "must be positive");
      if (!(loaded.damping_ratio > 0)) return body.Error("damping_ratio", "must be positive");
      if (!std::isfinite(loaded.pitch_rad_per_g))
        return body.Error("pitch_rad_per_g", "must be finite");
      twin.body = loaded;
    }
  }

  if (rig.skull.vertex_count() != rig.vertex_count()) {
    return FailedPreconditionError(
        fmt::format("face rig '{}' has no skull sharing the skin's topology", rig.name));
  }
  const TetShell shell = BuildTetShell(rig.neutral, rig.skull.positions_mm, twin.tissue.layers);
  StatusOr<Eigen::VectorXi> tet_group = TetStiffnessGroups(rig, shell, twin.groups);
  if (!tet_group.ok()) return root.Error("stiffness_groups", tet_group.status().message());
  twin.material.tet_stiffness_scale.resize(tet_group->size());
  for (Eigen::Index e = 0; e < tet_group->size(); ++e)
    twin.material.tet_stiffness_scale[e] = scales[(*tet_group)[e]];
  return twin;
}

}  // namespace facedyn::physics
