// LoadSweepScript (rig/sweep.h): config/sweeps/*.yaml, checked against the simulated rig's
// limits as `facedyn sweep` does before anything moves.
#include <cstddef>
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "rig/rig_config.h"
#include "rig/sweep.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const auto rig = facedyn::rig::LoadRigConfig(
      facedyn::fuzz::SourcePath("config/rigs/sim-tcp.yaml"));
  if (!rig.ok()) __builtin_trap();  // the shipped rig must load
  const std::string path = facedyn::fuzz::WriteScratchFile("sweeps/input.yaml", data, size);
  const auto script = facedyn::rig::LoadSweepScript(path);
  if (!script.ok()) return 0;
  (void)script->InstanceCount();
  (void)script->MinimumDurationS();
  (void)script->CheckAgainst(*rig);
  return 0;
}
