// A process-wide "stop requested" flag set by SIGINT and SIGTERM, for the rig's control loops:
// RigSupervisor polls it every few milliseconds and ramps the platform to a stop. The handler
// only stores to a lock-free atomic, which is async-signal-safe.
#pragma once

#include <atomic>

namespace facedyn::rig {

// Installs the handlers (idempotent) and returns the flag they set.
const std::atomic<bool>* InstallStopSignalHandlers();
// For tests and for commands that handle a stop and carry on.
void ClearStopRequest();

}  // namespace facedyn::rig
