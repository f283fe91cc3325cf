// Which frames training, validation and metrics use (dynamics/training_frames.h).

#include "dynamics/training_frames.h"

#include <gtest/gtest.h>

#include <map>
#include <random>
#include <set>

#include "core/mesh_primitives.h"

namespace facedyn::dynamics {
namespace {

Take EmptyTake(int frames, double fps) {
  Take take;
  take.info.fps = fps;
  take.topology = MakeEllipsoidPatch(10, 10, 10, 1.0, 0.8, 2, 2);
  take.positions.vertex_count = take.topology.vertex_count();
  take.positions.positions.setZero(3 * take.positions.vertex_count, frames);
  return take;
}

TEST(UsableFrames, MarginsFirstVelocityAndHoldStart) {
  Take take = EmptyTake(100, 128.0);
  // Window [t - 10, t + 10] inside the take and starting at frame 1 or later.
  FrameRange range = UsableFrames(take, 10, true);
  EXPECT_EQ(range.begin, 11);
  EXPECT_EQ(range.end, 90);
  // Hold start 0.25 s = frame 32 exactly, 0.251 s rounds up to 33.
  take.info.hold_start_s = 0.25;
  EXPECT_EQ(FirstHeldFrame(take), 32);
  EXPECT_EQ(UsableFrames(take, 10, true).begin, 42);
  EXPECT_EQ(UsableFrames(take, 10, false).begin, 11);  // exact targets ignore the hold
  EXPECT_EQ(ScoredFrames(take, 10).begin, 42);
  take.info.hold_start_s = 0.251;
  EXPECT_EQ(FirstHeldFrame(take), 33);
  // Nothing left: empty, never reversed.
  take.info.hold_start_s = 10.0;
  EXPECT_EQ(FirstHeldFrame(take), 100);
  EXPECT_TRUE(UsableFrames(take, 10, true).empty());
  EXPECT_EQ(UsableFrames(EmptyTake(15, 128.0), 10, false).size(), 0);
  // ... and its bounds are frames of the take, so a metric over it stays in range (the range
  // was [110, 110) of a 100-frame take).
  for (const FrameRange empty : {UsableFrames(take, 10, true),
                                 UsableFrames(EmptyTake(15, 128.0), 10, false)}) {
    EXPECT_GE(empty.begin, 0);
    EXPECT_LE(empty.end, 100);
    EXPECT_EQ(empty.begin, empty.end);
  }
  EXPECT_LE(UsableFrames(EmptyTake(15, 128.0), 10, false).end, 15);
}

// The property the split exists for: no validation frame within 2w frames of a training frame
// of the same take, so no validation window shares a slot with a training window. Checked over
// random take lengths, fractions and seeds, with the parameters TrainRemoval uses.
TEST(SplitByBlocks, NoValidationFrameNearATrainingFrameOfTheSameTake) {
  std::mt19937 rng(3);
  for (int round = 0; round < 200; ++round) {
    const int w = 1 + static_cast<int>(rng() % 16);
    std::vector<FrameRange> ranges;
    long usable = 0;
    const int takes = 1 + static_cast<int>(rng() % 6);
    for (int k = 0; k < takes; ++k) {
      const int begin = static_cast<int>(rng() % 50);
      const int size = static_cast<int>(rng() % 400);
      ranges.push_back({begin, begin + size});
      usable += size;
    }
    const double fraction = 0.05 * static_cast<double>(rng() % 10);
    const FrameSplit split = SplitByBlocks(ranges, fraction, ValidationBlockFrames(w),
                                           ValidationGapFrames(w), rng());
    std::map<int, std::set<int>> validation;
    for (const auto& [take, frame] : split.validation) {
      ASSERT_TRUE(ranges[take].Contains(frame));
      validation[take].insert(frame);
    }
    for (const auto& [take, frame] : split.train) {
      ASSERT_TRUE(ranges[take].Contains(frame));
      const std::set<int>& near = validation[take];
      const auto it = near.lower_bound(frame - 2 * w);
      ASSERT_TRUE(it == near.end() || *it > frame + 2 * w)
          << "training frame " << frame << " of take " << take << " is within " << 2 * w
          << " frames of validation frame " << *it;
    }
    // Validation stays within twice the fraction, and reaches it when the fraction is at least
    // one block (fraction <= 0.45, so there are always enough blocks).
    const double wanted = fraction * static_cast<double>(usable);
    EXPECT_LE(static_cast<double>(split.validation.size()), 2 * wanted);
    if (wanted >= ValidationBlockFrames(w)) {
      EXPECT_GE(static_cast<double>(split.validation.size()), wanted);
    }
    if (fraction == 0) {
      EXPECT_TRUE(split.validation.empty());
    }
  }
}

TEST(SplitByBlocks, BlocksAreContiguousAndSeeded) {
  const std::vector<FrameRange> ranges = {{10, 330}, {10, 330}};  // 8 blocks of 40 each
  const FrameSplit a = SplitByBlocks(ranges, 0.1, 40, 20, 1);
  const FrameSplit b = SplitByBlocks(ranges, 0.1, 40, 20, 1);
  EXPECT_EQ(a.validation, b.validation);
  EXPECT_EQ(a.train, b.train);
  // 640 usable frames, 10%: two blocks of 40 (one is not enough), each contiguous.
  ASSERT_EQ(a.validation.size(), 80u);
  for (size_t i = 1; i < a.validation.size(); ++i) {
    if (i % 40 != 0) {
      EXPECT_EQ(a.validation[i].first, a.validation[i - 1].first);
      EXPECT_EQ(a.validation[i].second, a.validation[i - 1].second + 1);
    }
  }
  // Each validation block costs its 40 frames plus up to 20 on each side.
  EXPECT_GE(a.train.size(), 640u - 80u - 4 * 20u);
  // A take too short for a block of validation keeps its frames for training.
  const FrameSplit short_take = SplitByBlocks({{11, 70}}, 0.1, 40, 20, 1);
  EXPECT_TRUE(short_take.validation.empty());
  EXPECT_EQ(short_take.train.size(), 59u);
  bool differs = false;
  for (uint64_t seed = 2; seed < 6 && !differs; ++seed) {
    differs = SplitByBlocks(ranges, 0.1, 40, 20, seed).validation != a.validation;
  }
  EXPECT_TRUE(differs);
}

TEST(WeightedFrames, RepeatsWholeWeightsAndDrawsASeededFraction) {
  std::vector<TakeFrame> frames;
  for (int t = 0; t < 10; ++t) frames.emplace_back(0, t);
  for (int t = 0; t < 20; ++t) frames.emplace_back(1, t);
  // Weight 1 everywhere is the input itself, in its order.
  EXPECT_EQ(WeightedFrames(frames, {1.0, 1.0}, 3), frames);
  const std::vector<TakeFrame> weighted = WeightedFrames(frames, {2.0, 0.25}, 3);
  std::map<TakeFrame, int> count;
  for (const TakeFrame& frame : weighted) ++count[frame];
  long take0 = 0, take1 = 0;
  for (const auto& [frame, n] : count) {
    if (frame.first == 0) {
      EXPECT_EQ(n, 2) << frame.second;
      take0 += n;
    } else {
      EXPECT_EQ(n, 1) << frame.second;
      take1 += n;
    }
  }
  EXPECT_EQ(take0, 20);
  EXPECT_EQ(take1, 5);  // round(0.25 * 20)
  EXPECT_EQ(WeightedFrames(frames, {2.0, 0.25}, 3), weighted);
  EXPECT_NE(WeightedFrames(frames, {2.0, 0.25}, 4), weighted);
}

}  // namespace
}  // namespace facedyn::dynamics
