// Training tuples (weights, markers) from the puppet (FDLS section 4.1 and supplementary
// section 7) and salient-sample selection (section 4.2, Eq. 3).
//
// Weights: every channel alone swept 0..1 (the "one-hot" FACS animation); every left/right pair
// together and each side with the other at half (symmetric and asymmetric); range-of-motion
// sweeps (random pairs of poses linearly interpolated, as the paper's ROM clips do between
// keys); random sparse combinations of a few channels. The jaw channels join the sparse
// combinations with probability 1/2 so that every region sees its shapes over an open jaw.
// Markers: the puppet's, then augmented: isotropic Gaussian noise per marker, a small rigid
// shift of the whole mask (a mask placed differently on another day, section 4.4.2), and
// dropout (a marker lost by tracking, refilled the way a solve refills it: FillMissingMarkers).
// Everything is drawn from one seeded std::mt19937_64, so a seed gives the same set.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/status.h"
#include "solve/puppet.h"

namespace facedyn::solve {

struct TrainingDataOptions {
  uint64_t seed = 1;
  int sweep_steps = 10;           // poses per single-channel sweep (weights k/steps, k = 1..steps)
  int rom_clips = 60;             // range-of-motion clips between random sparse poses
  int rom_clip_frames = 12;       // frames per clip
  int random_combos = 2000;       // random sparse combinations
  int max_active_channels = 4;    // channels active in one random combination (1..)
  int augment_copies = 2;         // augmented copies of every pose (0: clean poses only)
  double noise_mm = 0.05;         // sd of the per-marker Gaussian noise of the copies
  double mask_shift_mm = 0.3;     // radius of the rigid mask shift of the copies
  double dropout = 0.0;           // probability that a copy loses a marker (refilled)
  std::vector<int> jaw_channels;  // joined to random combinations with probability 1/2
  // Sizes and probabilities in range; the message names the field.
  Status Check() const;
};

struct TrainingSet {
  Eigen::MatrixXd weights;  // C x N, each within the puppet's bounds
  Eigen::MatrixXd markers;  // 3M x N, skull frame, mm (stacked as Puppet::StackedMarkers)
  int sample_count() const { return static_cast<int>(weights.cols()); }
};

// The clean training poses (C x N) of section 4.1.
StatusOr<Eigen::MatrixXd> MakeTrainingWeights(const Puppet& puppet,
                                              const TrainingDataOptions& options);

// Markers for the poses: the clean set, then `augment_copies` noisy copies of every pose.
StatusOr<TrainingSet> MakeTrainingSet(const Puppet& puppet, const Eigen::MatrixXd& weights,
                                      const TrainingDataOptions& options);

// Missing markers (present(m) false) of one stacked frame refilled with the neutral position
// plus the mean delta of the `neighbours` nearest present markers (nearest on the neutral).
// With no present marker the frame is left at neutral for the missing ones.
void FillMissingMarkers(const Puppet& puppet, const Eigen::Array<bool, Eigen::Dynamic, 1>& present,
                        Eigen::Ref<Eigen::VectorXd> stacked_markers, int neighbours = 3);

// Salient-sample selection, Eq. (3) of FDLS: walk the samples in order and keep sample i when
// its largest similarity to any kept sample is below `threshold`, with the exponential RBF
// similarity s(i, j) = exp(-|x_i - x_j| / scale_mm) on the stacked markers (3M x N). Returns
// the kept column indices (ascending; the first sample is always kept). threshold in (0, 1]:
// 1 keeps every sample that is not an exact duplicate.
std::vector<int> SelectSalientSamples(const Eigen::MatrixXd& markers, double threshold,
                                      double scale_mm);

}  // namespace facedyn::solve
