// Frequency sweeps: a YAML script of steps (platform frequency, settle, hold, the prompt for the
// actor — typically the expression to hold — and repeats), validated in full against the rig's
// limits before the platform moves, then run step by step through a RigSupervisor with every
// event in the session's JSON Lines log.
//
// The log is also the sweep's state: each completed step instance writes one "step_done"
// record, so `--resume` after a crash (even kill -9) re-reads the log, checks the script is the
// one the session started with (FNV-1a hash of its text), skips every completed instance and
// continues with the first one that has no "step_done" — an interrupted step is redone from its
// start, and no completed step is ever repeated.
//
// Script format (config/sweeps/*.yaml):
//
//   name: paper-protocol
//   rig: ../rigs/sim-tcp.yaml        # optional; `facedyn sweep --rig` overrides
//   defaults: {settle_timeout_s: 30, settle_s: 2, hold_s: 10, repeats: 1}
//   steps:                           # explicit steps, run in order ...
//     - {hz: 6, prompt: "neutral", hold_s: 8}
//   grid:                            # ... and/or a frequencies x prompts grid appended after them
//     frequencies_hz: [6, 7, 8, 9, 10, 11]
//     prompts: [neutral, smile]
//     order: prompt_major           # or frequency_major
//
// Per step: hz (required), settle_timeout_s (fail if the platform has not settled by then),
// settle_s (extra dwell after settling, before the hold), hold_s (> 0), prompt, repeats (>= 1).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/config_node.h"
#include "core/json_io.h"
#include "core/status.h"
#include "rig/rig_config.h"
#include "rig/supervisor.h"

namespace facedyn::rig {

struct SweepStep {
  double hz = 0.0;
  double settle_timeout_s = 30.0;
  double settle_s = 0.0;
  double hold_s = 10.0;
  std::string prompt;
  int repeats = 1;
  int line = 0;  // source line, for messages
};

struct SweepScript {
  std::string name;
  std::string description;
  std::string source_path;
  std::string rig_path;          // resolved against the script's folder; "" when not given
  std::vector<SweepStep> steps;  // grid already expanded, in run order
  uint64_t text_hash = 0;        // FNV-1a of the file's bytes

  // Number of step instances (steps times their repeats), counted in int64.
  int64_t InstanceCount() const;
  // Checks the instance cap (100,000) and every step against the rig's limits; names the step
  // and field.
  Status CheckAgainst(const RigConfig& rig) const;
  // Sum of settle dwells and holds, a lower bound on the running time.
  double MinimumDurationS() const;
};

StatusOr<SweepScript> LoadSweepScript(const std::string& path);
StatusOr<SweepScript> ParseSweepScript(const ConfigNode& root, const std::string& base_dir,
                                       uint64_t text_hash);

// One step instance as the runner and its hooks see it.
struct SweepStepInfo {
  int instance = 0;  // 0-based position in the expanded sweep
  int instance_count = 0;
  int step = 0;    // index into SweepScript::steps
  int repeat = 0;  // 0-based
  SweepStep spec;
};

// What during_hold gets besides its step.
struct HoldWork {
  const std::atomic<bool>* abort = nullptr;    // never null inside during_hold
  std::function<PlatformSnapshot()> platform;  // the supervisor's last reading (thread-safe)
};

// Per-step hooks, e.g. for the capture module to record one take per step. on_hold_start runs
// once the platform has settled (and dwelt settle_s), right before the hold; on_hold_end right
// after it, with how well the frequency was held. Both run on the supervisor's thread, which
// does not tick while they run: they must return at once (bookkeeping, a marker).
// during_hold is for work that takes time (recording a take): it runs on a thread of its own
// during the hold while the supervisor keeps the platform supervised (HoldDuring): the hold
// lasts hold_s and until during_hold returns, at most max_hold_s; `abort` becomes true when
// the supervisor stops the platform (trip, overspeed, stop request, lost link), and
// during_hold must then return promptly (a take keeps what it recorded). A failed hook ramps
// the platform to a stop and ends the sweep with that error; the step is then not marked
// done, so --resume redoes it.
struct SweepHooks {
  std::function<Status(const SweepStepInfo&)> on_hold_start;
  std::function<Status(const SweepStepInfo&, const HoldWork&)> during_hold;
  std::function<Status(const SweepStepInfo&, const HoldSummary&)> on_hold_end;
  double max_hold_s = 600.0;  // bound on a hold that waits for during_hold
  // Asked (on --resume) for each step not yet marked done, before the platform moves: true
  // when the step's work was completed by an earlier run that died before its "step_done"
  // (a kill between the end of a take and the log record). The step is then marked done,
  // "recovered", and not run again.
  std::function<bool(const SweepStepInfo&)> already_done;
};

struct SweepOptions {
  std::string session_dir;
  bool resume = false;
  SweepHooks hooks;
  const std::atomic<bool>* stop_requested = nullptr;  // SIGINT/SIGTERM flag
  bool print_prompts = true;                          // "[3/12] 8.00 Hz  hold: smile" on stdout

  Status Check() const;
};

struct SweepStepResult {
  int instance = 0;
  double target_hz = 0.0;
  std::string prompt;
  HoldSummary hold;
  bool this_run = false;  // false: completed before a --resume
};

struct SweepResult {
  std::string log_path;
  std::string summary_path;
  int skipped = 0;                     // instances already done before --resume
  std::vector<SweepStepResult> steps;  // every completed instance, in order
  Json exposure;

  Json ToJson() const;
};

// Runs (or resumes) the sweep in options.session_dir: rig_log.jsonl is the journal,
// sweep_summary.json the result. The script is validated against the rig before anything
// moves. Ends with the platform stopped, whatever happens.
StatusOr<SweepResult> RunSweep(const SweepScript& script, const RigConfig& rig,
                               const SweepOptions& options);

}  // namespace facedyn::rig
