// The tissue's harmonic response and material identification (issue 23), on the shell patch
// (tests/physics/shell_rig.h): gradients against finite differences, the steady state against
// time stepping, and identification of another subject's material from its steady states.

#include "physics/harmonic_response.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "physics/material_fit.h"
#include "physics/soft_tissue.h"
#include "tests/physics/shell_rig.h"

namespace facedyn::physics {
namespace {

using Complex = std::complex<double>;

std::unique_ptr<SoftTissueModel> MakeModel(const TissueOptions& options, double bulge,
                                           double dt_s) {
  auto created = SoftTissueModel::Create(MakeShellRig(), options);
  EXPECT_TRUE(created.ok()) << created.status().message();
  if (!created.ok()) return nullptr;
  EXPECT_TRUE((*created)->SetReference(Eigen::VectorXd::Constant(1, bulge), 0.0, dt_s).ok());
  return std::move(*created);
}

// Tetrahedra on the patch's -X side in group 0, the others in group 1.
Eigen::VectorXi TwoGroups(const SoftTissueModel& model) {
  const TetShell& shell = model.shell();
  Eigen::VectorXi groups(shell.tets.cols());
  for (int e = 0; e < shell.tets.cols(); ++e) {
    groups[e] = shell.rest_positions_mm(0, shell.SkinNode(shell.tet_surface_vertex[e])) < 0 ? 0 : 1;
  }
  return groups;
}

std::vector<int> AllSkinVertices(const TissueSystemParts& parts) {
  std::vector<int> vertices;
  for (int v = 0; v < static_cast<int>(parts.skin_dof.size()); ++v) {
    if (parts.skin_dof[v] >= 0) vertices.push_back(v);
  }
  return vertices;
}

std::unique_ptr<HarmonicTissueResponse> MakeResponse(const SoftTissueModel& model,
                                                     const Eigen::VectorXi& groups,
                                                     int group_count) {
  auto parts = model.SystemParts(groups, group_count);
  EXPECT_TRUE(parts.ok()) << parts.status().message();
  if (!parts.ok()) return nullptr;
  std::vector<int> observed = AllSkinVertices(*parts);
  auto response = HarmonicTissueResponse::Create(std::move(*parts), std::move(observed));
  EXPECT_TRUE(response.ok()) << response.status().message();
  return response.ok() ? std::move(*response) : nullptr;
}

// A skull bouncing vertically with a little pitch, as on the platform.
HarmonicSkullMotion Bounce(double hz) {
  HarmonicSkullMotion motion;
  motion.frequency_hz = hz;
  const double w2 = std::pow(2 * M_PI * hz, 2);
  motion.uniform_acceleration_in_skull =
      Eigen::Vector3cd(Complex(0.02 * w2, 0), Complex(w2, 0.3 * w2), 0);
  motion.angular_acceleration_in_skull = Eigen::Vector3cd(Complex(0.002 * w2, -0.001 * w2), 0, 0);
  return motion;
}

// Central differences of every parameter (step 1e-5 in the logarithm) against the Jacobian,
// to 1e-4 relative.
void ExpectJacobianMatchesFiniteDifferences(const HarmonicTissueResponse& response,
                                            const Eigen::VectorXd& theta,
                                            const HarmonicSkullMotion& motion) {
  Eigen::Matrix3Xcd u;
  std::vector<Eigen::Matrix3Xcd> jacobian;
  ASSERT_TRUE(response.Evaluate(theta, motion, &u, &jacobian).ok());
  ASSERT_EQ(static_cast<int>(jacobian.size()), response.parameter_count());
  for (int j = 0; j < response.parameter_count(); ++j) {
    constexpr double kStep = 1e-5;
    Eigen::VectorXd plus = theta, minus = theta;
    plus[j] += kStep;
    minus[j] -= kStep;
    Eigen::Matrix3Xcd u_plus, u_minus;
    ASSERT_TRUE(response.Evaluate(plus, motion, &u_plus).ok());
    ASSERT_TRUE(response.Evaluate(minus, motion, &u_minus).ok());
    const Eigen::Matrix3Xcd finite = (u_plus - u_minus) / (2 * kStep);
    ASSERT_GT(jacobian[j].norm(), 0.0) << "parameter " << j;
    EXPECT_LT((finite - jacobian[j]).norm() / jacobian[j].norm(), 1e-4)
        << "parameter " << j << " at " << motion.frequency_hz << " Hz";
  }
}

TEST(HarmonicTissueResponse, JacobianMatchesFiniteDifferences) {
  std::unique_ptr<SoftTissueModel> model = MakeModel(TissueOptions(), 0.6, 1.0 / 128);
  ASSERT_NE(model, nullptr);
  std::unique_ptr<HarmonicTissueResponse> response = MakeResponse(*model, TwoGroups(*model), 2);
  ASSERT_NE(response, nullptr);
  ASSERT_EQ(response->parameter_count(), 4);
  Eigen::VectorXd theta = response->InitialParameters();
  theta += Eigen::Vector4d(0.15, -0.2, 0.3, -0.25);  // away from the calibrated material
  for (double hz : {6.0, 11.0}) {
    ExpectJacobianMatchesFiniteDifferences(*response, theta, Bounce(hz));
  }
}

// The reduced system (load-dependent Ritz vectors at the parameters it is evaluated at) agrees
// with the full one at every frequency and damping, and its Jacobian with its finite differences.
TEST(HarmonicTissueResponse, ReductionMatchesTheFullSystem) {
  std::unique_ptr<SoftTissueModel> model = MakeModel(TissueOptions(), 0.6, 1.0 / 128);
  ASSERT_NE(model, nullptr);
  std::unique_ptr<HarmonicTissueResponse> response = MakeResponse(*model, TwoGroups(*model), 2);
  ASSERT_NE(response, nullptr);
  Eigen::VectorXd theta = response->InitialParameters();
  theta += Eigen::Vector4d(0.15, -0.2, 0.3, -0.25);
  EXPECT_FALSE(response->ReduceAt(theta, 0).ok());
  ASSERT_TRUE(response->ReduceAt(theta, 12).ok());
  EXPECT_TRUE(response->reduced());
  EXPECT_GT(response->basis_size(), 30);
  for (double hz : {6.0, 8.0, 11.0, 14.0}) {
    auto error = response->ReductionError(theta, Bounce(hz));
    ASSERT_TRUE(error.ok()) << error.status().message();
    EXPECT_LT(*error, 1e-4) << hz << " Hz";
    // Other damping at the same stiffness: still exact up to the truncation.
    Eigen::VectorXd damped = theta;
    damped.tail<2>() += Eigen::Vector2d(0.7, -0.4);
    error = response->ReductionError(damped, Bounce(hz));
    ASSERT_TRUE(error.ok());
    EXPECT_LT(*error, 1e-4) << hz << " Hz, other damping";
  }
  const HarmonicSkullMotion motion = Bounce(9.0);
  ExpectJacobianMatchesFiniteDifferences(*response, theta, motion);
  response->UseFullSystem();
  EXPECT_FALSE(response->reduced());
}

// The phasors predicted in the frequency domain are the steady state that Newmark time stepping
// reaches under the same skull motion (at a fine step, where the integrator's frequency shift is
// ~1e-4), with the skull motion's phasor measured from the sampled poses.
TEST(HarmonicTissueResponse, MatchesTimeSteppedSteadyState) {
  constexpr double kDt = 1.0 / 2048, kHz = 8.0;
  auto created = SoftTissueModel::Create(MakeShellRig(), TissueOptions());
  ASSERT_TRUE(created.ok());
  SoftTissueModel& model = **created;
  // The calibrated material as an explicit one, so the fine step does not recalibrate it.
  ASSERT_TRUE(model.SetMaterial(model.material()).ok());
  ASSERT_TRUE(model.SetReference(Eigen::VectorXd::Constant(1, 0.6), 0.0, kDt).ok());
  std::unique_ptr<HarmonicTissueResponse> response =
      MakeResponse(model, Eigen::VectorXi::Zero(model.shell().tets.cols()), 1);
  ASSERT_NE(response, nullptr);

  // world_from_skull(t): 1 mm vertical bounce, 0.6 mm fore-aft, 0.004 rad pitch, phase-shifted.
  constexpr double kPitchRad = 0.004;
  const double omega = 2 * M_PI * kHz;
  auto forcing_at = [&](double t, Rigid3* pose) {
    const double pitch = kPitchRad * std::sin(omega * t + 0.7);
    const Eigen::Vector3d translation(0, std::sin(omega * t), 0.6 * std::cos(omega * t));
    const Eigen::Vector3d acceleration = -omega * omega * translation;
    *pose =
        Rigid3(Eigen::Quaterniond(Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitX())), translation);
    TissueForcing forcing;
    forcing.weights = Eigen::VectorXd::Constant(1, 0.6);
    forcing.kinematics.world_from_skull = *pose;
    forcing.kinematics.origin_acceleration_in_skull = pose->rotation().conjugate() * acceleration;
    forcing.kinematics.angular_velocity_in_skull =
        Eigen::Vector3d(kPitchRad * omega * std::cos(omega * t + 0.7), 0, 0);
    forcing.kinematics.angular_acceleration_in_skull =
        Eigen::Vector3d(-kPitchRad * omega * omega * std::sin(omega * t + 0.7), 0, 0);
    return forcing;
  };
  Rigid3 pose;
  model.Reset(forcing_at(0, &pose));
  const Eigen::Matrix3Xd reference = model.ReferenceSkin();
  std::vector<double> times;
  std::vector<Rigid3> poses;
  std::vector<Eigen::Matrix3Xd> offsets;
  const int steps = static_cast<int>(2.0 / kDt);
  for (int step = 1; step <= steps; ++step) {
    const double t = step * kDt;
    model.Step(forcing_at(t, &pose));
    if (t >= 1.0 && step % 16 == 0) {  // 1 s of settling is ~15 decay times at zeta 0.22
      times.push_back(t);
      poses.push_back(pose);
      const Eigen::Matrix3Xd skin = model.DynamicSkin() - reference;
      Eigen::Matrix3Xd observed(3, response->observed_vertices().size());
      for (size_t i = 0; i < response->observed_vertices().size(); ++i)
        observed.col(i) = skin.col(response->observed_vertices()[i]);
      offsets.push_back(observed);
    }
  }
  auto motion = FitHarmonicSkullMotion(times, poses, kHz);
  ASSERT_TRUE(motion.ok()) << motion.status().message();
  auto measured = FitHarmonicPhasors(times, offsets, kHz);
  ASSERT_TRUE(measured.ok()) << measured.status().message();
  Eigen::Matrix3Xcd predicted;
  ASSERT_TRUE(response->Evaluate(response->InitialParameters(), *motion, &predicted).ok());
  ASSERT_GT(measured->norm(), 0.0);
  // Left out of the harmonic model: centripetal and Coriolis terms (second order, at 0 and 2w)
  // and the integrator's shift; measured 9e-5 of the response.
  EXPECT_LT((predicted - *measured).norm() / measured->norm(), 1e-3)
      << "measured " << measured->norm() << " predicted " << predicted.norm();
}

// Another subject (8.5 Hz, damping 0.30) seen at 6-10 Hz through noisy phasors: the twin,
// started from the defaults (11 Hz, 0.22), recovers its cheek mode within 3%.
TEST(FitTissueMaterial, RecoversAnotherSubjectsFrequencyAndDamping) {
  TissueOptions truth_options;
  truth_options.fundamental_hz = 8.5;
  truth_options.damping_ratio = 0.30;
  std::unique_ptr<SoftTissueModel> truth = MakeModel(truth_options, 0.0, 1.0 / 128);
  std::unique_ptr<SoftTissueModel> twin = MakeModel(TissueOptions(), 0.0, 1.0 / 128);
  ASSERT_NE(truth, nullptr);
  ASSERT_NE(twin, nullptr);
  const Eigen::VectorXi one_group = Eigen::VectorXi::Zero(twin->shell().tets.cols());
  std::unique_ptr<HarmonicTissueResponse> truth_response = MakeResponse(*truth, one_group, 1);
  std::unique_ptr<HarmonicTissueResponse> twin_response = MakeResponse(*twin, one_group, 1);
  ASSERT_NE(truth_response, nullptr);
  ASSERT_NE(twin_response, nullptr);

  std::mt19937 rng(3);
  std::normal_distribution<double> normal;
  std::vector<PlatformObservation> observations;
  for (double hz : {6.0, 7.0, 8.0, 9.0, 10.0}) {
    PlatformObservation observation;
    observation.name = fmt::format("{} Hz", hz);
    observation.model = twin_response.get();
    observation.motion = Bounce(hz);
    ASSERT_TRUE(truth_response
                    ->Evaluate(truth_response->InitialParameters(), observation.motion,
                               &observation.skin_phasors_mm)
                    .ok());
    // Measurement noise: 3% of the typical phasor.
    const double sigma =
        0.03 * observation.skin_phasors_mm.norm() / std::sqrt(observation.skin_phasors_mm.size());
    for (Eigen::Index i = 0; i < observation.skin_phasors_mm.size(); ++i) {
      observation.skin_phasors_mm.data()[i] += Complex(sigma * normal(rng), sigma * normal(rng));
    }
    observations.push_back(observation);
  }
  auto fit = FitTissueMaterial(observations, MaterialFitOptions());
  ASSERT_TRUE(fit.ok()) << fit.status().message();
  EXPECT_LT(fit->rms_final_mm, 0.5 * fit->rms_initial_mm);
  EXPECT_GE(fit->reductions, 2);  // the basis was refreshed at the fitted stiffness
  EXPECT_LT(fit->reduction_error, 1e-3);
  EXPECT_TRUE(fit->theta_stddev.allFinite());

  // The fitted material on the twin, then its cheek mode against the truth's.
  TissueMaterial material = twin->material();
  material.youngs_modulus_kpa *= std::exp(fit->theta[0]);
  material.rayleigh_mass = std::exp(fit->theta[1]);
  material.rayleigh_stiffness = std::exp(fit->theta[2]);
  ASSERT_TRUE(twin->SetMaterial(material).ok());
  auto fitted_mode = twin->CheekMode();
  ASSERT_TRUE(fitted_mode.ok());
  ASSERT_TRUE(truth->SetMaterial(truth->material()).ok());  // back to the neutral, unstressed
  auto true_mode = truth->CheekMode();
  ASSERT_TRUE(true_mode.ok());
  EXPECT_NEAR(fitted_mode->omega_rad_s, true_mode->omega_rad_s, 0.03 * true_mode->omega_rad_s);
  EXPECT_NEAR(fitted_mode->damping_ratio, true_mode->damping_ratio,
              0.03 * true_mode->damping_ratio);
}

TEST(HarmonicTissueResponse, BadInputIsNamed) {
  std::unique_ptr<SoftTissueModel> model = MakeModel(TissueOptions(), 0.0, 1.0 / 128);
  ASSERT_NE(model, nullptr);
  auto parts = model->SystemParts(Eigen::VectorXi::Zero(3), 1);
  ASSERT_FALSE(parts.ok());
  EXPECT_NE(parts.status().message().find("3 group labels"), std::string::npos)
      << parts.status().message();
  parts = model->SystemParts(Eigen::VectorXi::Zero(model->shell().tets.cols()), 1);
  ASSERT_TRUE(parts.ok());
  auto response = HarmonicTissueResponse::Create(*parts, {-1});
  ASSERT_FALSE(response.ok());
  EXPECT_NE(response.status().message().find("observed vertex -1"), std::string::npos);
  response = HarmonicTissueResponse::Create(*parts, {0});
  ASSERT_TRUE(response.ok());
  Eigen::Matrix3Xcd u;
  EXPECT_FALSE(
      (*response)->Evaluate(Eigen::VectorXd::Zero(2), Bounce(8), &u).ok());  // 3 parameters
  EXPECT_FALSE(
      (*response)->Evaluate((*response)->InitialParameters(), HarmonicSkullMotion(), &u).ok());

  auto phasors = FitHarmonicPhasors(
      {0.0, 0.1}, {Eigen::Matrix3Xd::Zero(3, 1), Eigen::Matrix3Xd::Zero(3, 1)}, 8);
  ASSERT_FALSE(phasors.ok());
  EXPECT_NE(phasors.status().message().find("2 samples"), std::string::npos);
  std::vector<double> short_times;
  for (int i = 0; i < 10; ++i) short_times.push_back(i * 0.001);
  auto motion = FitHarmonicSkullMotion(short_times, std::vector<Rigid3>(10), 8);
  ASSERT_FALSE(motion.ok());
  EXPECT_NE(motion.status().message().find("less than one period"), std::string::npos);

  TissueMaterial bad = model->material();
  bad.tet_stiffness_scale = Eigen::VectorXd::Ones(2);
  const Status status = model->SetMaterial(bad);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find("2 stiffness scales"), std::string::npos) << status.message();
  bad = model->material();
  bad.youngs_modulus_kpa = -1;
  EXPECT_FALSE(model->SetMaterial(bad).ok());

  EXPECT_FALSE(FitTissueMaterial({}, MaterialFitOptions()).ok());
}

}  // namespace
}  // namespace facedyn::physics
