// ExpressionCurve: blendshape weights over time, w(t) in [0, 1]^n, the expression track the
// simulator drives its muscle targets with (Bao et al. 2018: targets move linearly with the
// weights).
//
// Both curves are stateless functions of t (any t may be asked for, in any order, from any
// thread), deterministic for a seed, and neutral (all zeros) for t <= 0.
// - A held expression is what the paper's captures are (Zoss et al. 2020, section 4: the actor
//   holds an expression while the platform shakes): a C2 ramp from neutral to the target, then
//   the target with a small, slow, seeded drift, because a real face never holds perfectly
//   still and the quasistatic extraction must cope with that.
// - A speech-like sequence moves between key poses (visemes, expressions) at a syllable rate:
//   each syllable arrives at a key pose with zero velocity and acceleration (quintic
//   smootherstep between consecutive poses), so the curve is C2 and every weight is a convex
//   combination of two key poses, hence inside [0, 1] without clamping.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <vector>

namespace facedyn::sim {

class ExpressionCurve {
 public:
  virtual ~ExpressionCurve() = default;
  // Blendshape weights at t, size(), each in [0, 1].
  virtual Eigen::VectorXd Weights(double t_s) const = 0;
  virtual int size() const = 0;
};

// A held expression: w(t) = Ramp(t / ramp_s) * (c + a * n(t)) per weight, where Ramp is the C2
// fade-in of sim/skull_motion.h, n(t) in [-1, 1] is band-limited noise (four sinusoids with
// seeded frequencies in 0.05..0.8 Hz and seeded phases, independent per weight), a =
// drift_fraction * target is the peak drift, and c = min(target, 1 - a) keeps the weight in
// [0, 1] (a weight of 1 drifts downward only). So the weight stays within 2a of its target
// once ramped; drift_fraction ~0.02-0.03 is natural.
// Preconditions (CHECKed): target in [0, 1]^n (n = 0 allowed: a rig without blendshapes);
// ramp_s > 0; drift_fraction in [0, 0.5].
std::unique_ptr<ExpressionCurve> MakeHeldExpression(const Eigen::VectorXd& target, double ramp_s,
                                                    double drift_fraction, uint64_t seed);

// Speech-like: knots t_0 = 0 (neutral), t_k = (k + j_k) / syllables_per_s for k >= 1 with seeded
// jitter j_k in [-0.25, 0.25], and at knot k >= 1 a seeded choice among `key_poses`; between
// knots a quintic smootherstep. Syllable rates of 4-5 per second are speech-like.
// Preconditions (CHECKed): key_poses non-empty, all of the same size, entries in [0, 1];
// syllables_per_s in (0, 20].
std::unique_ptr<ExpressionCurve> MakeSpeechSequence(const std::vector<Eigen::VectorXd>& key_poses,
                                                    double syllables_per_s, uint64_t seed);

// A scripted session through key poses (a range of motion): the speech sequence's timing and
// blends, but every key pose exactly once per cycle of key_poses.size() knots, in a seeded order
// per cycle, so a session of n / poses_per_s seconds visits every pose. Same preconditions.
std::unique_ptr<ExpressionCurve> MakeScriptedSequence(const std::vector<Eigen::VectorXd>& key_poses,
                                                      double poses_per_s, uint64_t seed);

}  // namespace facedyn::sim
