// What `facedyn sweep --resume` reads back from a session's rig_log.jsonl: which step instances
// are done, which one was interrupted, and the vibration exposure so far. The log is outside
// input (a crash can tear it, a person can edit it), so every field is checked here and a bad
// record is an error naming it; nothing in it can make the resumed sweep skip a step that was not
// held, repeat one that was, or start with less exposure than the actor already has.
#pragma once

#include <cstdint>
#include <map>
#include <string>

#include "core/status.h"
#include "rig/sweep.h"

namespace facedyn::rig {

struct PriorSweep {
  bool started = false;                 // a sweep_start of this script was found
  bool finished = false;                // sweep_done
  std::map<int, SweepStepResult> done;  // instance -> result, each in [0, instance_count)
  int interrupted = -1;                 // a step_start without its step_done, or -1
  int64_t last_t_ns = 0;                // the log's latest timestamp (new records follow it)
  // Exposure at the end of the log: the largest value any record carries (exposure only grows,
  // so a smaller later value is a hand edit and must not lower the actor's dose).
  double vibrating_s = 0.0;
  double dose_m2_s3 = 0.0;
  double peak_rms_m_s2 = 0.0;
};

// Reads log_path for a resume of `script`, whose expansion has instance_count step instances.
// Errors: a record that is not an object with a string "event"; a mistyped or out-of-range
// field (instance outside the script, negative or non-finite exposure); a sweep_start of a
// different script (by hash); a step done twice; a non-empty log with no sweep_start. A torn
// last line (a crash mid-write) is reported by a warning and ignored.
StatusOr<PriorSweep> ReadPriorSweep(const std::string& log_path, const SweepScript& script,
                                    int instance_count);

}  // namespace facedyn::rig
