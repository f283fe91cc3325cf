// The capture stage of `facedyn demo`: a short simulated multi-view take recorded into
// <out_dir>/capture-session/ (replaced each run) and checked with CheckSession.
#pragma once

#include <string>

#include "capture/capture_config.h"
#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::app {

// Records 0.25 s (quick: 3 cameras at 640x512) or 1 s (8 cameras at 1280x1024) at 128 fps of
// the procedural face smiling on the 8 Hz platform, prints the take report and fills *metrics
// (may be null) with the take's JSON report plus "cameras", "session", "session_complete".
// Fails when the take or the session check is not complete.
Status RunCaptureDemoStage(const std::string& out_dir, bool quick, Json* metrics);

// Records one take of a simulated capture `config` into a new session at `session_dir` (removed
// first), prints its report and returns the take's folder. Errors: not a sim config, an
// incomplete take.
StatusOr<std::string> CaptureSimulatedTake(const capture::CaptureConfig& config,
                                           const std::string& session_dir,
                                           const std::string& take_name);

}  // namespace facedyn::app
