#include "solve/training_data.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace facedyn::solve {

Status TrainingDataOptions::Check() const {
  if (sweep_steps < 1) return InvalidArgumentError(fmt::format("sweep_steps: {} < 1", sweep_steps));
  if (rom_clips < 0) return InvalidArgumentError(fmt::format("rom_clips: {} < 0", rom_clips));
  if (rom_clip_frames < 2)
    return InvalidArgumentError(fmt::format("rom_clip_frames: {} < 2", rom_clip_frames));
  if (random_combos < 0)
    return InvalidArgumentError(fmt::format("random_combos: {} < 0", random_combos));
  if (max_active_channels < 1)
    return InvalidArgumentError(fmt::format("max_active_channels: {} < 1", max_active_channels));
  if (augment_copies < 0)
    return InvalidArgumentError(fmt::format("augment_copies: {} < 0", augment_copies));
  if (!(noise_mm >= 0.0) || !std::isfinite(noise_mm))
    return InvalidArgumentError(fmt::format("noise_mm: {} is not >= 0", noise_mm));
  if (!(mask_shift_mm >= 0.0) || !std::isfinite(mask_shift_mm))
    return InvalidArgumentError(fmt::format("mask_shift_mm: {} is not >= 0", mask_shift_mm));
  if (!(dropout >= 0.0 && dropout < 1.0))
    return InvalidArgumentError(fmt::format("dropout: {} is not in [0, 1)", dropout));
  return Status::Ok();
}

namespace {

// A random sparse pose: 1..max_active channels (the jaw with probability 1/2 besides), each
// uniform within its bounds.
Eigen::VectorXd RandomSparsePose(const Puppet& puppet, const TrainingDataOptions& options,
                                 std::mt19937_64& rng) {
  const int c_count = puppet.channel_count();
  Eigen::VectorXd w = Eigen::VectorXd::Zero(c_count);
  std::uniform_int_distribution<int> count_dist(1, std::min(options.max_active_channels, c_count));
  std::uniform_int_distribution<int> channel_dist(0, c_count - 1);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  auto draw = [&](int c) {
    w[c] = puppet.lower_bounds[c] + unit(rng) * (puppet.upper_bounds[c] - puppet.lower_bounds[c]);
  };
  const int active = count_dist(rng);
  for (int k = 0; k < active; ++k) draw(channel_dist(rng));
  for (int c : options.jaw_channels) {
    if (unit(rng) < 0.5) draw(c);
  }
  return w;
}

}  // namespace

StatusOr<Eigen::MatrixXd> MakeTrainingWeights(const Puppet& puppet,
                                              const TrainingDataOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check().WithContext("training data options"));
  for (int c : options.jaw_channels) {
    if (c < 0 || c >= puppet.channel_count()) {
      return InvalidArgumentError(
          fmt::format("training data options: jaw channel {} is not a channel of the puppet", c));
    }
  }
  std::mt19937_64 rng(options.seed);
  const int c_count = puppet.channel_count();
  std::vector<Eigen::VectorXd> poses;
  poses.push_back(Eigen::VectorXd::Zero(c_count));  // the neutral itself
  // Single channels (one-hot sweeps).
  for (int c = 0; c < c_count; ++c) {
    for (int k = 1; k <= options.sweep_steps; ++k) {
      Eigen::VectorXd w = Eigen::VectorXd::Zero(c_count);
      w[c] = puppet.lower_bounds[c] +
             (puppet.upper_bounds[c] - puppet.lower_bounds[c]) * k / options.sweep_steps;
      poses.push_back(w);
    }
  }
  // Symmetric and asymmetric pairs.
  for (const auto& [left, right] : puppet.symmetric_pairs) {
    for (int k = 1; k <= options.sweep_steps; ++k) {
      const double a = static_cast<double>(k) / options.sweep_steps;
      for (const auto& [wl, wr] : {std::pair<double, double>{a, a}, {a, 0.5 * a}, {0.5 * a, a}}) {
        Eigen::VectorXd w = Eigen::VectorXd::Zero(c_count);
        w[left] = puppet.lower_bounds[left] +
                  wl * (puppet.upper_bounds[left] - puppet.lower_bounds[left]);
        w[right] = puppet.lower_bounds[right] +
                   wr * (puppet.upper_bounds[right] - puppet.lower_bounds[right]);
        poses.push_back(w);
      }
    }
  }
  // Range-of-motion clips: linear interpolation between random sparse keys.
  Eigen::VectorXd key = RandomSparsePose(puppet, options, rng);
  for (int clip = 0; clip < options.rom_clips; ++clip) {
    const Eigen::VectorXd next = RandomSparsePose(puppet, options, rng);
    for (int f = 1; f <= options.rom_clip_frames; ++f) {
      const double t = static_cast<double>(f) / options.rom_clip_frames;
      poses.push_back((1.0 - t) * key + t * next);
    }
    key = next;
  }
  for (int k = 0; k < options.random_combos; ++k)
    poses.push_back(RandomSparsePose(puppet, options, rng));
  Eigen::MatrixXd weights(c_count, static_cast<Eigen::Index>(poses.size()));
  for (size_t i = 0; i < poses.size(); ++i) weights.col(static_cast<Eigen::Index>(i)) = poses[i];
  return weights;
}

void FillMissingMarkers(const Puppet& puppet, const Eigen::Array<bool, Eigen::Dynamic, 1>& present,
                        Eigen::Ref<Eigen::VectorXd> stacked_markers, int neighbours) {
  const int m_count = puppet.marker_count();
  const Eigen::Matrix3Xd& neutral = puppet.neutral_markers_in_skull;
  std::vector<std::pair<double, int>> nearest;
  for (int m = 0; m < m_count; ++m) {
    if (present[m]) continue;
    nearest.clear();
    for (int o = 0; o < m_count; ++o) {
      if (present[o]) nearest.emplace_back((neutral.col(o) - neutral.col(m)).squaredNorm(), o);
    }
    Eigen::Vector3d delta = Eigen::Vector3d::Zero();
    const int k = std::min<int>(neighbours, static_cast<int>(nearest.size()));
    std::partial_sort(nearest.begin(), nearest.begin() + k, nearest.end());
    for (int i = 0; i < k; ++i) {
      const int o = nearest[i].second;
      delta += stacked_markers.segment<3>(3 * o) - neutral.col(o);
    }
    if (k > 0) delta /= k;
    stacked_markers.segment<3>(3 * m) = neutral.col(m) + delta;
  }
}

StatusOr<TrainingSet> MakeTrainingSet(const Puppet& puppet, const Eigen::MatrixXd& weights,
                                      const TrainingDataOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check().WithContext("training data options"));
  if (weights.rows() != puppet.channel_count() || weights.cols() == 0) {
    return InvalidArgumentError(
        fmt::format("training set: {} x {} weights for a puppet with {} channels", weights.rows(),
                    weights.cols(), puppet.channel_count()));
  }
  const Eigen::Index n = weights.cols();
  const int copies = 1 + options.augment_copies;
  const int m_count = puppet.marker_count();
  TrainingSet set;
  set.weights.resize(weights.rows(), n * copies);
  set.markers.resize(3 * m_count, n * copies);
  const Eigen::MatrixXd clean =
      (puppet.marker_basis_mm * weights).colwise() + puppet.StackedNeutral();
  std::mt19937_64 rng(options.seed ^ 0x9e3779b97f4a7c15ULL);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  Eigen::Array<bool, Eigen::Dynamic, 1> present(m_count);
  for (int copy = 0; copy < copies; ++copy) {
    for (Eigen::Index i = 0; i < n; ++i) {
      const Eigen::Index col = copy * n + i;
      set.weights.col(col) = weights.col(i);
      set.markers.col(col) = clean.col(i);
      if (copy == 0) continue;
      // Mask shift: uniform in the ball of radius mask_shift_mm (rejection sampling).
      Eigen::Vector3d shift;
      do {
        shift = Eigen::Vector3d(2 * unit(rng) - 1, 2 * unit(rng) - 1, 2 * unit(rng) - 1);
      } while (shift.squaredNorm() > 1.0);
      shift *= options.mask_shift_mm;
      bool any_missing = false;
      for (int m = 0; m < m_count; ++m) {
        present[m] = !(options.dropout > 0.0 && unit(rng) < options.dropout);
        any_missing |= !present[m];
        for (int a = 0; a < 3; ++a) {
          set.markers(3 * m + a, col) += shift[a] + options.noise_mm * normal(rng);
        }
      }
      if (any_missing) FillMissingMarkers(puppet, present, set.markers.col(col));
    }
  }
  return set;
}

std::vector<int> SelectSalientSamples(const Eigen::MatrixXd& markers, double threshold,
                                      double scale_mm) {
  std::vector<int> kept;
  if (markers.cols() == 0) return kept;
  kept.push_back(0);
  // s(i, j) < threshold  <=>  |x_i - x_j| > -scale * log(threshold).
  const double min_distance = -scale_mm * std::log(threshold);
  const double min_squared = min_distance * min_distance;
  for (Eigen::Index i = 1; i < markers.cols(); ++i) {
    bool similar = false;
    for (int j : kept) {
      const double d2 = (markers.col(i) - markers.col(j)).squaredNorm();
      if (d2 <= min_squared) {
        similar = true;
        break;
      }
    }
    if (!similar) kept.push_back(static_cast<int>(i));
  }
  return kept;
}

}  // namespace facedyn::solve
