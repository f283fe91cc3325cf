// The rig stage of `facedyn demo`: the simulated drive and platform behind a real Modbus TCP
// server on a free loopback port, driven through the RigSupervisor by a short scripted sweep
// (config/sweeps/demo.yaml on config/rigs/sim-tcp.yaml).
#pragma once

#include <string>

#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::app {

// Runs the demo sweep, journals it in <out_dir>/rig-session/ (rig_log.jsonl,
// sweep_summary.json; a previous demo's two files there are replaced), prints one line per
// step with the requested, measured and true platform frequency, and fills *metrics (may be
// null) with {"steps": [...], "max_abs_error_hz", "worst_steady_state_error_hz", "exposure",
// "log"}. `quick` shortens the holds. The config folder is found through $FACEDYN_CONFIG_DIR,
// else ../../config or ../config next to the executable (the build tree), else ./config.
Status RunRigDemoStage(const std::string& out_dir, bool quick, Json* metrics);

// The shipped config folder (drives/, rigs/, sweeps/), searched as described above.
StatusOr<std::string> FindConfigDir();

}  // namespace facedyn::app
