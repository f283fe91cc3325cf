#include "core/parallel_for.h"

#include <algorithm>
#include <atomic>
#include <mutex>
#include <thread>
#include <vector>

namespace facedyn {

int ParallelThreadCount(int threads, int count) {
  if (threads <= 0) threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  return std::max(1, std::min(threads, count));
}

Status ParallelFor(int count, int threads, const std::function<Status(int index)>& body) {
  if (count <= 0) return Status::Ok();
  threads = ParallelThreadCount(threads, count);
  std::atomic<int> next{0};
  std::atomic<bool> failed{false};
  std::mutex mutex;
  int failed_index = count;
  Status first_error;
  auto work = [&] {
    while (!failed.load(std::memory_order_relaxed)) {
      const int index = next.fetch_add(1);
      if (index >= count) return;
      Status status = body(index);
      if (!status.ok()) {
        std::lock_guard<std::mutex> lock(mutex);
        if (index < failed_index) {
          failed_index = index;
          first_error = std::move(status);
        }
        failed.store(true, std::memory_order_relaxed);
      }
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(threads - 1);
  for (int t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& thread : pool) thread.join();
  return failed_index < count ? first_error : Status::Ok();
}

}  // namespace facedyn
