// LoadRigConfig (rig/rig_config.h): RIG.yaml. The input is written to rigs/input.yaml beside a
// copy of config/drives, so a "drive_profile: ../drives/sim.yaml" reference resolves.
#include <cstddef>
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "rig/rig_config.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  facedyn::fuzz::CopyConfigFolder("drives");
  const std::string path = facedyn::fuzz::WriteScratchFile("rigs/input.yaml", data, size);
  const auto rig = facedyn::rig::LoadRigConfig(path);
  if (rig.ok()) {
    if (!rig->Check().ok()) __builtin_trap();  // loading checks; an accepted rig passes
    (void)rig->MotorLimits().Check();
  }
  return 0;
}
