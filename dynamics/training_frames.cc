#include "dynamics/training_frames.h"

#include <algorithm>
#include <cmath>
#include <random>

#include "core/check.h"

namespace facedyn::dynamics {

FrameRange UsableFrames(const Take& take, int margin_frames, bool held_only) {
  FACEDYN_CHECK(margin_frames >= 0, "UsableFrames: negative margin");
  const int frames = take.frame_count();
  const int first_window_start = std::max(1, held_only ? FirstHeldFrame(take) : 0);
  FrameRange range;
  range.begin = first_window_start + margin_frames;
  range.end = frames - margin_frames;
  // Nothing usable: an empty range whose bounds are still frames of the take, so a caller that
  // loops or indexes over it stays in range.
  if (range.end < range.begin) range.begin = range.end = std::clamp(range.end, 0, frames);
  return range;
}

int ValidationBlockFrames(int window_frames) {
  return std::max(2 * window_frames + 1, 4 * window_frames);
}

FrameSplit SplitByBlocks(const std::vector<FrameRange>& usable_per_take, double fraction,
                         int block_frames, int gap_frames, uint64_t seed) {
  FACEDYN_CHECK(fraction >= 0 && fraction < 1, "SplitByBlocks: fraction out of [0, 1)");
  FACEDYN_CHECK(block_frames >= 1 && gap_frames >= 0, "SplitByBlocks: bad block or gap");
  struct Block {
    int take, begin, end;
  };
  std::vector<Block> blocks;
  long total = 0;
  for (size_t k = 0; k < usable_per_take.size(); ++k) {
    const FrameRange& range = usable_per_take[k];
    total += range.size();
    for (int b = range.begin; b < range.end; b += block_frames) {
      blocks.push_back({static_cast<int>(k), b, std::min(range.end, b + block_frames)});
    }
  }
  std::vector<char> is_validation(blocks.size(), 0);
  if (fraction > 0 && blocks.size() >= 2) {
    std::vector<size_t> order(blocks.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::mt19937_64 rng(seed);
    std::shuffle(order.begin(), order.end(), rng);
    const double wanted = fraction * static_cast<double>(total);
    long chosen = 0;
    // A block that would take validation past twice the fraction is passed over: on a short
    // take one block (plus its gaps) could otherwise leave nothing to train on.
    for (size_t i : order) {
      if (static_cast<double>(chosen) >= wanted) break;
      const long size = blocks[i].end - blocks[i].begin;
      if (static_cast<double>(chosen + size) > 2 * wanted) continue;
      is_validation[i] = 1;
      chosen += size;
    }
  }
  FrameSplit split;
  for (size_t k = 0; k < usable_per_take.size(); ++k) {
    const FrameRange& range = usable_per_take[k];
    // This take's validation frames, and the frames within the gap of one (not trained on).
    std::vector<char> excluded(static_cast<size_t>(range.size()), 0);
    std::vector<char> validation(static_cast<size_t>(range.size()), 0);
    for (size_t i = 0; i < blocks.size(); ++i) {
      if (!is_validation[i] || blocks[i].take != static_cast<int>(k)) continue;
      for (int t = blocks[i].begin; t < blocks[i].end; ++t) validation[t - range.begin] = 1;
      const int lo = std::max(range.begin, blocks[i].begin - gap_frames);
      const int hi = std::min(range.end, blocks[i].end + gap_frames);
      for (int t = lo; t < hi; ++t) excluded[t - range.begin] = 1;
    }
    for (int t = range.begin; t < range.end; ++t) {
      const size_t i = static_cast<size_t>(t - range.begin);
      if (validation[i]) {
        split.validation.emplace_back(static_cast<int>(k), t);
      } else if (!excluded[i]) {
        split.train.emplace_back(static_cast<int>(k), t);
      }
    }
  }
  return split;
}

std::vector<TakeFrame> WeightedFrames(const std::vector<TakeFrame>& frames,
                                      const std::vector<double>& weights, uint64_t seed) {
  for (double weight : weights) {
    FACEDYN_CHECK(std::isfinite(weight) && weight > 0, "WeightedFrames: weight must be > 0");
  }
  std::vector<std::vector<TakeFrame>> per_take(weights.size());
  for (const TakeFrame& frame : frames) {
    FACEDYN_CHECK(frame.first >= 0 && frame.first < static_cast<int>(weights.size()),
                  "WeightedFrames: frame of an unknown take");
    per_take[frame.first].push_back(frame);
  }
  std::vector<TakeFrame> out;
  std::mt19937_64 rng(seed ^ 0x9e3779b97f4a7c15ULL);  // apart from the validation split's draw
  for (size_t k = 0; k < weights.size(); ++k) {
    const std::vector<TakeFrame>& take = per_take[k];
    const double whole = std::floor(weights[k]);
    for (int r = 0; r < static_cast<int>(whole); ++r)
      out.insert(out.end(), take.begin(), take.end());
    const size_t extra =
        static_cast<size_t>(std::lround((weights[k] - whole) * static_cast<double>(take.size())));
    if (extra == 0) continue;
    std::vector<size_t> order(take.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::shuffle(order.begin(), order.end(), rng);
    order.resize(extra);
    std::sort(order.begin(), order.end());
    for (size_t i : order) out.push_back(take[i]);
  }
  return out;
}

}  // namespace facedyn::dynamics
