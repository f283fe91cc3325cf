#include "capture/frame_sync.h"

#include <gtest/gtest.h>

#include "capture/trigger.h"

namespace facedyn::capture {
namespace {

constexpr double kRate = 128.0;
int64_t T(int64_t k) { return VirtualTrigger::PulseTimeNs(k, kRate); }

TEST(FrameSyncChecker, CleanSequence) {
  FrameSyncChecker checker(1000);
  for (int k = 0; k < 10; ++k)
    EXPECT_EQ(checker.Observe(k, T(k), T(k), 10).verdict, SyncVerdict::kOk);
  checker.Finish(10);
  EXPECT_TRUE(checker.counts().Clean());
  EXPECT_EQ(checker.counts().unique, 10);
}

TEST(FrameSyncChecker, CountsMissingDuplicateOutOfOrderAndUnknown) {
  FrameSyncChecker checker(1000);
  // Arrival order: 0 1 3 2 3 5 7 (99 never emitted); 4 and 6 never arrive, 8 and 9 neither.
  EXPECT_EQ(checker.Observe(0, T(0), T(0), 10).verdict, SyncVerdict::kOk);
  EXPECT_EQ(checker.Observe(1, T(1), T(1), 10).verdict, SyncVerdict::kOk);
  const SyncObservation gap = checker.Observe(3, T(3), T(3), 10);
  EXPECT_EQ(gap.verdict, SyncVerdict::kGap);
  EXPECT_EQ(gap.gap_triggers, 1);
  EXPECT_EQ(checker.Observe(2, T(2), T(2), 10).verdict, SyncVerdict::kOutOfOrder);
  const SyncObservation duplicate = checker.Observe(3, T(3), T(3), 10);
  EXPECT_EQ(duplicate.verdict, SyncVerdict::kDuplicate);
  EXPECT_FALSE(duplicate.record);
  EXPECT_EQ(checker.Observe(5, T(5), T(5), 10).verdict, SyncVerdict::kGap);
  EXPECT_EQ(checker.Observe(7, T(7) + 5000, T(7), 10).verdict, SyncVerdict::kGap);
  EXPECT_EQ(checker.Observe(99, 0, 0, 10).verdict, SyncVerdict::kUnknownTrigger);
  checker.Finish(10);
  const SyncCounts& counts = checker.counts();
  EXPECT_EQ(counts.received, 8);
  EXPECT_EQ(counts.unique, 6);
  EXPECT_EQ(counts.missing, 4);  // 4, 6, 8, 9
  EXPECT_EQ(counts.duplicated, 1);
  EXPECT_EQ(counts.out_of_order, 1);
  EXPECT_EQ(counts.unknown_trigger, 1);
  EXPECT_EQ(counts.timestamp_mismatch, 1);
  EXPECT_EQ(counts.max_timestamp_error_ns, 5000);
  EXPECT_EQ(checker.MissingTriggers(10), (std::vector<int64_t>{4, 6, 8, 9}));
  EXPECT_FALSE(counts.Clean());
}

TEST(VirtualTrigger, EmitsExactTimesAndStops) {
  VirtualTrigger trigger({128.0, 0.0});
  std::vector<TriggerEvent> events;
  ASSERT_TRUE(trigger
                  .Run(256,
                       [&](const TriggerEvent& e) {
                         events.push_back(e);
                         return Status::Ok();
                       })
                  .ok());
  ASSERT_EQ(events.size(), 256u);
  EXPECT_EQ(events[128].time_ns, 1000000000);
  EXPECT_EQ(events[1].time_ns, 7812500);
  Status stopped = trigger.Run(100, [&](const TriggerEvent& e) {
    if (e.index == 9) trigger.Stop();
    return Status::Ok();
  });
  EXPECT_EQ(stopped.code(), StatusCode::kAborted);
  EXPECT_EQ(trigger.emitted(), 10);
  Status failed = trigger.Run(100, [&](const TriggerEvent& e) {
    return e.index == 4 ? UnavailableError("camera 2 gone") : Status::Ok();
  });
  EXPECT_EQ(failed.message(), "camera 2 gone");
  EXPECT_FALSE((VirtualTriggerOptions{0.0, 0.0}.Check().ok()));
}

}  // namespace
}  // namespace facedyn::capture
