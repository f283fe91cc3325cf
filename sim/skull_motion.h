// SkullMotion: the head's rigid trajectory world_from_skull(t) (the paper's T(t)) that drives
// the soft-tissue simulation — a vibrating platform, walking, running, jumping, nodding or
// shaking the head, no motion, or a recorded skull.csv.
//
// Why it is shaped this way:
// - The tissue is simulated in the skull frame, where head motion enters only through the
//   skull's acceleration, angular velocity and angular acceleration (physics/skull_kinematics.h).
//   Generated motions are therefore built to be C2 in time (continuous acceleration): sums of
//   sinusoids and of smooth (Hann-shaped) acceleration pulses integrated in closed form. A
//   kink in velocity would be an infinite force on the flesh.
// - Every generated motion starts from the rest pose (world_from_skull(0) = identity plus the
//   constant forward velocity of walk/run) and fades its oscillations in over `ramp_in_s`
//   with a C2 ramp (the integral of a raised-cosine window, see Ramp below), so the simulated
//   tissue, which starts at rest, does not receive an acceleration step at t = 0. Before
//   t = 0 the oscillations are zero.
// - Walk and run progress along +Z at a constant mean speed for all t (a frame moving at
//   constant velocity is inertial, so the tissue does not feel it); only the fluctuations about
//   it are ramped.
// - Kinematics() differentiates WorldFromSkull numerically (5-point central differences,
//   accurate to ~1e-6 relative for these motions; see the .cc), so a new motion only has to
//   provide poses.
//
// World frame: +Y up, gravity along -Y, forward along +Z, lateral +X (ARCHITECTURE.md).
// Head angles are small rotations about the skull origin: pitch about X (positive tips the
// top of the head towards +Z, i.e. a nod), yaw about Y, roll about Z; R = Ry(yaw) Rx(pitch)
// Rz(roll). Units: mm, s, Hz, rad.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "core/rigid3.h"
#include "core/status.h"
#include "physics/skull_kinematics.h"

namespace facedyn::sim {

enum class MotionKind {
  kPlatform,
  kWalk,
  kRun,
  kJump,
  kNod,
  kShake,
  kSway,
  kTurnWalk,
  kLieBack,
  kNone,
  kFile
};

// "platform", "walk", "run", "jump", "nod", "shake", "sway", "turn_walk", "lie_back", "none",
// "file".
const char* MotionKindName(MotionKind kind);

// Parses "platform|walk|run|jump|nod|shake|sway|turn_walk|lie_back|none|file:PATH". For "file:PATH"
// stores PATH in *file_path (when non-null). An unknown spec or an empty PATH is an InvalidArgument
// error listing the valid kinds.
StatusOr<MotionKind> ParseMotionKind(const std::string& spec, std::string* file_path);

struct MotionOptions {
  MotionKind kind = MotionKind::kPlatform;
  std::string file;   // skull.csv (frame,time_s,qw,qx,qy,qz,tx,ty,tz) for kFile
  uint64_t seed = 1;  // random phases of sway, gait phase at t = 0, rotation harmonics

  // Fade-in of every generated motion: the oscillations are multiplied by a C2 ramp from 0 to 1
  // over this time. Must be > 0 (a zero ramp would be an acceleration step at t = 0).
  double ramp_in_s = 0.25;

  // --- platform: the subject stands on a platform moving vertically by A sin(2 pi f t). ---
  double platform_hz = 8.0;   // oscillation frequency, 6..11 typical, allowed 0.5..30
  double amplitude_mm = 2.0;  // platform vertical amplitude A (peak), mm, allowed 0..50
  // Body transmissibility from platform to head: a base-excited single-DOF oscillator
  // (physics::BodyTransmissibility). Standing-body figures: apparent-mass resonance near 5 Hz with
  // damping ratio 0.3-0.4 (see the .cc for sources).
  double body_resonance_hz = 5.0;    // allowed 1..20
  double body_damping_ratio = 0.35;  // allowed 0.05..2
  // Head pitch (nod) proportional to the head's vertical acceleration, rad per g. The default
  // gives ~0.3 degrees at 8 Hz and 2 mm (head acceleration ~0.4 g). Allowed 0..0.2.
  double pitch_rad_per_g = 0.013;
  // Low-frequency postural sway, lateral (X) and fore-aft (Z): per axis the sum of two
  // sinusoids with seeded frequencies in [sway_min_hz, sway_max_hz] and seeded phases, peak
  // at most sway_mm; the head tilts with it as an inverted pendulum about the ankles.
  double sway_mm = 3.0;      // allowed 0..50
  double sway_min_hz = 0.2;  // allowed 0.01..5, <= sway_max_hz
  double sway_max_hz = 0.4;

  // --- walk: inverted-pendulum gait, head lowest just after each heel strike. ---
  double walk_step_hz = 1.9;            // steps per second (stride = 2 steps), allowed 0.5..4
  double walk_speed_mm_per_s = 1300.0;  // mean forward speed along +Z, allowed 0..3000
  double walk_vertical_mm = 40.0;       // peak-to-peak vertical head excursion per step, 0..150
  double walk_lateral_mm = 30.0;        // peak-to-peak lateral sway at stride frequency, 0..150
  double walk_heel_strike_g = 0.3;      // heel-strike acceleration pulse, peak in g, 0..3

  // --- run: stance (ground contact) and flight per step; vertical motion follows from them. ---
  double run_step_hz = 2.8;            // allowed 1..5
  double run_speed_mm_per_s = 3000.0;  // allowed 0..10000
  double run_flight_s = 0.10;          // flight time per step; stance = 1/run_step_hz - flight
  // Foot-strike transient added to the stance force, peak in g. With the defaults the head's
  // vertical acceleration peaks at ~1.6 g (an accelerometer, reading a + g, shows ~2.6 g).
  double run_impact_g = 2.5;
  double run_impact_s = 0.03;  // duration of the foot-strike transient

  // --- jump: repeated vertical jumps in place; flight under gravity, landing impact. ---
  double jump_period_s = 0.8;   // one jump (stance + flight), allowed 0.3..10
  double jump_flight_s = 0.4;   // time in the air; stance = period - flight
  double jump_impact_g = 3.0;   // landing transient added to the stance force, peak in g
  double jump_impact_s = 0.04;  // duration of the landing transient

  // --- nod / shake: the head rotating on the neck, the motions Zoss et al. 2020 (section 8.1)
  // could not capture on a platform (issue 23's augmentation). A sinusoidal pitch (nod) or yaw
  // (shake) of head_motion_deg peak at head_motion_hz about a pivot at the top of the cervical
  // spine, below and behind the skull origin, so the face also translates as the head turns. ---
  double head_motion_hz = 2.0;     // allowed 0.2..6
  double head_motion_deg = 15.0;   // peak, allowed 0..45
  double neck_pivot_y_mm = -80.0;  // pivot in the skull frame (x = 0), allowed -200..0
  double neck_pivot_z_mm = -20.0;  // allowed -150..50

  // --- sway: the standing body swaying side to side, the lateral motion of section 8.1. The
  // head moves along X by head_sway_mm peak at head_motion_hz and rolls with it as the top of an
  // inverted pendulum about the ankles (kStandingPendulumMm tall), so the gravity direction in
  // the skull frame swings too. ---
  double head_sway_mm = 40.0;  // peak, allowed 0..200

  // --- turn_walk: walking (the walk fields above) while turning the head left and right: a
  // yaw of head_motion_deg peak at head_motion_hz about the neck pivot. ---

  // --- lie_back: a change of the gravity direction: from standing upright the subject lies
  // back by lie_back_deg (pitch, top of the head towards -Z) about the hips (kHipBelowSkullMm
  // below the skull origin) over lie_back_s, a C2 transition, and then stays there. ---
  double lie_back_deg = 60.0;  // allowed 0..90
  double lie_back_s = 1.5;     // allowed 0.3..10

  // Every field in range, and the pulses fit their stance phases. Messages name the field.
  Status Check() const;
};

// Heights used by sway and lie_back: the standing body as an inverted pendulum from the ankles
// to the skull origin, and the hips below the skull origin when lying back (adult figures).
inline constexpr double kStandingPendulumMm = 1500.0;
inline constexpr double kHipBelowSkullMm = 650.0;

// A world_from_skull(t) trajectory. Implementations are C2 unless stated (kFile is C1).
class SkullMotion {
 public:
  virtual ~SkullMotion() = default;

  virtual Rigid3 WorldFromSkull(double t_s) const = 0;

  // Kinematics at t in skull coordinates: origin acceleration R^T d2t/dt2, angular velocity
  // w with [w]x = R^T dR/dt, angular acceleration dw/dt. This default differentiates
  // WorldFromSkull with 5-point central differences of step kDifferenceStepS = 0.5 ms on the
  // translation and the quaternion (w = 2 vec(q* q'), dw/dt = 2 vec(q* q'')). Truncation error
  // is h^4 f^(6) / 90: ~1e-5 relative for a 30 Hz sinusoid, ~1e-6 for the 30 ms impact pulses;
  // rounding adds ~5e-9 |t| mm/s^2. Subclasses may override with analytic derivatives.
  virtual physics::SkullKinematics Kinematics(double t_s) const;

  static constexpr double kDifferenceStepS = 5e-4;
};

// Builds the motion `options.kind` describes. Checks the options first; for kFile reads the
// file (its errors are forwarded, naming the file).
StatusOr<std::unique_ptr<SkullMotion>> MakeSkullMotion(const MotionOptions& options);

// The fade-in used by generated motions: 0 for s <= 0, 1 for s >= 1, and in between
// s - sin(2 pi s) / (2 pi), the integral of a raised-cosine (Hann) window. Its first and second
// derivatives vanish at both ends, so it is C2 (a plain raised cosine 0.5 - 0.5 cos(pi s) is
// only C1: its second derivative jumps at the ends).
double Ramp(double s);

}  // namespace facedyn::sim
