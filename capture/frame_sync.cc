#include "capture/frame_sync.h"

#include <cstdlib>

namespace facedyn::capture {

const char* SyncVerdictName(SyncVerdict verdict) {
  switch (verdict) {
    case SyncVerdict::kOk:
      return "ok";
    case SyncVerdict::kGap:
      return "gap";
    case SyncVerdict::kOutOfOrder:
      return "out_of_order";
    case SyncVerdict::kDuplicate:
      return "duplicate";
    case SyncVerdict::kUnknownTrigger:
      return "unknown_trigger";
  }
  return "unknown";
}

Json SyncCounts::ToJson() const {
  return Json{{"received", received},
              {"unique", unique},
              {"missing", missing},
              {"duplicated", duplicated},
              {"out_of_order", out_of_order},
              {"unknown_trigger", unknown_trigger},
              {"timestamp_mismatch", timestamp_mismatch},
              {"max_timestamp_error_ns", max_timestamp_error_ns}};
}

SyncObservation FrameSyncChecker::Observe(int64_t trigger_index, int64_t timestamp_ns,
                                          int64_t trigger_time_ns, int64_t emitted_so_far) {
  SyncObservation observation;
  ++counts_.received;
  if (trigger_index < 0 || trigger_index >= emitted_so_far) {
    ++counts_.unknown_trigger;
    observation.verdict = SyncVerdict::kUnknownTrigger;
    observation.record = false;
    return observation;
  }
  if (static_cast<int64_t>(seen_.size()) <= trigger_index) seen_.resize(trigger_index + 1, false);
  observation.timestamp_error_ns = timestamp_ns - trigger_time_ns;
  const int64_t abs_error = std::llabs(observation.timestamp_error_ns);
  if (abs_error > counts_.max_timestamp_error_ns) counts_.max_timestamp_error_ns = abs_error;
  if (abs_error > tolerance_ns_) {
    observation.timestamp_mismatch = true;
    ++counts_.timestamp_mismatch;
  }
  if (seen_[trigger_index]) {
    ++counts_.duplicated;
    observation.verdict = SyncVerdict::kDuplicate;
    observation.record = false;
    return observation;
  }
  seen_[trigger_index] = true;
  ++counts_.unique;
  if (trigger_index < newest_) {
    ++counts_.out_of_order;
    observation.verdict = SyncVerdict::kOutOfOrder;
  } else {
    if (trigger_index > newest_ + 1) {
      observation.verdict = SyncVerdict::kGap;
      observation.gap_triggers = trigger_index - newest_ - 1;
    }
    newest_ = trigger_index;
  }
  return observation;
}

void FrameSyncChecker::Finish(int64_t emitted) {
  int64_t missing = 0;
  for (int64_t k = 0; k < emitted; ++k) {
    if (k >= static_cast<int64_t>(seen_.size()) || !seen_[k]) ++missing;
  }
  counts_.missing = missing;
}

std::vector<int64_t> FrameSyncChecker::MissingTriggers(int64_t emitted) const {
  std::vector<int64_t> missing;
  for (int64_t k = 0; k < emitted; ++k) {
    if (k >= static_cast<int64_t>(seen_.size()) || !seen_[k]) missing.push_back(k);
  }
  return missing;
}

}  // namespace facedyn::capture
