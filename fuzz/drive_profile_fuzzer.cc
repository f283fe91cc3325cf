// LoadDriveProfile (rig/drive_profile.h): config/drives/*.yaml, a user may add their own. An
// accepted profile is then used the way the client and the simulated drive use it: scalings
// both ways, status-word and fault-code decoding, fault text.
#include <cstddef>
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "rig/drive_profile.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("drives/input.yaml", data, size);
  const auto profile = facedyn::rig::LoadDriveProfile(path);
  if (!profile.ok()) return 0;
  (void)profile->MaxRegister();
  for (const uint16_t word : {0x0000, 0x0001, 0x00FF, 0x7FFF, 0x8000, 0xFFFF}) {
    (void)profile->IsRunning(word);
    (void)profile->IsFaultBitSet(word);
    (void)profile->DescribeFault(profile->FaultCodeFrom(word));
    (void)profile->setpoint_scaling.RegisterToHz(word);
    (void)profile->output_scaling.RegisterToHz(word);
    (void)profile->oscillation_scaling.RegisterToHz(word);
  }
  for (const double hz : {0.0, 6.0, 11.0, 50.0, 1e6, -1.0}) {
    (void)profile->setpoint_scaling.HzToRegister(hz, "setpoint");
    (void)profile->output_scaling.HzToRegister(hz, "output");
  }
  return 0;
}
