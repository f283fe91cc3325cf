// Which frames of a take a network trains on, validates on, and is scored on.
//
// Two things make a frame unusable, and both are explicit here rather than folded into a
// fixed "skip the first 10 frames":
//   - the window margins: a frame whose feature (or target-estimate) window reaches past either
//     end reads replicated edge frames (features.h's end-of-take policy), and the first frame's
//     velocity is zero by that policy, so a window must start at frame 1 or later to carry a
//     real velocity in every slot;
//   - the held part of the take: a held-expression target (the moving average of Eq. 5, the
//     platform-synchronous fit) assumes the expression is held and the motion steady, which is
//     false while the expression forms (take.json's hold_start_s, core/take.h). Frames whose
//     window reaches before it are left out wherever such a target is used, and from every
//     metric, so a baseline is not charged for smearing an onset nobody trains on.
//
// Validation is split by contiguous blocks of frames, not by single frames: neighbouring frames
// 7.8 ms apart share all but one of their 2w+1 window slots, so a random-frame split measures
// interpolation. Training frames within `gap_frames` of a validation frame of the same take
// are dropped, so no validation window overlaps a training window when gap_frames >= 2w.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "core/take.h"

namespace facedyn::dynamics {

// Frames [begin, end) of one take.
struct FrameRange {
  int begin = 0;
  int end = 0;
  int size() const { return end > begin ? end - begin : 0; }
  bool empty() const { return size() == 0; }
  bool Contains(int frame) const { return frame >= begin && frame < end; }
};

// Frames whose [t - margin, t + margin] window lies inside the take and starts at frame 1 or
// later (a real velocity in every slot); with `held_only` also at or after the first held frame
// (FirstHeldFrame). Empty when nothing is left.
FrameRange UsableFrames(const Take& take, int margin_frames, bool held_only);

// The frames every metric uses: UsableFrames(take, margin_frames, held_only = true).
inline FrameRange ScoredFrames(const Take& take, int margin_frames) {
  return UsableFrames(take, margin_frames, true);
}

// (take index, frame) pairs.
using TakeFrame = std::pair<int, int>;

struct FrameSplit {
  std::vector<TakeFrame> train;
  std::vector<TakeFrame> validation;
};

// Splits each take's usable frames into contiguous blocks of `block_frames` (the last block of
// a take may be shorter), draws blocks in a seeded order until at least `fraction` of all
// usable frames are validation frames, passing over any block that would take validation past
// twice the fraction (so takes too short for a block get no validation rather than no
// training), and drops every training frame within `gap_frames` of a validation frame of the
// same take. fraction 0 puts everything in train. Preconditions (CHECKed): fraction in
// [0, 1), block_frames >= 1, gap_frames >= 0, ranges.size() == number of takes.
FrameSplit SplitByBlocks(const std::vector<FrameRange>& usable_per_take, double fraction,
                         int block_frames, int gap_frames, uint64_t seed);

// Training frames repeated by their take's weight (weights[take] finite, > 0, one per take;
// CHECKed): every frame of take k appears floor(w_k) times, and a seeded choice of
// round(frac(w_k) * n_k) of its n_k frames once more, so a take of weight 0.5 contributes half
// its frames and one of weight 2 each frame twice. Order: by take, then the input's order.
std::vector<TakeFrame> WeightedFrames(const std::vector<TakeFrame>& frames,
                                      const std::vector<double>& weights, uint64_t seed);

// Block length and gap for a window of w frames: blocks of max(2w + 1, 4w) frames, gap 2w.
int ValidationBlockFrames(int window_frames);
inline int ValidationGapFrames(int window_frames) { return 2 * window_frames; }

}  // namespace facedyn::dynamics
