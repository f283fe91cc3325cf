#include "capture/recorder.h"

#include <chrono>

namespace facedyn::capture {

const char* BackpressurePolicyName(BackpressurePolicy policy) {
  return policy == BackpressurePolicy::kBlock ? "block" : "drop_newest";
}

StatusOr<BackpressurePolicy> ParseBackpressurePolicy(const std::string& name) {
  if (name == "block") return BackpressurePolicy::kBlock;
  if (name == "drop_newest") return BackpressurePolicy::kDropNewest;
  return InvalidArgumentError("backpressure '" + name + "' is not one of block, drop_newest");
}

Status RecorderOptions::Check() const {
  if (queue_frames < 1 || queue_frames > 4096) {
    return InvalidArgumentError("recorder queue_frames " + std::to_string(queue_frames) +
                                " is not in 1..4096");
  }
  if (!(block_timeout_s > 0)) return InvalidArgumentError("recorder block_timeout_s must be > 0");
  return Status::Ok();
}

Json CameraRecordStats::ToJson() const {
  return Json{{"frames_written", frames_written},
              {"bytes_written", bytes_written},
              {"dropped_queue_full", dropped_queue_full},
              {"discarded_after_error", discarded_after_error},
              {"max_queue_depth", max_queue_depth},
              {"error", error.empty() ? Json(nullptr) : Json(error)}};
}

StatusOr<std::unique_ptr<Recorder>> Recorder::Start(const RecorderOptions& options,
                                                    const std::vector<std::string>& file_paths,
                                                    BufferPool* pool) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<Recorder> recorder(new Recorder(options, pool));
  for (const std::string& path : file_paths) {
    auto queue = std::make_unique<Queue>();
    FACEDYN_ASSIGN_OR_RETURN(queue->writer, FrameFileWriter::Create(path));
    recorder->queues_.push_back(std::move(queue));
  }
  for (auto& queue : recorder->queues_) {
    Queue* q = queue.get();
    Recorder* self = recorder.get();
    q->thread = std::thread([self, q] { self->WriterLoop(q); });
  }
  return recorder;
}

Recorder::~Recorder() { (void)Finish(); }

void Recorder::SetErrorCallback(std::function<void(const Status&)> callback) {
  std::lock_guard<std::mutex> lock(error_mutex_);
  error_callback_ = std::move(callback);
}

PushResult Recorder::Push(int camera, Frame&& frame) {
  FACEDYN_CHECK(camera >= 0 && camera < camera_count(),
                "Recorder::Push: camera index out of range");
  if (failed_) return PushResult::kFailed;
  Queue& q = *queues_[camera];
  std::unique_lock<std::mutex> lock(q.mutex);
  const auto has_space = [&] {
    return static_cast<int>(q.frames.size()) < options_.queue_frames || q.closed || failed_;
  };
  if (!has_space()) {
    if (options_.policy == BackpressurePolicy::kBlock) {
      q.not_full.wait_for(lock, std::chrono::duration<double>(options_.block_timeout_s), has_space);
    }
  }
  if (failed_ || q.closed) return PushResult::kFailed;
  if (static_cast<int>(q.frames.size()) >= options_.queue_frames) {
    ++q.stats.dropped_queue_full;
    return PushResult::kDropped;
  }
  q.frames.push_back(std::move(frame));
  if (static_cast<int>(q.frames.size()) > q.stats.max_queue_depth)
    q.stats.max_queue_depth = static_cast<int>(q.frames.size());
  q.not_empty.notify_one();
  return PushResult::kQueued;
}

void Recorder::Fail(const Status& status) {
  std::function<void(const Status&)> callback;
  {
    std::lock_guard<std::mutex> lock(error_mutex_);
    if (failed_) return;
    first_error_ = status;
    failed_ = true;
    callback = error_callback_;
  }
  for (auto& queue : queues_) {  // wake blocked producers
    std::lock_guard<std::mutex> lock(queue->mutex);
    queue->not_full.notify_all();
  }
  if (callback) callback(status);
}

void Recorder::WriterLoop(Queue* q) {
  for (;;) {
    Frame frame;
    {
      std::unique_lock<std::mutex> lock(q->mutex);
      q->not_empty.wait(lock, [&] { return !q->frames.empty() || q->closed; });
      if (q->frames.empty()) return;  // closed and drained
      frame = std::move(q->frames.front());
      q->frames.pop_front();
      q->not_full.notify_one();
    }
    bool already_failed;
    {
      std::lock_guard<std::mutex> lock(q->mutex);
      already_failed = !q->stats.error.empty();
      if (already_failed) ++q->stats.discarded_after_error;
    }
    if (!already_failed) {
      Status status = q->writer->Append(frame);
      {
        std::lock_guard<std::mutex> lock(q->mutex);
        if (status.ok()) {
          ++q->stats.frames_written;
          q->stats.bytes_written = q->writer->bytes_committed();
        } else {
          q->stats.error = status.message();
          ++q->stats.discarded_after_error;
        }
      }
      if (!status.ok()) Fail(status);  // takes other locks: called without this queue's
    }
    if (pool_ != nullptr) pool_->Release(std::move(frame.pixels));
  }
}

Status Recorder::Finish() {
  if (finished_) {
    std::lock_guard<std::mutex> lock(error_mutex_);
    return first_error_;
  }
  finished_ = true;
  for (auto& queue : queues_) {
    std::lock_guard<std::mutex> lock(queue->mutex);
    queue->closed = true;
    queue->not_empty.notify_all();
    queue->not_full.notify_all();
  }
  Status close_error;
  for (auto& queue : queues_) {
    if (queue->thread.joinable()) queue->thread.join();
    Status status = queue->writer->Close(options_.sync_on_close);
    if (!status.ok() && close_error.ok()) close_error = status;
  }
  std::lock_guard<std::mutex> lock(error_mutex_);
  if (!first_error_.ok()) return first_error_;
  return close_error;
}

std::vector<CameraRecordStats> Recorder::stats() const {
  std::vector<CameraRecordStats> result;
  for (const auto& queue : queues_) {
    std::lock_guard<std::mutex> lock(queue->mutex);
    result.push_back(queue->stats);
  }
  return result;
}

}  // namespace facedyn::capture
