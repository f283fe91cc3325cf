// A process-wide "stop requested" flag set by SIGINT, SIGTERM, SIGHUP (the terminal closed)
// and SIGQUIT (Ctrl-\), for the rig's control loops: RigSupervisor polls it every few
// milliseconds and ramps the platform to a stop. The handler only stores to a lock-free
// atomic, which is async-signal-safe. SIGPIPE is ignored, so a reader of stdout that goes away
// makes writes fail with EPIPE instead of killing facedyn without a stop (some drive profiles
// have no comm watchdog to fall back on).
#pragma once

#include <atomic>

namespace facedyn::rig {

// The signals that request a stop.
extern const int kStopSignals[4];
// Installs the handlers (idempotent), ignores SIGPIPE, and returns the flag they set.
const std::atomic<bool>* InstallStopSignalHandlers();
// For tests and for commands that handle a stop and carry on.
void ClearStopRequest();

}  // namespace facedyn::rig
