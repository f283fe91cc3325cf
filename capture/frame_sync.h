// FrameSyncChecker: per-camera bookkeeping of which trigger pulses produced a frame.
//
// A dropped or misaligned frame corrupts the skin velocities the dynamics networks read, so
// every anomaly is classified, counted and reported (the session runner writes each one to
// events.jsonl); nothing is dropped silently. For each arriving frame:
//   kOk            first frame for its trigger, in order, timestamp within tolerance
//   kGap           first frame for its trigger but later triggers skipped before it: the
//                  skipped ones are provisionally missing (they may still arrive out of order)
//   kOutOfOrder    first frame for a trigger older than the newest one seen (fills a gap)
//   kDuplicate     a second frame for a trigger already seen (not recorded again)
//   kUnknownTrigger a trigger index that was never emitted (negative or beyond the last pulse)
// Independently, a frame whose timestamp differs from its trigger's time by more than
// `timestamp_tolerance_ns` counts as a timestamp mismatch (it is still recorded).
// Finish(emitted) turns every trigger without a frame into a final missing count.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/json_io.h"

namespace facedyn::capture {

enum class SyncVerdict { kOk, kGap, kOutOfOrder, kDuplicate, kUnknownTrigger };
const char* SyncVerdictName(SyncVerdict verdict);

struct SyncCounts {
  int64_t received = 0;  // every frame the camera delivered
  int64_t unique = 0;    // distinct valid triggers with a frame
  int64_t missing = 0;   // emitted triggers without a frame (final after Finish)
  int64_t duplicated = 0;
  int64_t out_of_order = 0;
  int64_t unknown_trigger = 0;
  int64_t timestamp_mismatch = 0;
  int64_t max_timestamp_error_ns = 0;  // over frames of known triggers

  bool Clean() const {
    return missing == 0 && duplicated == 0 && out_of_order == 0 && unknown_trigger == 0 &&
           timestamp_mismatch == 0;
  }
  Json ToJson() const;
};

struct SyncObservation {
  SyncVerdict verdict = SyncVerdict::kOk;
  int64_t gap_triggers = 0;  // for kGap: triggers skipped before this one
  bool timestamp_mismatch = false;
  int64_t timestamp_error_ns = 0;
  // True when the frame should be recorded (not a duplicate, not an unknown trigger).
  bool record = true;
};

class FrameSyncChecker {
 public:
  explicit FrameSyncChecker(int64_t timestamp_tolerance_ns)
      : tolerance_ns_(timestamp_tolerance_ns) {}

  // `emitted_so_far` pulses have been emitted when the frame is examined; `trigger_time_ns`
  // is the emitted time of the frame's trigger (ignored for unknown triggers).
  SyncObservation Observe(int64_t trigger_index, int64_t timestamp_ns, int64_t trigger_time_ns,
                          int64_t emitted_so_far);
  // Final accounting once `emitted` pulses are known to be all the take had.
  void Finish(int64_t emitted);

  const SyncCounts& counts() const { return counts_; }
  // Triggers without a frame, in order (valid after Finish).
  std::vector<int64_t> MissingTriggers(int64_t emitted) const;

 private:
  int64_t tolerance_ns_;
  std::vector<bool> seen_;
  int64_t newest_ = -1;
  SyncCounts counts_;
};

}  // namespace facedyn::capture
