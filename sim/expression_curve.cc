#include "sim/expression_curve.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "core/check.h"
#include "sim/skull_motion.h"

namespace facedyn::sim {
namespace {

constexpr double kTwoPi = 2.0 * 3.14159265358979323846;

// Drift noise: this many sinusoids per weight, frequencies in [kDriftMinHz, kDriftMaxHz].
constexpr int kDriftTerms = 4;
constexpr double kDriftMinHz = 0.05;
constexpr double kDriftMaxHz = 0.8;

// Speech knot jitter, as a fraction of the mean syllable period.
constexpr double kSyllableJitter = 0.25;

// SplitMix64 finaliser: a stateless hash, so the k-th knot of a sequence is computed directly.
uint64_t Mix(uint64_t z) {
  z += 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Uniform in [0, 1) from a hash value.
double UnitInterval(uint64_t bits) { return static_cast<double>(bits >> 11) * 0x1.0p-53; }

bool AllInUnitInterval(const Eigen::VectorXd& w) {
  return (w.array() >= 0.0).all() && (w.array() <= 1.0).all();  // an empty vector passes
}

class HeldExpression : public ExpressionCurve {
 public:
  HeldExpression(const Eigen::VectorXd& target, double ramp_s, double drift_fraction, uint64_t seed)
      : ramp_s_(ramp_s) {
    const int n = static_cast<int>(target.size());
    drift_peak_ = drift_fraction * target;
    centre_ = target.cwiseMin((Eigen::VectorXd::Ones(n) - drift_peak_));
    amplitude_.resize(n, kDriftTerms);
    hz_.resize(n, kDriftTerms);
    phase_.resize(n, kDriftTerms);
    uint64_t state = seed;
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < kDriftTerms; ++j) {
        state = Mix(state);
        hz_(i, j) = kDriftMinHz + (kDriftMaxHz - kDriftMinHz) * UnitInterval(state);
        state = Mix(state);
        phase_(i, j) = kTwoPi * UnitInterval(state);
        amplitude_(i, j) = drift_peak_[i] / kDriftTerms;
      }
    }
  }

  Eigen::VectorXd Weights(double t_s) const override {
    const double r = Ramp(t_s / ramp_s_);
    const int n = size();
    if (r == 0.0) return Eigen::VectorXd::Zero(n);
    const Eigen::ArrayXXd noise =
        amplitude_.array() * (kTwoPi * hz_.array() * t_s + phase_.array()).sin();
    return r * (centre_ + noise.rowwise().sum().matrix());
  }

  int size() const override { return static_cast<int>(centre_.size()); }

 private:
  double ramp_s_;
  Eigen::VectorXd drift_peak_;  // peak drift a per weight
  Eigen::VectorXd centre_;
  Eigen::MatrixXd amplitude_, hz_, phase_;  // n x kDriftTerms
};

class SpeechSequence : public ExpressionCurve {
 public:
  SpeechSequence(std::vector<Eigen::VectorXd> key_poses, double syllables_per_s, uint64_t seed,
                 bool every_pose_per_cycle = false)
      : key_poses_(std::move(key_poses)),
        syllables_per_s_(syllables_per_s),
        seed_(seed),
        every_pose_per_cycle_(every_pose_per_cycle) {}

  Eigen::VectorXd Weights(double t_s) const override {
    if (t_s <= 0.0) return Eigen::VectorXd::Zero(size());
    // Knot k lies within [(k - 0.25), (k + 0.25)] syllable periods, so the knot interval
    // containing t starts at one of floor(t rate) - 1 .. floor(t rate) + 1.
    const int64_t guess = static_cast<int64_t>(std::floor(t_s * syllables_per_s_));
    int64_t k = std::max<int64_t>(0, guess - 1);
    while (KnotTime(k + 1) <= t_s) ++k;
    const double t0 = KnotTime(k), t1 = KnotTime(k + 1);
    const double s = (t_s - t0) / (t1 - t0);
    const double blend = s * s * s * (10.0 + s * (-15.0 + 6.0 * s));
    return (1.0 - blend) * Pose(k) + blend * Pose(k + 1);
  }

  int size() const override { return static_cast<int>(key_poses_.front().size()); }

 private:
  uint64_t Hash(int64_t k, uint64_t stream) const {
    return Mix(Mix(seed_ ^ (stream * 0xD1B54A32D192ED03ull)) + static_cast<uint64_t>(k));
  }
  double KnotTime(int64_t k) const {
    if (k == 0) return 0.0;
    const double jitter = kSyllableJitter * (2.0 * UnitInterval(Hash(k, 1)) - 1.0);
    return (static_cast<double>(k) + jitter) / syllables_per_s_;
  }
  Eigen::VectorXd Pose(int64_t k) const {
    if (k == 0) return Eigen::VectorXd::Zero(size());
    if (!every_pose_per_cycle_) return key_poses_[Hash(k, 2) % key_poses_.size()];
    // Knots 1..n are cycle 0, n+1..2n cycle 1, ...: each cycle a seeded permutation of the
    // poses (Fisher-Yates driven by the cycle's hashes).
    const int64_t n = static_cast<int64_t>(key_poses_.size());
    const int64_t cycle = (k - 1) / n;
    std::vector<int64_t> order(n);
    for (int64_t i = 0; i < n; ++i) order[i] = i;
    for (int64_t i = n - 1; i > 0; --i) {
      std::swap(order[i], order[Hash(cycle * n + i, 3) % static_cast<uint64_t>(i + 1)]);
    }
    return key_poses_[order[(k - 1) % n]];
  }

  std::vector<Eigen::VectorXd> key_poses_;
  double syllables_per_s_;
  uint64_t seed_;
  bool every_pose_per_cycle_;
};

}  // namespace

std::unique_ptr<ExpressionCurve> MakeHeldExpression(const Eigen::VectorXd& target, double ramp_s,
                                                    double drift_fraction, uint64_t seed) {
  FACEDYN_CHECK(AllInUnitInterval(target), "MakeHeldExpression: target weights must be in [0, 1]");
  FACEDYN_CHECK(ramp_s > 0.0 && std::isfinite(ramp_s),
                "MakeHeldExpression: ramp_s must be positive, got " + std::to_string(ramp_s));
  FACEDYN_CHECK(drift_fraction >= 0.0 && drift_fraction <= 0.5,
                "MakeHeldExpression: drift_fraction must be in [0, 0.5], got " +
                    std::to_string(drift_fraction));
  return std::make_unique<HeldExpression>(target, ramp_s, drift_fraction, seed);
}

std::unique_ptr<ExpressionCurve> MakeSpeechSequence(const std::vector<Eigen::VectorXd>& key_poses,
                                                    double syllables_per_s, uint64_t seed) {
  FACEDYN_CHECK(!key_poses.empty(), "MakeSpeechSequence: needs at least one key pose");
  for (size_t i = 0; i < key_poses.size(); ++i) {
    FACEDYN_CHECK(
        key_poses[i].size() == key_poses.front().size() && AllInUnitInterval(key_poses[i]),
        "MakeSpeechSequence: key pose " + std::to_string(i) +
            " must have the first pose's size and weights in [0, 1]");
  }
  FACEDYN_CHECK(syllables_per_s > 0.0 && syllables_per_s <= 20.0,
                "MakeSpeechSequence: syllables_per_s must be in (0, 20], got " +
                    std::to_string(syllables_per_s));
  return std::make_unique<SpeechSequence>(key_poses, syllables_per_s, seed);
}

std::unique_ptr<ExpressionCurve> MakeScriptedSequence(const std::vector<Eigen::VectorXd>& key_poses,
                                                      double poses_per_s, uint64_t seed) {
  FACEDYN_CHECK(!key_poses.empty(), "MakeScriptedSequence: needs at least one key pose");
  for (size_t i = 0; i < key_poses.size(); ++i) {
    FACEDYN_CHECK(
        key_poses[i].size() == key_poses.front().size() && AllInUnitInterval(key_poses[i]),
        "MakeScriptedSequence: key pose " + std::to_string(i) +
            " must have the first pose's size and weights in [0, 1]");
  }
  FACEDYN_CHECK(
      poses_per_s > 0.0 && poses_per_s <= 20.0,
      "MakeScriptedSequence: poses_per_s must be in (0, 20], got " + std::to_string(poses_per_s));
  return std::make_unique<SpeechSequence>(key_poses, poses_per_s, seed, true);
}

}  // namespace facedyn::sim
