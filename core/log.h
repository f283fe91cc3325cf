// Logging through spdlog. Messages go to stderr so stdout stays clean for --json output.
// Levels: --quiet shows warnings and errors only, the default shows info, --verbose debug.
#pragma once

#include <spdlog/spdlog.h>

namespace facedyn {

enum class Verbosity { kQuiet, kNormal, kVerbose };

// Sets up the process-wide logger ("facedyn", stderr, coloured on a terminal) and the
// default progress mode. Call once from main(); safe to call again to change the level.
void InitLogging(Verbosity verbosity);
Verbosity CurrentVerbosity();

}  // namespace facedyn
