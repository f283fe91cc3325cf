#include "sim/skull_motion.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <utility>
#include <vector>

#include "core/take.h"
#include "physics/body_transmissibility.h"

namespace facedyn::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTwoPi = 2.0 * kPi;
constexpr double kGMmPerS2 = 9810.0;  // |physics::kGravityInWorld|
constexpr double kDegToRad = kPi / 180.0;

// Postural sway is an inverted pendulum about the ankles: the head tilts by
// (horizontal head displacement) / (ankle-to-head height).
constexpr double kSwayPendulumMm = 1500.0;

// Walking. Pozzo, Berthoz & Lefort (1990, Exp. Brain Res., "Head stabilization during various
// locomotor tasks in humans") report head translations of several centimetres while head pitch
// stays within a few degrees; the figures below are of that order.
constexpr double kWalkHeelStrikeS = 0.06;          // heel-strike pulse duration
constexpr double kWalkSurgeFraction = 0.08;        // forward speed fluctuation, peak / mean speed
constexpr double kWalkPitchRad = 1.5 * kDegToRad;  // at step frequency
constexpr double kWalkRollRad = 1.5 * kDegToRad;   // at stride frequency
constexpr double kWalkYawRad = 2.0 * kDegToRad;    // at stride frequency

// Running. Braking then propulsion during stance (peak horizontal acceleration ~0.3 g), head
// pitch/roll/yaw of a few degrees, lateral sway ~2 cm peak-to-peak at stride frequency.
constexpr double kRunBrakingPeakG = 0.3;
constexpr double kRunLateralMm = 10.0;  // peak
constexpr double kRunPitchRad = 2.0 * kDegToRad;
constexpr double kRunRollRad = 1.5 * kDegToRad;
constexpr double kRunYawRad = 2.0 * kDegToRad;

// Jumping in place: small nods and balance corrections.
constexpr double kJumpPitchRad = 2.0 * kDegToRad;
constexpr double kJumpSwayMm = 3.0;

// Seeded phase jitter of the gait's rotation harmonics about their nominal phase.
constexpr double kPhaseJitterRad = 0.5;

// SplitMix64 (Steele, Lea & Flood 2014): a small counter-based generator whose output is the
// same on every platform, unlike std:: distributions.
class Random {
 public:
  explicit Random(uint64_t seed) : state_(seed) {}
  uint64_t Next() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [lo, hi).
  double Uniform(double lo, double hi) {
    return lo + (hi - lo) * static_cast<double>(Next() >> 11) * 0x1.0p-53;
  }

 private:
  uint64_t state_;
};

// amplitude * sin(2 pi hz t + phase_rad).
struct Sinusoid {
  double amplitude = 0.0;
  double hz = 0.0;
  double phase_rad = 0.0;
  double Value(double t_s) const { return amplitude * std::sin(kTwoPi * hz * t_s + phase_rad); }
};

// A raised-cosine acceleration pulse peak * (1 - cos(2 pi u / D)) / 2 for u = t - start in
// [0, D]. Value and slope vanish at both ends, so a sum of them is a C1 acceleration and the
// position it integrates to is C3.
struct HannPulse {
  double start_s = 0.0;
  double duration_s = 0.0;
  double peak = 0.0;

  double Impulse() const { return 0.5 * peak * duration_s; }
  // First integral from start: velocity contributed at time t.
  double Integral1(double t_s) const {
    const double u = t_s - start_s, d = duration_s;
    if (u <= 0.0) return 0.0;
    if (u >= d) return 0.5 * peak * d;
    return 0.5 * peak * (u - d * std::sin(kTwoPi * u / d) / kTwoPi);
  }
  // Second integral from start: displacement contributed at time t.
  double Integral2(double t_s) const {
    const double u = t_s - start_s, d = duration_s;
    if (u <= 0.0) return 0.0;
    if (u >= d) return 0.25 * peak * d * d + 0.5 * peak * d * (u - d);
    return 0.5 * peak *
           (0.5 * u * u + d * d * (std::cos(kTwoPi * u / d) - 1.0) / (kTwoPi * kTwoPi));
  }
};

// A periodic displacement whose acceleration is a train of Hann pulses minus their mean:
//   a(tau) = sum_k pulse_k(tau) - I / P,   tau = t mod P,  I = sum of impulses.
// With I = g P this is a body pushed by the ground in stance and in free fall (a = -g) where no
// pulse acts. Integrated in closed form within the period; the initial velocity is chosen so the
// position is periodic, and the position is 0 at tau = 0 (e.g. touchdown at rest height).
class PulseTrain {
 public:
  PulseTrain() = default;
  PulseTrain(double period_s, std::vector<HannPulse> pulses)
      : period_s_(period_s), pulses_(std::move(pulses)) {
    FACEDYN_CHECK(period_s_ > 0.0, "PulseTrain needs a positive period");
    double impulse = 0.0, end_displacement = 0.0;
    for (const HannPulse& p : pulses_) {
      FACEDYN_CHECK(p.start_s >= 0.0 && p.duration_s > 0.0 &&
                        p.start_s + p.duration_s <= period_s_ * (1.0 + 1e-12),
                    "PulseTrain: a pulse must lie within one period");
      impulse += p.Impulse();
      end_displacement += p.Integral2(period_s_);
    }
    mean_acceleration_ = impulse / period_s_;
    // y(P) = sum Integral2(P) - mean P^2 / 2 + v0 P = 0.
    initial_velocity_ =
        (0.5 * mean_acceleration_ * period_s_ * period_s_ - end_displacement) / period_s_;
  }

  double mean_acceleration() const { return mean_acceleration_; }

  double Position(double t_s) const {
    if (pulses_.empty()) return 0.0;
    const double tau = t_s - period_s_ * std::floor(t_s / period_s_);
    double y = initial_velocity_ * tau - 0.5 * mean_acceleration_ * tau * tau;
    for (const HannPulse& p : pulses_) y += p.Integral2(tau);
    return y;
  }

 private:
  double period_s_ = 1.0;
  std::vector<HannPulse> pulses_;
  double mean_acceleration_ = 0.0;
  double initial_velocity_ = 0.0;
};

// One scalar degree of freedom: sinusoids plus a pulse-train displacement.
struct Channel {
  std::vector<Sinusoid> sinusoids;
  PulseTrain pulses;
  double Value(double t_s) const {
    double v = pulses.Position(t_s);
    for (const Sinusoid& s : sinusoids) v += s.Value(t_s);
    return v;
  }
};

// The generated motions: translation (x, y, z) and small head angles, each a Channel evaluated
// at t + phase_offset_s and faded in by Ramp(t / ramp_in_s), plus a constant forward speed.
class SynthesizedMotion : public SkullMotion {
 public:
  Channel x_mm, y_mm, z_mm, pitch_rad, yaw_rad, roll_rad;
  double forward_speed_mm_per_s = 0.0;
  double ramp_in_s = 0.25;
  double phase_offset_s = 0.0;
  // The rotations turn the head about this point of the skull frame (the skull origin by
  // default): world_from_skull = translation * pivot * rotation * pivot^-1.
  Eigen::Vector3d pivot_in_skull = Eigen::Vector3d::Zero();

  Rigid3 WorldFromSkull(double t_s) const override {
    const double r = Ramp(t_s / ramp_in_s);
    Eigen::Vector3d translation(0.0, 0.0, forward_speed_mm_per_s * t_s);
    if (r == 0.0) return Rigid3::FromTranslation(translation);
    const double tc = t_s + phase_offset_s;
    translation += r * Eigen::Vector3d(x_mm.Value(tc), y_mm.Value(tc), z_mm.Value(tc));
    const Eigen::Quaterniond rotation =
        Eigen::AngleAxisd(r * yaw_rad.Value(tc), Eigen::Vector3d::UnitY()) *
        Eigen::AngleAxisd(r * pitch_rad.Value(tc), Eigen::Vector3d::UnitX()) *
        Eigen::AngleAxisd(r * roll_rad.Value(tc), Eigen::Vector3d::UnitZ());
    translation += pivot_in_skull - rotation * pivot_in_skull;
    return Rigid3(rotation, translation);
  }
};

class NoMotion : public SkullMotion {
 public:
  Rigid3 WorldFromSkull(double) const override { return Rigid3::Identity(); }
  physics::SkullKinematics Kinematics(double) const override { return physics::SkullKinematics{}; }
};

// Sway: per horizontal axis two sinusoids with seeded frequencies and phases, each of half the
// peak, so |sway| <= sway_mm.
void AddSway(const MotionOptions& o, Random* random, Channel* channel) {
  for (int i = 0; i < 2; ++i) {
    const double hz = random->Uniform(o.sway_min_hz, o.sway_max_hz);
    channel->sinusoids.push_back({0.5 * o.sway_mm, hz, random->Uniform(0.0, kTwoPi)});
  }
}

// Platform (whole-body vibration). The standing body between platform and head is modelled as a
// base-excited single-DOF oscillator, resonance ~5 Hz, damping ratio ~0.35. Sources for the
// figures: the standing body's vertical apparent mass has its principal resonance near 5-6 Hz
// (Matsumoto & Griffin 1998, J. Sound Vib., "Dynamic response of the standing human body
// exposed to vertical vibration"); the idealised seated-body values of ISO 5982:2001 put the
// apparent-mass peak near 4-5 Hz, and seat-to-head transmissibility peaks in the same 4-6 Hz
// band with magnitudes ~1.5-2 (review: Paddan & Griffin 1998, J. Sound Vib.); ISO 2631-1's
// vertical weighting Wk is highest over 4-8 Hz for the same reason. A single-DOF fit to these
// curves gives damping ratios of 0.3-0.5. Steady state only: the head moves by
// |T(f)| A sin(2 pi f t + arg T(f)); the ramp-in replaces the oscillator's start transient.
std::unique_ptr<SkullMotion> MakePlatform(const MotionOptions& o) {
  auto motion = std::make_unique<SynthesizedMotion>();
  motion->ramp_in_s = o.ramp_in_s;
  Random random(o.seed);
  const std::complex<double> t =
      physics::BodyTransmissibility(o.platform_hz, o.body_resonance_hz, o.body_damping_ratio);
  const double head_mm = std::abs(t) * o.amplitude_mm;
  const double phase = std::arg(t);
  motion->y_mm.sinusoids.push_back({head_mm, o.platform_hz, phase});
  // Pitch = k a_y / g with a_y = -w^2 y: the same sinusoid, scaled and inverted.
  const double w = kTwoPi * o.platform_hz;
  motion->pitch_rad.sinusoids.push_back(
      {-o.pitch_rad_per_g * w * w * head_mm / kGMmPerS2, o.platform_hz, phase});
  AddSway(o, &random, &motion->x_mm);
  AddSway(o, &random, &motion->z_mm);
  // Inverted pendulum: forward sway (+Z) tips the head forward (+pitch), lateral (+X) rolls it
  // towards +X (negative roll about Z).
  for (const Sinusoid& s : motion->z_mm.sinusoids) {
    motion->pitch_rad.sinusoids.push_back({s.amplitude / kSwayPendulumMm, s.hz, s.phase_rad});
  }
  for (const Sinusoid& s : motion->x_mm.sinusoids) {
    motion->roll_rad.sinusoids.push_back({-s.amplitude / kSwayPendulumMm, s.hz, s.phase_rad});
  }
  return motion;
}

// Walking: the head rides an inverted pendulum, lowest just after heel strike (tau = 0 of each
// step) and highest at mid-stance, with the forward speed lowest at mid-stance (kinetic and
// potential energy exchange). The heel strike adds a short upward acceleration pulse whose
// harmonics reach well above the step frequency. Lateral sway, roll and yaw repeat per stride
// (two steps).
std::unique_ptr<SynthesizedMotion> MakeWalk(const MotionOptions& o) {
  auto motion = std::make_unique<SynthesizedMotion>();
  motion->ramp_in_s = o.ramp_in_s;
  motion->forward_speed_mm_per_s = o.walk_speed_mm_per_s;
  Random random(o.seed);
  const double step_hz = o.walk_step_hz, stride_hz = 0.5 * o.walk_step_hz;
  motion->phase_offset_s = random.Uniform(0.0, 2.0 / step_hz);
  motion->y_mm.sinusoids.push_back({0.5 * o.walk_vertical_mm, step_hz, -0.5 * kPi});
  motion->y_mm.pulses =
      PulseTrain(1.0 / step_hz, {{0.0, kWalkHeelStrikeS, o.walk_heel_strike_g * kGMmPerS2}});
  motion->x_mm.sinusoids.push_back({0.5 * o.walk_lateral_mm, stride_hz, 0.0});
  const double surge_mm = kWalkSurgeFraction * o.walk_speed_mm_per_s / (kTwoPi * step_hz);
  motion->z_mm.sinusoids.push_back({surge_mm, step_hz, 0.0});
  const auto jitter = [&random]() { return random.Uniform(-kPhaseJitterRad, kPhaseJitterRad); };
  motion->pitch_rad.sinusoids.push_back({kWalkPitchRad, step_hz, jitter()});
  motion->roll_rad.sinusoids.push_back({kWalkRollRad, stride_hz, 0.5 * kPi + jitter()});
  motion->yaw_rad.sinusoids.push_back({kWalkYawRad, stride_hz, jitter()});
  return motion;
}

// The vertical pulses of a bouncing gait (run, jump): each period of `period_s` starts with
// touchdown; a smooth impact transient of `impact_s` and peak `impact_g` g rides on a stance
// force spanning the whole `stance_s`, scaled so the total impulse is g * period_s. Then the
// mean acceleration is g, and where no pulse acts (flight) the head falls freely (a = -g). The
// stance force is one Hann pulse (a running step's half-sine-like ground reaction), or with
// `plateau` three Hann pulses of half the stance at quarter-stance spacing, whose sum rises over
// the first quarter, stays flat, and falls over the last quarter (a jump's landing, squat and
// push-off; a single slow-rising pulse would let the body sink half a metre before it is caught).
PulseTrain BouncingVertical(double period_s, double stance_s, double impact_g, double impact_s,
                            bool plateau) {
  const HannPulse impact{0.0, impact_s, impact_g * kGMmPerS2};
  const double stance_impulse = kGMmPerS2 * period_s - impact.Impulse();
  FACEDYN_CHECK(stance_impulse > 0.0, "MotionOptions::Check() lets an impact exceed the weight");
  if (!plateau) {
    return PulseTrain(period_s, {impact, {0.0, stance_s, 2.0 * stance_impulse / stance_s}});
  }
  const double half = 0.5 * stance_s, peak = stance_impulse / (0.75 * stance_s);
  return PulseTrain(period_s,
                    {impact, {0.0, half, peak}, {0.25 * stance_s, half, peak}, {half, half, peak}});
}

// Running (spring-mass gait with a flight phase): the vertical excursion follows from the step
// rate, the flight time and Newton's law instead of being set directly (~75 mm peak-to-peak
// with the defaults, of the order of the 6-10 cm measured for the body's centre of mass). The
// foot-strike transient is a 30 ms pulse of ~2.5 g, the size of the head accelerations found
// in shock-attenuation studies of running (roughly 1-3 g at the head). Braking then propulsion
// along +Z during stance.
std::unique_ptr<SkullMotion> MakeRun(const MotionOptions& o) {
  auto motion = std::make_unique<SynthesizedMotion>();
  motion->ramp_in_s = o.ramp_in_s;
  motion->forward_speed_mm_per_s = o.run_speed_mm_per_s;
  Random random(o.seed);
  const double period_s = 1.0 / o.run_step_hz, stride_hz = 0.5 * o.run_step_hz;
  const double stance_s = period_s - o.run_flight_s;
  motion->phase_offset_s = random.Uniform(0.0, 2.0 * period_s);
  motion->y_mm.pulses = BouncingVertical(period_s, stance_s, o.run_impact_g, o.run_impact_s,
                                         /*plateau=*/false);
  const double brake = kRunBrakingPeakG * kGMmPerS2;
  motion->z_mm.pulses = PulseTrain(
      period_s, {{0.0, 0.5 * stance_s, -brake}, {0.5 * stance_s, 0.5 * stance_s, brake}});
  motion->x_mm.sinusoids.push_back({kRunLateralMm, stride_hz, 0.0});
  const auto jitter = [&random]() { return random.Uniform(-kPhaseJitterRad, kPhaseJitterRad); };
  motion->pitch_rad.sinusoids.push_back({kRunPitchRad, o.run_step_hz, jitter()});
  motion->roll_rad.sinusoids.push_back({kRunRollRad, stride_hz, 0.5 * kPi + jitter()});
  motion->yaw_rad.sinusoids.push_back({kRunYawRad, stride_hz, jitter()});
  return motion;
}

// Jumping in place: stance (landing, squat, push-off) then a flight parabola under gravity. With
// the defaults (0.8 s per jump, 0.4 s flight) the head rises ~225 mm above touchdown height and
// sinks ~230 mm below it in the squat; peak acceleration ~2.2 g plus the landing transient.
std::unique_ptr<SkullMotion> MakeJump(const MotionOptions& o) {
  auto motion = std::make_unique<SynthesizedMotion>();
  motion->ramp_in_s = o.ramp_in_s;
  Random random(o.seed);
  const double jump_hz = 1.0 / o.jump_period_s;
  motion->phase_offset_s = random.Uniform(0.0, o.jump_period_s);
  motion->y_mm.pulses = BouncingVertical(o.jump_period_s, o.jump_period_s - o.jump_flight_s,
                                         o.jump_impact_g, o.jump_impact_s, /*plateau=*/true);
  motion->pitch_rad.sinusoids.push_back(
      {kJumpPitchRad, jump_hz, random.Uniform(-kPhaseJitterRad, kPhaseJitterRad)});
  motion->x_mm.sinusoids.push_back({kJumpSwayMm, jump_hz, random.Uniform(0.0, kTwoPi)});
  motion->z_mm.sinusoids.push_back({kJumpSwayMm, jump_hz, random.Uniform(0.0, kTwoPi)});
  return motion;
}

// Nodding (pitch) or shaking (yaw) the head about the neck: one sinusoid, seeded phase.
std::unique_ptr<SkullMotion> MakeHeadRotation(const MotionOptions& o, bool shake) {
  auto motion = std::make_unique<SynthesizedMotion>();
  motion->ramp_in_s = o.ramp_in_s;
  motion->pivot_in_skull = Eigen::Vector3d(0.0, o.neck_pivot_y_mm, o.neck_pivot_z_mm);
  Random random(o.seed);
  Channel& channel = shake ? motion->yaw_rad : motion->pitch_rad;
  channel.sinusoids.push_back(
      {o.head_motion_deg * kDegToRad, o.head_motion_hz, random.Uniform(0.0, kTwoPi)});
  return motion;
}

// Swaying side to side: the head along X at the top of an inverted pendulum about the ankles,
// rolling with it (to first order in the sway angle; the head's drop, L (1 - cos), is below
// 0.6 mm at the default 40 mm and left out). Rolling about +Z by a positive angle tips the top of
// the head towards -X, so a sway towards +X is a negative roll.
std::unique_ptr<SkullMotion> MakeSway(const MotionOptions& o) {
  auto motion = std::make_unique<SynthesizedMotion>();
  motion->ramp_in_s = o.ramp_in_s;
  Random random(o.seed);
  const double phase = random.Uniform(0.0, kTwoPi);
  motion->x_mm.sinusoids.push_back({o.head_sway_mm, o.head_motion_hz, phase});
  motion->roll_rad.sinusoids.push_back(
      {-std::atan(o.head_sway_mm / kStandingPendulumMm), o.head_motion_hz, phase});
  return motion;
}

// Lying back: a constant pitch of -lie_back_deg faded in by the motion's C2 ramp over
// lie_back_s (a sinusoid at 0 Hz with phase pi/2 is a constant), about the hips.
std::unique_ptr<SkullMotion> MakeLieBack(const MotionOptions& o) {
  auto motion = std::make_unique<SynthesizedMotion>();
  motion->ramp_in_s = o.lie_back_s;
  motion->pivot_in_skull = Eigen::Vector3d(0.0, -kHipBelowSkullMm, 0.0);
  motion->pitch_rad.sinusoids.push_back({-o.lie_back_deg * kDegToRad, 0.0, 0.5 * kPi});
  return motion;
}

// Rotation vector of a unit quaternion (the log map), taking the shorter arc.
Eigen::Vector3d LogMap(Eigen::Quaterniond q) {
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();
  const double s = q.vec().norm();
  if (s < 1e-12) return 2.0 * q.vec() / q.w();
  return 2.0 * std::atan2(s, q.w()) / s * q.vec();
}

Eigen::Quaterniond ExpMap(const Eigen::Vector3d& v) {
  const double theta = v.norm();
  const double k = theta < 1e-6 ? 0.5 - theta * theta / 48.0 : std::sin(0.5 * theta) / theta;
  return Eigen::Quaterniond(std::cos(0.5 * theta), k * v.x(), k * v.y(), k * v.z());
}

Eigen::Matrix3d Hat(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

// Inverse right Jacobian of SO(3): for R(s) = R0 Exp(phi(s)), the body angular velocity is
// J_r(phi) phi', so phi' = J_r^-1(phi) w.
Eigen::Matrix3d InverseRightJacobian(const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const Eigen::Matrix3d hat = Hat(phi);
  const double c = theta < 1e-4 ? 1.0 / 12.0 + theta * theta / 720.0
                                : 1.0 / (theta * theta) -
                                      (1.0 + std::cos(theta)) / (2.0 * theta * std::sin(theta));
  return Eigen::Matrix3d::Identity() + 0.5 * hat + c * hat * hat;
}

// A recorded trajectory. Translation: cubic Hermite with the 3-point (parabola) tangent at each
// sample, which handles uneven sample times. Rotation: cubic Hermite in the log chart at the
// interval's first sample, q(t) = q_k Exp(rho(t)), with the body angular velocity at each
// sample estimated the same way in that sample's own chart and mapped through the inverse
// right Jacobian at the far end, so the angular velocity is continuous across samples: the
// curve is C1, passes through every sample, and is exact for a constant-rate rotation. Before
// the first and after the last sample the pose is held (velocity jumps there: simulate within
// the recorded time span).
class FileMotion : public SkullMotion {
 public:
  FileMotion(std::vector<double> time_s, const std::vector<Rigid3>& poses)
      : time_s_(std::move(time_s)) {
    const size_t n = poses.size();
    translation_.reserve(n);
    rotation_.reserve(n);
    for (size_t i = 0; i < n; ++i) {
      translation_.push_back(poses[i].translation());
      Eigen::Quaterniond q = poses[i].rotation();
      if (i > 0 && q.dot(rotation_.back()) < 0.0) q.coeffs() = -q.coeffs();
      rotation_.push_back(q);
    }
    velocity_.assign(n, Eigen::Vector3d::Zero());
    angular_velocity_.assign(n, Eigen::Vector3d::Zero());
    if (n < 2) return;
    for (size_t i = 0; i < n; ++i) {
      // Slopes to the neighbours (one-sided at the ends), blended as the derivative at sample i
      // of the parabola through samples i-1, i, i+1.
      const bool has_prev = i > 0, has_next = i + 1 < n;
      const double h_prev = has_prev ? time_s_[i] - time_s_[i - 1] : 0.0;
      const double h_next = has_next ? time_s_[i + 1] - time_s_[i] : 0.0;
      const Eigen::Quaterniond inv = rotation_[i].conjugate();
      Eigen::Vector3d d_prev = Eigen::Vector3d::Zero(), d_next = Eigen::Vector3d::Zero();
      Eigen::Vector3d w_prev = Eigen::Vector3d::Zero(), w_next = Eigen::Vector3d::Zero();
      if (has_prev) {
        d_prev = (translation_[i] - translation_[i - 1]) / h_prev;
        w_prev = -LogMap(inv * rotation_[i - 1]) / h_prev;
      }
      if (has_next) {
        d_next = (translation_[i + 1] - translation_[i]) / h_next;
        w_next = LogMap(inv * rotation_[i + 1]) / h_next;
      }
      if (!has_prev) {
        velocity_[i] = d_next;
        angular_velocity_[i] = w_next;
      } else if (!has_next) {
        velocity_[i] = d_prev;
        angular_velocity_[i] = w_prev;
      } else {
        velocity_[i] = (h_next * d_prev + h_prev * d_next) / (h_prev + h_next);
        angular_velocity_[i] = (h_next * w_prev + h_prev * w_next) / (h_prev + h_next);
      }
    }
  }

  Rigid3 WorldFromSkull(double t_s) const override {
    const size_t n = time_s_.size();
    if (n == 1 || t_s <= time_s_.front()) return Rigid3(rotation_.front(), translation_.front());
    if (t_s >= time_s_.back()) return Rigid3(rotation_.back(), translation_.back());
    const size_t k = static_cast<size_t>(std::upper_bound(time_s_.begin(), time_s_.end(), t_s) -
                                         time_s_.begin()) -
                     1;
    const double dt = time_s_[k + 1] - time_s_[k];
    const double s = (t_s - time_s_[k]) / dt;
    const double s2 = s * s, s3 = s2 * s;
    const double h00 = 2 * s3 - 3 * s2 + 1, h10 = s3 - 2 * s2 + s;
    const double h01 = -2 * s3 + 3 * s2, h11 = s3 - s2;
    const Eigen::Vector3d translation = h00 * translation_[k] + h10 * dt * velocity_[k] +
                                        h01 * translation_[k + 1] + h11 * dt * velocity_[k + 1];
    const Eigen::Vector3d end = LogMap(rotation_[k].conjugate() * rotation_[k + 1]);
    const Eigen::Vector3d end_rate = InverseRightJacobian(end) * angular_velocity_[k + 1];
    const Eigen::Vector3d rho = h10 * dt * angular_velocity_[k] + h01 * end + h11 * dt * end_rate;
    return Rigid3(rotation_[k] * ExpMap(rho), translation);
  }

 private:
  std::vector<double> time_s_;
  std::vector<Eigen::Vector3d> translation_;
  std::vector<Eigen::Quaterniond> rotation_;       // consecutive ones on the same hemisphere
  std::vector<Eigen::Vector3d> velocity_;          // mm/s, world
  std::vector<Eigen::Vector3d> angular_velocity_;  // rad/s, skull
};

// "<field> = <value> is outside [lo, hi] <unit>" when value is not in range (NaN included).
Status CheckRange(const char* field, double value, double lo, double hi, const char* unit) {
  if (value >= lo && value <= hi) return Status::Ok();
  return InvalidArgumentError(fmt::format("motion option {} = {} is outside [{}, {}]{}{}", field,
                                          value, lo, hi, *unit ? " " : "", unit));
}

}  // namespace

double Ramp(double s) {
  if (s <= 0.0) return 0.0;
  if (s >= 1.0) return 1.0;
  return s - std::sin(kTwoPi * s) / kTwoPi;
}

const char* MotionKindName(MotionKind kind) {
  switch (kind) {
    case MotionKind::kPlatform:
      return "platform";
    case MotionKind::kWalk:
      return "walk";
    case MotionKind::kRun:
      return "run";
    case MotionKind::kJump:
      return "jump";
    case MotionKind::kNod:
      return "nod";
    case MotionKind::kShake:
      return "shake";
    case MotionKind::kSway:
      return "sway";
    case MotionKind::kTurnWalk:
      return "turn_walk";
    case MotionKind::kLieBack:
      return "lie_back";
    case MotionKind::kNone:
      return "none";
    case MotionKind::kFile:
      return "file";
  }
  return "unknown";
}

StatusOr<MotionKind> ParseMotionKind(const std::string& spec, std::string* file_path) {
  static constexpr MotionKind kNamed[] = {
      MotionKind::kPlatform, MotionKind::kWalk,  MotionKind::kRun,  MotionKind::kJump,
      MotionKind::kNod,      MotionKind::kShake, MotionKind::kSway, MotionKind::kTurnWalk,
      MotionKind::kLieBack,  MotionKind::kNone};
  for (MotionKind kind : kNamed) {
    if (spec == MotionKindName(kind)) return kind;
  }
  const std::string prefix = "file:";
  if (spec.compare(0, prefix.size(), prefix) == 0) {
    const std::string path = spec.substr(prefix.size());
    if (path.empty()) {
      return InvalidArgumentError("motion 'file:' needs a path to a skull.csv, as file:PATH");
    }
    if (file_path != nullptr) *file_path = path;
    return MotionKind::kFile;
  }
  return InvalidArgumentError(
      "motion '" + spec +
      "' is not one of platform, walk, run, jump, nod, shake, sway, turn_walk, lie_back, none, "
      "file:PATH");
}

Status MotionOptions::Check() const {
  FACEDYN_RETURN_IF_ERROR(CheckRange("ramp_in_s", ramp_in_s, 1e-3, 10.0, "s"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("platform_hz", platform_hz, 0.5, 30.0, "Hz"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("amplitude_mm", amplitude_mm, 0.0, 50.0, "mm"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("body_resonance_hz", body_resonance_hz, 1.0, 20.0, "Hz"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("body_damping_ratio", body_damping_ratio, 0.05, 2.0, ""));
  FACEDYN_RETURN_IF_ERROR(CheckRange("pitch_rad_per_g", pitch_rad_per_g, 0.0, 0.2, "rad/g"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("sway_mm", sway_mm, 0.0, 50.0, "mm"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("sway_min_hz", sway_min_hz, 0.01, 5.0, "Hz"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("sway_max_hz", sway_max_hz, sway_min_hz, 5.0, "Hz"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("head_motion_hz", head_motion_hz, 0.2, 6.0, "Hz"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("head_motion_deg", head_motion_deg, 0.0, 45.0, "deg"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("neck_pivot_y_mm", neck_pivot_y_mm, -200.0, 0.0, "mm"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("neck_pivot_z_mm", neck_pivot_z_mm, -150.0, 50.0, "mm"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("head_sway_mm", head_sway_mm, 0.0, 200.0, "mm"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("lie_back_deg", lie_back_deg, 0.0, 90.0, "deg"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("lie_back_s", lie_back_s, 0.3, 10.0, "s"));

  FACEDYN_RETURN_IF_ERROR(CheckRange("walk_step_hz", walk_step_hz, 0.5, 4.0, "Hz"));
  FACEDYN_RETURN_IF_ERROR(
      CheckRange("walk_speed_mm_per_s", walk_speed_mm_per_s, 0.0, 3000.0, "mm/s"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("walk_vertical_mm", walk_vertical_mm, 0.0, 150.0, "mm"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("walk_lateral_mm", walk_lateral_mm, 0.0, 150.0, "mm"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("walk_heel_strike_g", walk_heel_strike_g, 0.0, 3.0, "g"));
  // The heel-strike pulse must fit in one step.
  FACEDYN_RETURN_IF_ERROR(CheckRange("walk_step_hz", walk_step_hz, 0.5, 1.0 / kWalkHeelStrikeS,
                                     "Hz (heel-strike pulse must fit in a step)"));

  FACEDYN_RETURN_IF_ERROR(CheckRange("run_step_hz", run_step_hz, 1.0, 5.0, "Hz"));
  FACEDYN_RETURN_IF_ERROR(
      CheckRange("run_speed_mm_per_s", run_speed_mm_per_s, 0.0, 10000.0, "mm/s"));
  const double run_period_s = 1.0 / run_step_hz;
  FACEDYN_RETURN_IF_ERROR(CheckRange("run_flight_s", run_flight_s, 0.0, 0.7 * run_period_s,
                                     "s (at most 70% of a step)"));
  const double run_stance_s = run_period_s - run_flight_s;
  FACEDYN_RETURN_IF_ERROR(
      CheckRange("run_impact_s", run_impact_s, 1e-3, run_stance_s, "s (within the stance phase)"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("run_impact_g", run_impact_g, 0.0,
                                     1.9 * run_period_s / run_impact_s,
                                     "g (its impulse must stay below the body weight's)"));

  FACEDYN_RETURN_IF_ERROR(CheckRange("jump_period_s", jump_period_s, 0.3, 10.0, "s"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("jump_flight_s", jump_flight_s, 0.0, jump_period_s - 0.15,
                                     "s (stance must last at least 0.15 s)"));
  const double jump_stance_s = jump_period_s - jump_flight_s;
  FACEDYN_RETURN_IF_ERROR(CheckRange("jump_impact_s", jump_impact_s, 1e-3, jump_stance_s,
                                     "s (within the stance phase)"));
  FACEDYN_RETURN_IF_ERROR(CheckRange("jump_impact_g", jump_impact_g, 0.0,
                                     1.9 * jump_period_s / jump_impact_s,
                                     "g (its impulse must stay below the body weight's)"));

  if (kind == MotionKind::kFile && file.empty()) {
    return InvalidArgumentError("motion option file is empty; motion 'file' needs a skull.csv");
  }
  return Status::Ok();
}

physics::SkullKinematics SkullMotion::Kinematics(double t_s) const {
  const double h = kDifferenceStepS;
  Rigid3 pose[5];
  for (int i = 0; i < 5; ++i) pose[i] = WorldFromSkull(t_s + (i - 2) * h);
  const Eigen::Quaterniond& q0 = pose[2].rotation();
  Eigen::Vector3d dp[5];
  Eigen::Vector4d dq[5];
  for (int i = 0; i < 5; ++i) {
    dp[i] = pose[i].translation() - pose[2].translation();
    Eigen::Vector4d c = pose[i].rotation().coeffs();
    if (c.dot(q0.coeffs()) < 0.0) c = -c;
    dq[i] = c - q0.coeffs();
  }
  // 5-point stencils: f' = (f-2 - 8 f-1 + 8 f1 - f2) / 12h, f'' = (-f-2 + 16 f-1 - 30 f0 + 16 f1
  // - f2) / 12h^2 (differences from the centre; the centre term is then zero).
  const Eigen::Vector3d acceleration =
      (-dp[0] + 16.0 * dp[1] + 16.0 * dp[3] - dp[4]) / (12 * h * h);
  const Eigen::Vector4d q_dot = (dq[0] - 8.0 * dq[1] + 8.0 * dq[3] - dq[4]) / (12 * h);
  const Eigen::Vector4d q_ddot = (-dq[0] + 16.0 * dq[1] + 16.0 * dq[3] - dq[4]) / (12 * h * h);
  const Eigen::Quaterniond q0_conj = q0.conjugate();
  physics::SkullKinematics k;
  k.world_from_skull = pose[2];
  k.origin_acceleration_in_skull = q0_conj * acceleration;
  k.angular_velocity_in_skull = 2.0 * (q0_conj * Eigen::Quaterniond(q_dot)).vec();
  k.angular_acceleration_in_skull = 2.0 * (q0_conj * Eigen::Quaterniond(q_ddot)).vec();
  return k;
}

StatusOr<std::unique_ptr<SkullMotion>> MakeSkullMotion(const MotionOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  switch (options.kind) {
    case MotionKind::kPlatform:
      return MakePlatform(options);
    case MotionKind::kWalk:
      return std::unique_ptr<SkullMotion>(MakeWalk(options));
    case MotionKind::kRun:
      return MakeRun(options);
    case MotionKind::kJump:
      return MakeJump(options);
    case MotionKind::kNod:
      return MakeHeadRotation(options, /*shake=*/false);
    case MotionKind::kShake:
      return MakeHeadRotation(options, /*shake=*/true);
    case MotionKind::kSway:
      return MakeSway(options);
    case MotionKind::kTurnWalk: {
      std::unique_ptr<SynthesizedMotion> walk = MakeWalk(options);
      walk->pivot_in_skull = Eigen::Vector3d(0.0, options.neck_pivot_y_mm, options.neck_pivot_z_mm);
      Random random(options.seed ^ 0x5bd1e995u);  // the turn's phase, apart from the gait's
      walk->yaw_rad.sinusoids.push_back({options.head_motion_deg * kDegToRad,
                                         options.head_motion_hz, random.Uniform(0.0, kTwoPi)});
      return std::unique_ptr<SkullMotion>(std::move(walk));
    }
    case MotionKind::kLieBack:
      return MakeLieBack(options);
    case MotionKind::kNone:
      return std::unique_ptr<SkullMotion>(std::make_unique<NoMotion>());
    case MotionKind::kFile: {
      std::vector<double> time_s;
      std::vector<Rigid3> poses;
      FACEDYN_RETURN_IF_ERROR(ReadTransformCsv(options.file, &time_s, &poses));
      if (poses.empty()) {
        return DataLossError(options.file + ": no samples (a skull.csv needs at least one row)");
      }
      return std::unique_ptr<SkullMotion>(std::make_unique<FileMotion>(std::move(time_s), poses));
    }
  }
  return InternalError("unknown MotionKind");
}

}  // namespace facedyn::sim
