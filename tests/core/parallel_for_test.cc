// ParallelFor: every index once, the lowest failing index's error, no work after an error.
#include "core/parallel_for.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace facedyn {
namespace {

using ::testing::HasSubstr;

TEST(ParallelForTest, RunsEveryIndexExactlyOnce) {
  for (int threads : {1, 2, 3, 8}) {
    std::vector<std::atomic<int>> runs(1000);
    const Status status = ParallelFor(1000, threads, [&](int i) {
      runs[i].fetch_add(1);
      return Status::Ok();
    });
    ASSERT_TRUE(status.ok()) << status.message();
    for (int i = 0; i < 1000; ++i)
      EXPECT_EQ(runs[i].load(), 1) << "index " << i << ", threads " << threads;
  }
}

TEST(ParallelForTest, UsesSeveralThreadsWhenAsked) {
  std::mutex mutex;
  std::vector<std::thread::id> ids;
  std::atomic<int> waiting{0};
  const Status status = ParallelFor(2, 2, [&](int) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      ids.push_back(std::this_thread::get_id());
    }
    // Both items are in flight at once only if two threads run them: wait (bounded) for the
    // other one, so a single-threaded implementation fails instead of hanging.
    waiting.fetch_add(1);
    for (int spin = 0; spin < 2000 && waiting.load() < 2; ++spin)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    return Status::Ok();
  });
  ASSERT_TRUE(status.ok());
  ASSERT_EQ(ids.size(), 2u);
  EXPECT_NE(ids[0], ids[1]);
}

TEST(ParallelForTest, ZeroItemsIsOk) {
  bool called = false;
  EXPECT_TRUE(ParallelFor(0, 2, [&](int) {
                called = true;
                return Status::Ok();
              }).ok());
  EXPECT_FALSE(called);
}

TEST(ParallelForTest, ReturnsTheLowestFailingIndexsError) {
  const Status status = ParallelFor(100000, 2, [&](int i) {
    if (i == 7 || i == 9) return InvalidArgumentError("item " + std::to_string(i) + " is bad");
    return Status::Ok();
  });
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  // Index 9 may fail before 7 reports, but 7 always runs (indices are handed out in order and a
  // handed-out index always runs), and the lower index's error wins.
  EXPECT_THAT(status.message(), HasSubstr("item 7 is bad"));
}

TEST(ParallelForTest, StopsHandingOutWorkAfterAnError) {
  int ran = 0;  // one thread: the calling thread, in index order
  const Status status = ParallelFor(1000, 1, [&](int i) {
    ++ran;
    return i == 7 ? InvalidArgumentError("item 7 is bad") : Status::Ok();
  });
  EXPECT_FALSE(status.ok());
  EXPECT_EQ(ran, 8);
}

TEST(ParallelForTest, ThreadCountIsBoundedByTheItems) {
  EXPECT_EQ(ParallelThreadCount(8, 3), 3);
  EXPECT_EQ(ParallelThreadCount(2, 100), 2);
  EXPECT_GE(ParallelThreadCount(0, 100), 1);
  EXPECT_EQ(ParallelThreadCount(4, 0), 1);
}

}  // namespace
}  // namespace facedyn
