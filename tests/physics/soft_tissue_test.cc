// Physics checks of the tissue model on a spherical shell patch (tests/physics/shell_rig.h):
// calibration, impulse response, energy, frame consistency.

#include "physics/soft_tissue.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <random>

#include <Eigen/Dense>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/mesh_primitives.h"
#include "sim/procedural_face.h"
#include "tests/physics/shell_rig.h"
#include "tests/support/test_support.h"

namespace facedyn::physics {
namespace {

TissueForcing Rest(int blendshapes, double bulge = 0.0) {
  TissueForcing forcing;
  forcing.weights = Eigen::VectorXd::Zero(blendshapes);
  if (blendshapes > 0) forcing.weights[0] = bulge;
  return forcing;
}

// Mean coordinate `axis` of the skin vertices within 25 mm of the patch axis at rest (the
// selection must not change as the skin moves).
double Centre(const Eigen::Matrix3Xd& skin, int axis) {
  static const Eigen::Matrix3Xd rest = MakeShellRig().neutral.positions_mm;
  double sum = 0;
  int n = 0;
  for (int v = 0; v < skin.cols(); ++v) {
    if (std::hypot(rest(0, v), rest(1, v)) < 25) {
      sum += skin(axis, v);
      ++n;
    }
  }
  return sum / n;
}
double CentreZ(const Eigen::Matrix3Xd& skin) { return Centre(skin, 2); }

// The procedural face (its default 5000 vertices), built once.
const FaceRig& ProceduralFace() {
  static const FaceRig* rig = new FaceRig(sim::MakeProceduralFace(sim::ProceduralFaceOptions()).value());
  return *rig;
}

// A damped mode seen in a sampled signal: natural frequency |s| / 2 pi and damping ratio
// -Re(s) / |s| of its continuous-time pole s = ln(z) / dt.
struct MeasuredMode {
  double hz = 0.0;
  double damping_ratio = 0.0;
  double amplitude = 0.0;  // of the pole pair's contribution at the first sample
};

// Prony's method (linear prediction; Hildebrand, Introduction to Numerical Analysis, 9.4):
// fits y[n] = sum_k c_k y[n-k] of order `order` by least squares, takes the roots z_j of the
// prediction polynomial, then the amplitudes b_j of y[n] = sum_j b_j z_j^n, and returns the
// oscillating pole pair that contributes most. Exact for a sum of `order` damped exponentials,
// which a linear system's free response is; the extra order absorbs the faint higher modes.
MeasuredMode DominantMode(const std::vector<double>& y, int order, double dt) {
  const int n = static_cast<int>(y.size());
  Eigen::MatrixXd a(n - order, order);
  Eigen::VectorXd b(n - order);
  for (int i = order; i < n; ++i) {
    for (int k = 1; k <= order; ++k) a(i - order, k - 1) = y[i - k];
    b(i - order) = y[i];
  }
  const Eigen::VectorXd c = a.colPivHouseholderQr().solve(b);
  Eigen::MatrixXd companion = Eigen::MatrixXd::Zero(order, order);
  companion.row(0) = c.transpose();
  for (int k = 1; k < order; ++k) companion(k, k - 1) = 1.0;
  const Eigen::VectorXcd z = Eigen::EigenSolver<Eigen::MatrixXd>(companion).eigenvalues();
  Eigen::MatrixXcd vandermonde(n, order);
  for (int j = 0; j < order; ++j) {
    std::complex<double> power = 1.0;
    for (int i = 0; i < n; ++i, power *= z[j]) vandermonde(i, j) = power;
  }
  const Eigen::VectorXcd weights = vandermonde.colPivHouseholderQr().solve(
      Eigen::Map<const Eigen::VectorXd>(y.data(), n).cast<std::complex<double>>());
  MeasuredMode best;
  for (int j = 0; j < order; ++j) {
    if (z[j].imag() <= 1e-9) continue;  // one of each conjugate pair; real poles do not ring
    const double amplitude = 2 * std::abs(weights[j]);
    if (amplitude <= best.amplitude) continue;
    const std::complex<double> s = std::log(z[j]) / dt;
    best = {std::abs(s) / (2 * M_PI), -s.real() / std::abs(s), amplitude};
  }
  return best;
}

// Free vibration of a neutral face at step dt_s, started with a velocity along the calibrated
// mode so that the face rings in that mode alone (a jolt of the head also rings the close
// modes around it, whose beating no 8-period record can separate). Returns
// observable(DynamicSkin()) minus its value at rest, at every step for `seconds`: the time
// response, which knows nothing of how the material was calibrated.
template <typename Observable>
std::vector<double> FreeVibrationAlongCalibratedMode(const FaceRig& rig,
                                                     const TissueOptions& options, double dt_s,
                                                     double seconds, Observable observable) {
  auto created = SoftTissueModel::Create(rig, options);
  EXPECT_TRUE(created.ok()) << created.status().message();
  if (!created.ok()) return {};
  SoftTissueModel& model = **created;
  const int blendshapes = static_cast<int>(rig.blendshape_names.size());
  EXPECT_TRUE(model.SetReference(Eigen::VectorXd::Zero(blendshapes), 0.0, dt_s).ok());
  const TissueForcing rest = Rest(blendshapes);
  model.Reset(rest);
  const double at_rest = observable(model.DynamicSkin());
  model.SetVelocity(model.calibrated_mode());
  std::vector<double> y = {0.0};
  const int steps = static_cast<int>(std::lround(seconds / dt_s));
  for (int step = 0; step < steps; ++step) {
    model.Step(rest);
    y.push_back(observable(model.DynamicSkin()) - at_rest);
  }
  return y;
}

// The Prony estimate itself on a synthetic two-mode signal: it recovers the dominant pole.
TEST(DominantMode, RecoversTheLargerOfTwoDampedSinusoids) {
  const double dt = 1.0 / 128;
  std::vector<double> y;
  for (int i = 0; i <= 96; ++i) {
    const double t = i * dt;
    auto mode = [&](double hz, double zeta, double phase) {
      const double omega = 2 * M_PI * hz;
      return std::exp(-zeta * omega * t) * std::cos(omega * std::sqrt(1 - zeta * zeta) * t + phase);
    };
    y.push_back(mode(11.0, 0.22, 0.3) + 0.3 * mode(14.0, 0.3, 1.0) - 0.05 * std::pow(-0.9, i));
  }
  const MeasuredMode mode = DominantMode(y, 8, dt);
  EXPECT_NEAR(mode.hz, 11.0, 1e-6);
  EXPECT_NEAR(mode.damping_ratio, 0.22, 1e-6);
}

// The shipped settings: the procedural face, default TissueOptions (11 Hz, zeta 0.22), one
// step per 128 fps frame (dt = max_step_s). The cheeks' mean vertical motion over 0.75 s
// (~8 periods; the envelope falls ~e^-11) shows the configured fundamental and damping ratio
// within 3%. Two Prony orders show the estimate does not hinge on the order.
TEST(SoftTissueModel, ShippedStepShowsConfiguredFrequencyAndDamping) {
  const TissueOptions options;
  const double dt = 1.0 / 128;
  ASSERT_EQ(options.max_step_s, dt);
  const auto& cheeks = ProceduralFace().regions.at("cheeks");
  const std::vector<double> y = FreeVibrationAlongCalibratedMode(
      ProceduralFace(), options, dt, 0.75, [&](const Eigen::Matrix3Xd& skin) {
        double sum = 0;
        for (int v : cheeks) sum += skin(1, v);
        return sum / cheeks.size();
      });
  ASSERT_EQ(y.size(), 97u);
  for (int order : {4, 8}) {
    const MeasuredMode mode = DominantMode(y, order, dt);
    SCOPED_TRACE(::testing::Message() << "Prony order " << order << ": measured " << mode.hz
                                      << " Hz, zeta " << mode.damping_ratio);
    EXPECT_NEAR(mode.hz, 11.0, 0.03 * 11.0);
    EXPECT_NEAR(mode.damping_ratio, 0.22, 0.03 * 0.22);
  }
}

// Other settings and steps on the (much cheaper) shell patch, whose calibrated mode is its
// lowest, a shear of the flesh over the skull; the centre's X follows it. The step is the one
// actually taken: 1/128 s, and 1/256 s as when max_step_s = 0.004 splits 128 fps frames in two.
TEST(SoftTissueModel, OtherSettingsAndStepsShowConfiguredFrequencyAndDamping) {
  struct Case {
    double hz, zeta, dt;
  };
  for (const Case& c :
       {Case{7.0, 0.15, 1.0 / 128}, Case{16.0, 0.3, 1.0 / 128}, Case{11.0, 0.22, 1.0 / 256}}) {
    TissueOptions options;
    options.fundamental_hz = c.hz;
    options.damping_ratio = c.zeta;
    options.max_step_s = c.dt;
    const std::vector<double> y = FreeVibrationAlongCalibratedMode(
        MakeShellRig(), options, c.dt, 8 / c.hz,
        [](const Eigen::Matrix3Xd& skin) { return Centre(skin, 0); });
    const MeasuredMode mode = DominantMode(y, 6, c.dt);
    SCOPED_TRACE(::testing::Message()
                 << "configured " << c.hz << " Hz, zeta " << c.zeta << ", dt " << c.dt
                 << ": measured " << mode.hz << " Hz, zeta " << mode.damping_ratio);
    EXPECT_NEAR(mode.hz, c.hz, 0.03 * c.hz);
    EXPECT_NEAR(mode.damping_ratio, c.zeta, 0.03 * c.zeta);
  }
}

// Newmark's average-acceleration step for u'' + 2 zeta omega u' + omega^2 u = 0 written out
// as the amplification matrix of (u, v, a) (Bathe, Finite Element Procedures, 9.4): column j
// is one step from the j-th unit state, by the rule's own update formulas.
Eigen::Matrix3d NewmarkAmplification(double omega, double zeta, double dt) {
  const double c = 2 * zeta * omega, k = omega * omega;
  Eigen::Matrix3d amplification;
  for (int j = 0; j < 3; ++j) {
    const Eigen::Vector3d x = Eigen::Vector3d::Unit(j);
    const double u = x[0], v = x[1], a = x[2];
    const double u_new = ((4 / (dt * dt)) * u + (4 / dt) * v + a + c * ((2 / dt) * u + v)) /
                         (k + 2 * c / dt + 4 / (dt * dt));
    const double a_new = (4 / (dt * dt)) * (u_new - u) - (4 / dt) * v - a;
    const double v_new = v + dt / 2 * (a + a_new);
    amplification.col(j) = Eigen::Vector3d(u_new, v_new, a_new);
  }
  return amplification;
}

// The mapping reproduces the recursion's own eigenvalues: the two of largest modulus (the
// third is 0, the acceleration being slaved to u and v) give poles ln(z) / dt whose
// frequency and damping NewmarkApparentMode predicts, from well resolved to four steps per
// period, underdamped and overdamped.
TEST(NewmarkApparentMode, MatchesTheAmplificationMatrixEigenvalues) {
  for (double hz : {2.0, 11.0, 32.0}) {
    for (double zeta : {0.0, 0.05, 0.22, 0.6, 1.5}) {
      const double dt = 1.0 / 128, omega = 2 * M_PI * hz;
      Eigen::Vector3cd z =
          Eigen::EigenSolver<Eigen::Matrix3d>(NewmarkAmplification(omega, zeta, dt)).eigenvalues();
      std::sort(z.data(), z.data() + 3, [](auto p, auto q) { return std::abs(p) > std::abs(q); });
      EXPECT_LT(std::abs(z[2]), 1e-9);
      const std::complex<double> s1 = std::log(z[0]) / dt, s2 = std::log(z[1]) / dt;
      const double omega_bar = std::sqrt((s1 * s2).real());
      const double zeta_bar = -(s1 + s2).real() / (2 * omega_bar);
      const DampedMode apparent = NewmarkApparentMode({omega, zeta}, dt);
      SCOPED_TRACE(::testing::Message() << hz << " Hz, zeta " << zeta);
      EXPECT_NEAR(apparent.omega_rad_s, omega_bar, 1e-9 * omega);
      EXPECT_NEAR(apparent.damping_ratio, zeta_bar, 1e-9);
    }
  }
}

// And the recursion itself, stepped: from u = 1 at rest, an underdamped mode's samples are
// u_n = A exp(-zeta_bar omega_bar n dt) cos(omega_bar sqrt(1 - zeta_bar^2) n dt + phi), with
// the apparent mode's figures (A and phi from the first two samples).
TEST(NewmarkApparentMode, PredictsTheSteppedResponse) {
  const double dt = 1.0 / 128, omega = 2 * M_PI * 11.0, zeta = 0.22;
  const Eigen::Matrix3d amplification = NewmarkAmplification(omega, zeta, dt);
  const DampedMode apparent = NewmarkApparentMode({omega, zeta}, dt);
  const double sigma = apparent.damping_ratio * apparent.omega_rad_s;
  const double omega_d =
      apparent.omega_rad_s * std::sqrt(1 - apparent.damping_ratio * apparent.damping_ratio);
  Eigen::Vector3d x(1.0, 0.0, -omega * omega);  // a consistent with the equation of motion
  std::vector<double> u = {x[0]};
  for (int n = 0; n < 64; ++n) u.push_back((x = amplification * x)[0]);
  // u_0 = A cos(phi), u_1 e^(sigma dt) = A cos(omega_d dt + phi).
  const double c0 = u[0], c1 = u[1] * std::exp(sigma * dt);
  const double phi = std::atan2(c0 * std::cos(omega_d * dt) - c1, c0 * std::sin(omega_d * dt));
  const double amplitude = c0 / std::cos(phi);
  for (int n = 0; n <= 64; ++n) {
    EXPECT_NEAR(u[n], amplitude * std::exp(-sigma * n * dt) * std::cos(omega_d * n * dt + phi),
                1e-12)
        << n;
  }
}

// Compensation is the exact inverse, and at the shipped step it asks for a stiffer, more
// damped continuous mode than the one configured (Newmark lengthens the period and, measured
// on the free response, lowers the damping ratio).
TEST(NewmarkCompensatedMode, InvertsTheApparentMode) {
  for (double dt : {1.0 / 128, 1.0 / 256, 1.0 / 1000}) {
    for (double hz : {3.0, 7.0, 11.0, 30.0}) {
      for (double zeta : {0.0, 0.15, 0.22, 0.9, 1.5}) {
        const DampedMode target{2 * M_PI * hz, zeta};
        const DampedMode round_trip = NewmarkApparentMode(NewmarkCompensatedMode(target, dt), dt);
        SCOPED_TRACE(::testing::Message() << hz << " Hz, zeta " << zeta << ", dt " << dt);
        EXPECT_NEAR(round_trip.omega_rad_s, target.omega_rad_s, 1e-9 * target.omega_rad_s);
        EXPECT_NEAR(round_trip.damping_ratio, target.damping_ratio, 1e-9);
      }
    }
  }
  const DampedMode shipped = NewmarkCompensatedMode({2 * M_PI * 11.0, 0.22}, 1.0 / 128);
  EXPECT_GT(shipped.omega_rad_s, 2 * M_PI * 11.0 * 1.02);
  EXPECT_GT(shipped.damping_ratio, 0.22 * 1.03);
}

TEST(SoftTissueModel, RefusesAStepTooCoarseForTheFundamental) {
  TissueOptions options;
  options.fundamental_hz = 40.0;  // 3.2 steps per period at 1/128 s
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("max_step_s"));
  options.max_step_s = 1.0 / 256;
  auto model = SoftTissueModel::Create(MakeShellRig(), options);
  ASSERT_TRUE(model.ok()) << model.status().message();
  EXPECT_FALSE((*model)->SetReference(Eigen::VectorXd::Zero(1), 0.0, 1.0 / 128).ok());
  EXPECT_TRUE((*model)->SetReference(Eigen::VectorXd::Zero(1), 0.0, 1.0 / 256).ok());
}

TEST(TissueOptions, CheckNamesTheField) {
  TissueOptions options;
  options.damping_ratio = -1;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("damping_ratio"));
  options = TissueOptions();
  options.layers = 0;
  EXPECT_THAT(options.Check().message(), ::testing::HasSubstr("layers"));
}

TEST(SoftTissueModel, RefusesSkullWithOtherTopology) {
  FaceRig rig = MakeShellRig();
  rig.skull = MakeEllipsoidPatch(75, 75, 75, 0.7, 0.6, 5, 5);
  auto model = SoftTissueModel::Create(rig, TissueOptions());
  ASSERT_FALSE(model.ok());
  EXPECT_THAT(model.status().message(), ::testing::HasSubstr("topology"));
}

// The continuous system's fundamental is the mode the step's compensation asks for (the
// time-response tests above check what the stepped face shows; this one that the calibration
// re-derives E for the step SetReference is given, not the one Create assumed).
TEST(SoftTissueModel, CalibratesFundamentalFrequency) {
  TissueOptions options;
  options.fundamental_hz = 9.0;
  auto model = SoftTissueModel::Create(MakeShellRig(), options);
  ASSERT_TRUE(model.ok()) << model.status().message();
  double previous_youngs = 0;
  for (double dt : {0.002, 1.0 / 128}) {
    ASSERT_TRUE((*model)->SetReference(Eigen::VectorXd::Zero(1), 0.0, dt).ok());
    auto hz = (*model)->NaturalFrequenciesHz(3);
    ASSERT_TRUE(hz.ok());
    const double expected_hz =
        NewmarkCompensatedMode({2 * M_PI * 9.0, 0.22}, dt).omega_rad_s / (2 * M_PI);
    // The neutral reference is the rest shape, so only the eigen solver's tolerance is left.
    EXPECT_NEAR((*hz)[0], expected_hz, 1e-4 * expected_hz) << dt;
    EXPECT_GT((*hz)[1], (*hz)[0]);
    EXPECT_GT((*model)->youngs_modulus_kpa(), previous_youngs);  // a coarser step, a stiffer E
    previous_youngs = (*model)->youngs_modulus_kpa();
  }
}

// A short sideways jolt of the head, then free vibration: the flesh shears over the skull in
// its lowest modes (sliding along the bone is softer than compressing the nearly
// incompressible tissue), so the centre's X oscillates at the fundamental and decays at the
// configured damping ratio (logarithmic decrement).
TEST(SoftTissueModel, ImpulseResponseMatchesConfiguredFrequencyAndDamping) {
  TissueOptions options;
  options.fundamental_hz = 10.0;
  options.damping_ratio = 0.08;
  auto created = SoftTissueModel::Create(MakeShellRig(), options);
  ASSERT_TRUE(created.ok()) << created.status().message();
  SoftTissueModel& model = **created;
  const double dt = 0.001;
  ASSERT_TRUE(model.SetReference(Eigen::VectorXd::Zero(1), 0.0, dt).ok());
  TissueForcing forcing = Rest(1);
  model.Reset(forcing);
  const double rest_x = Centre(model.DynamicSkin(), 0);
  std::vector<double> z;
  for (int step = 0; step < 1500; ++step) {
    forcing.kinematics.origin_acceleration_in_skull = step < 5 ? Eigen::Vector3d(2e4, 0, 0) : Eigen::Vector3d::Zero();
    model.Step(forcing);
    z.push_back(Centre(model.DynamicSkin(), 0) - rest_x);
  }
  // After the stiffer, more damped modes have died out (t > 0.25 s) the flesh rings in a
  // cluster of close shear modes around the fundamental; zero crossings give the mean
  // frequency and the decay of the RMS envelope gives sigma = zeta * omega (robust to the
  // beating of close modes, unlike single-peak log decrements).
  auto rms = [&](int from, int to) {
    double sum = 0;
    for (int i = from; i < to; ++i) sum += z[i] * z[i];
    return std::sqrt(sum / (to - from));
  };
  int crossings = 0, first = -1, last = -1;
  for (int i = 251; i < 1250; ++i) {
    if ((z[i - 1] < 0) != (z[i] < 0)) {
      if (first < 0) first = i;
      last = i;
      ++crossings;
    }
  }
  ASSERT_GE(crossings, 8);
  const double frequency_hz = (crossings - 1) / 2.0 / ((last - first) * dt);
  EXPECT_NEAR(frequency_hz, 10.0, 1.0);
  // Envelope windows of two periods, 0.6 s apart.
  const double sigma = std::log(rms(250, 450) / rms(850, 1050)) / 0.6;
  const double zeta = sigma / (2 * M_PI * frequency_hz);
  EXPECT_NEAR(zeta, 0.08, 0.008);
}

TEST(SoftTissueModel, UndampedFreeVibrationConservesEnergy) {
  TissueOptions options;
  options.damping_ratio = 0.0;
  auto created = SoftTissueModel::Create(MakeShellRig(), options);
  ASSERT_TRUE(created.ok());
  SoftTissueModel& model = **created;
  ASSERT_TRUE(model.SetReference(Eigen::VectorXd::Zero(1), 0.0, 1.0 / 256).ok());
  TissueForcing forcing = Rest(1);
  model.Reset(forcing);
  std::mt19937 rng(3);
  std::normal_distribution<double> normal(0.0, 20.0);  // mm/s
  Eigen::VectorXd velocity(model.free_dof_count());
  for (auto& x : velocity) x = normal(rng);
  model.SetVelocity(velocity);
  const double e0 = model.Energy();
  double worst = 0;
  for (int step = 0; step < 512; ++step) {  // 2 s
    model.Step(forcing);
    worst = std::max(worst, std::abs(model.Energy() - e0) / e0);
  }
  EXPECT_LT(worst, 0.01);
}

TEST(SoftTissueModel, NoMotionHeldExpressionIsQuasistatic) {
  auto created = SoftTissueModel::Create(MakeShellRig(), TissueOptions());
  ASSERT_TRUE(created.ok());
  SoftTissueModel& model = **created;
  ASSERT_TRUE(model.SetReference(Eigen::VectorXd::Constant(1, 1.0), 0.0, 1.0 / 256).ok());
  // Start neutral-ish (weight 0.8) and ramp to the held weight over 0.3 s, then hold.
  TissueForcing forcing = Rest(1, 0.8);
  model.Reset(forcing);
  double max_error = 0;
  for (int step = 1; step <= 512; ++step) {
    const double t = step / 256.0;
    forcing.weights[0] = 0.8 + 0.2 * std::min(1.0, t / 0.3);
    model.Step(forcing);
    if (t > 1.0) {
      max_error = std::max(max_error, (model.DynamicSkin() - model.QuasistaticSkin(forcing)).cwiseAbs().maxCoeff());
    }
  }
  EXPECT_LT(max_error, 0.01);
  // The expression is formed: its targets are the flesh's active rest shape, so the centre
  // bulges out by the blendshape's 5 mm (minus the gravity sag difference).
  auto neutral = SoftTissueModel::Create(MakeShellRig(), TissueOptions());
  ASSERT_TRUE((*neutral)->SetReference(Eigen::VectorXd::Zero(1), 0.0, 1.0 / 256).ok());
  EXPECT_GT(CentreZ(model.ReferenceSkin()) - CentreZ((*neutral)->ReferenceSkin()), 2.5);
}

// A sustained frame acceleration a0 acts like gravity changed by -a0: the dynamic state
// settles on the quasistatic state of a head turned upside down when a0 = 2 g upward... in
// skull coordinates, -a0 = g_upside_down - g_upright.
TEST(SoftTissueModel, SustainedAccelerationSettlesOnEquivalentGravity) {
  auto created = SoftTissueModel::Create(MakeShellRig(), TissueOptions());
  ASSERT_TRUE(created.ok());
  SoftTissueModel& model = **created;
  ASSERT_TRUE(model.SetReference(Eigen::VectorXd::Zero(1), 0.0, 1.0 / 256).ok());
  TissueForcing forcing = Rest(1);
  model.Reset(forcing);
  forcing.kinematics.origin_acceleration_in_skull = Eigen::Vector3d(0, -2 * 9810.0, 0);
  for (int step = 0; step < 768; ++step) model.Step(forcing);  // 3 s, many decay times
  TissueForcing upside_down = Rest(1);
  upside_down.kinematics.world_from_skull = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitZ(), M_PI);
  const Eigen::Matrix3Xd expected = model.QuasistaticSkin(upside_down);
  EXPECT_LT((model.DynamicSkin() - expected).cwiseAbs().maxCoeff(), 0.01);
  // And gravity matters: upside down differs from upright by a visible sag.
  EXPECT_GT((expected - model.QuasistaticSkin(Rest(1))).cwiseAbs().maxCoeff(), 0.05);
}

// A model created with an explicit material (a twin's) is the model Create then SetMaterial
// makes, without the calibration's eigensolve: the same quasistatic and dynamic skin under the
// same forcing, and the material's checks.
TEST(SoftTissueModel, CreateWithMaterialMatchesCreateThenSetMaterial) {
  auto calibrated = SoftTissueModel::Create(MakeShellRig(), TissueOptions());
  ASSERT_TRUE(calibrated.ok());
  TissueMaterial material = (*calibrated)->material();
  material.youngs_modulus_kpa *= 1.3;
  material.rayleigh_mass *= 0.7;
  material.tet_stiffness_scale = Eigen::VectorXd::LinSpaced((*calibrated)->shell().tets.cols(), 0.8, 1.2);
  ASSERT_TRUE((*calibrated)->SetMaterial(material).ok());
  auto direct = SoftTissueModel::Create(MakeShellRig(), TissueOptions(), material);
  ASSERT_TRUE(direct.ok()) << direct.status().message();
  EXPECT_EQ((*direct)->calibrated_mode().size(), 0);
  EXPECT_EQ((*direct)->youngs_modulus_kpa(), material.youngs_modulus_kpa);
  for (SoftTissueModel* model : {calibrated->get(), direct->get()}) {
    ASSERT_TRUE(model->SetReference(Eigen::VectorXd::Constant(1, 0.5), 0.0, 1.0 / 256).ok());
  }
  TissueForcing forcing = Rest(1, 0.5);
  forcing.kinematics.origin_acceleration_in_skull = Eigen::Vector3d(0, 3000, 0);
  (*calibrated)->Reset(forcing);
  (*direct)->Reset(forcing);
  for (int step = 0; step < 20; ++step) {
    (*calibrated)->Step(forcing);
    (*direct)->Step(forcing);
  }
  EXPECT_LT(((*calibrated)->DynamicSkin() - (*direct)->DynamicSkin()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT(((*calibrated)->QuasistaticSkin(forcing) - (*direct)->QuasistaticSkin(forcing)).cwiseAbs().maxCoeff(),
            1e-9);
  const auto mode_a = (*calibrated)->CheekMode(), mode_b = (*direct)->CheekMode();
  ASSERT_TRUE(mode_a.ok() && mode_b.ok());
  EXPECT_NEAR(mode_a->omega_rad_s, mode_b->omega_rad_s, 1e-9 * mode_a->omega_rad_s);
  // SetMaterial's checks apply.
  TissueMaterial bad = material;
  bad.youngs_modulus_kpa = -1;
  auto refused = SoftTissueModel::Create(MakeShellRig(), TissueOptions(), bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("youngs_modulus_kpa"), std::string::npos);
}

// The shell with a second, sideways expression and a jaw hinged under the patch, so every
// block of the held-expression Jacobian (elements, springs, jaw) is exercised.
FaceRig ShellRigWithJaw() {
  FaceRig rig = MakeShellRig(10);
  Eigen::Matrix3Xd shear = Eigen::Matrix3Xd::Zero(3, rig.vertex_count());
  std::vector<int> jaw;
  for (int v = 0; v < rig.vertex_count(); ++v) {
    const Eigen::Vector3d p = rig.neutral.positions_mm.col(v);
    shear(0, v) = 2.0 * std::exp(-((p.x() - 15) * (p.x() - 15) + p.y() * p.y()) / (25.0 * 25.0));
    if (p.y() < -10) jaw.push_back(v);
  }
  rig.blendshape_names.push_back("shear");
  rig.blendshape_deltas_mm.push_back(shear);
  rig.regions["jaw"] = jaw;
  rig.jaw.region = "jaw";
  rig.jaw.pivot_in_skull = Eigen::Vector3d(0, 10, 40);
  rig.jaw.axis_in_skull = Eigen::Vector3d::UnitX();
  return rig;
}

// Bao et al.'s targeting gradient: the held expression's equilibrium skin under tilted gravity,
// differentiated with respect to the weights and the jaw with the reference moving with them,
// against central differences of SetReference + QuasistaticSkin (which never use the Jacobian).
TEST(SoftTissueModel, HeldSkinJacobianMatchesFiniteDifferences) {
  const FaceRig rig = ShellRigWithJaw();
  auto created = SoftTissueModel::Create(rig, TissueOptions());
  ASSERT_TRUE(created.ok()) << created.status().message();
  SoftTissueModel& model = **created;
  // Lying back by 50 degrees: gravity turns in the skull frame.
  TissueForcing forcing = Rest(2);
  forcing.kinematics.world_from_skull =
      Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), -50 * M_PI / 180);
  const Eigen::Vector3d dg = forcing.kinematics.GravityInSkull() - kGravityInWorld;
  const Eigen::VectorXd w = (Eigen::VectorXd(2) << 0.35, 0.6).finished();  // partly active springs
  const double jaw = 0.08;
  const double dt = 1.0 / 256;
  std::vector<int> vertices;
  for (int v = 0; v < rig.vertex_count(); v += 3) vertices.push_back(v);

  auto skin_at = [&](const Eigen::VectorXd& weights, double jaw_rad) {
    EXPECT_TRUE(model.SetReference(weights, jaw_rad, dt).ok());
    forcing.weights = weights;
    const Eigen::Matrix3Xd skin = model.QuasistaticSkin(forcing);
    Eigen::VectorXd picked(3 * vertices.size());
    for (size_t i = 0; i < vertices.size(); ++i) picked.segment<3>(3 * i) = skin.col(vertices[i]);
    return picked;
  };
  const Eigen::VectorXd at = skin_at(w, jaw);
  auto held = model.HeldSkinWithJacobian(dg, vertices);
  ASSERT_TRUE(held.ok()) << held.status().message();
  EXPECT_LT((held->skin_mm - at).cwiseAbs().maxCoeff(), 1e-9);
  ASSERT_EQ(held->jacobian.cols(), 3);

  // Tilted, the flesh sags off its targets (the reference skin) by millimetres.
  const Eigen::Matrix3Xd reference = model.ReferenceSkin();
  double sag_mm = 0;
  for (size_t i = 0; i < vertices.size(); ++i) {
    sag_mm = std::max(sag_mm, (at.segment<3>(3 * i) - reference.col(vertices[i])).norm());
  }
  EXPECT_GT(sag_mm, 0.3);
  for (int p = 0; p < 3; ++p) {
    const double h = p < 2 ? 1e-5 : 1e-6;
    Eigen::VectorXd wp = w, wm = w;
    double jp = jaw, jm = jaw;
    if (p < 2) {
      wp[p] += h;
      wm[p] -= h;
    } else {
      jp += h;
      jm -= h;
    }
    const Eigen::VectorXd fd = (skin_at(wp, jp) - skin_at(wm, jm)) / (2 * h);
    // The sag's share of the column (the blendshape delta itself is exact by construction).
    Eigen::VectorXd delta = Eigen::VectorXd::Zero(fd.size());
    if (p < 2) {
      for (size_t i = 0; i < vertices.size(); ++i)
        delta.segment<3>(3 * i) = rig.blendshape_deltas_mm[p].col(vertices[i]);
    }
    const Eigen::VectorXd sag_fd = fd - delta, sag_exact = held->jacobian.col(p) - delta;
    ASSERT_GT(sag_fd.norm(), 1e-4)
        << "parameter " << p << " must change the sag for this test to mean anything";
    EXPECT_LT((sag_exact - sag_fd).norm(), 1e-4 * sag_fd.norm()) << "parameter " << p;
  }
  // The flesh's volume at the equilibrium, against the targets' (no sag) and the neutral's.
  ASSERT_TRUE(model.SetReference(w, jaw, dt).ok());
  const double targets = model.FleshVolumeMm3(model.NodeTargets(w, jaw));
  EXPECT_GT(held->flesh_volume_mm3, 0.0);
  EXPECT_NE(held->flesh_volume_mm3, targets);
  EXPECT_LT(std::abs(held->flesh_volume_mm3 / targets - 1), 0.05);
  // Refusals.
  EXPECT_FALSE(model.HeldSkinWithJacobian(dg, {rig.vertex_count()}).ok());
  auto fresh = SoftTissueModel::Create(rig, TissueOptions());
  ASSERT_TRUE(fresh.ok());
  EXPECT_EQ((*fresh)->HeldSkinWithJacobian(dg, {}).status().code(),
            StatusCode::kFailedPrecondition);
}

// The static reference (no Newmark factorisation) is the same linearisation for the quasistatic
// skin; stepping afterwards needs SetReference again, which then works as before.
TEST(SoftTissueModel, StaticReferenceGivesTheSameQuasistaticSkin) {
  const FaceRig rig = ShellRigWithJaw();
  auto a = SoftTissueModel::Create(rig, TissueOptions());
  auto b = SoftTissueModel::Create(rig, TissueOptions());
  ASSERT_TRUE(a.ok() && b.ok());
  const Eigen::VectorXd w = (Eigen::VectorXd(2) << 0.7, 0.2).finished();
  ASSERT_TRUE((*a)->SetReference(w, 0.05, (*a)->options().max_step_s).ok());
  ASSERT_TRUE((*b)->SetStaticReference(w, 0.05).ok());
  TissueForcing forcing = Rest(2);
  forcing.weights = w;
  forcing.kinematics.world_from_skull = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitZ(), 0.6);
  EXPECT_LT(((*a)->QuasistaticSkin(forcing) - (*b)->QuasistaticSkin(forcing)).cwiseAbs().maxCoeff(),
            1e-12);
  const Eigen::Vector3d dg = forcing.kinematics.GravityInSkull() - kGravityInWorld;
  auto held_a = (*a)->HeldSkinWithJacobian(dg, {});
  auto held_b = (*b)->HeldSkinWithJacobian(dg, {}, false);
  ASSERT_TRUE(held_a.ok() && held_b.ok());
  EXPECT_LT((held_a->skin_mm - held_b->skin_mm).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ(held_b->jacobian.size(), 0);
  EXPECT_DOUBLE_EQ(held_a->flesh_volume_mm3, held_b->flesh_volume_mm3);
  ASSERT_TRUE((*b)->SetReference(w, 0.05, (*b)->options().max_step_s).ok());
  (*a)->Reset(forcing);
  (*b)->Reset(forcing);
  (*a)->Step(forcing);
  (*b)->Step(forcing);
  EXPECT_LT(((*a)->DynamicSkin() - (*b)->DynamicSkin()).cwiseAbs().maxCoeff(), 1e-12);
}

}  // namespace
}  // namespace facedyn::physics
