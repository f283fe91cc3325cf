// The simulated drive's request handling (sim/drive_sim.h), without sockets: a sequence of
// request PDUs, each decoded by DecodeAcceptedWrite as DriveSim::Answer decodes it, applied to
// a DriveModel with ApplyDriveWrite, the model advanced 50 ms, and the register map refreshed
// with RefreshDriveRegisters. The input is records of one length byte and that many PDU bytes;
// the first byte picks the drive profile (config/drives/*.yaml).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "fuzz/drive_profiles.h"
#include "fuzz/fuzz_util.h"
#include "rig/drive_profile.h"
#include "sim/drive_sim.h"

using facedyn::fuzz::ShippedDriveProfiles;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const auto& profiles = ShippedDriveProfiles();
  const facedyn::rig::DriveProfile& profile = profiles[data[0] % profiles.size()];
  const int register_count = profile.MaxRegister() + 1;
  std::vector<uint16_t> registers(static_cast<size_t>(register_count), 0);
  facedyn::sim::DriveModelOptions options;
  options.watchdog_s = 1.0;
  options.watchdog_fault_code = 10;
  facedyn::sim::DriveModel model(options);
  size_t at = 1;
  while (at < size) {
    const size_t length = std::min<size_t>(data[at], size - at - 1);
    const uint8_t* pdu = data + at + 1;
    at += 1 + length;
    const auto write =
        facedyn::sim::DecodeAcceptedWrite(pdu, static_cast<int>(length), register_count);
    if (write) {
      if (write->values.empty() ||
          write->address + static_cast<int>(write->values.size()) > register_count) {
        __builtin_trap();  // an accepted write lies inside the register map
      }
      for (size_t i = 0; i < write->values.size(); ++i) {
        registers[static_cast<size_t>(write->address) + i] = write->values[i];
      }
      facedyn::sim::ApplyDriveWrite(profile, *write, &model);
    }
    model.NoteRequest();
    model.Advance(0.05);
    facedyn::sim::RefreshDriveRegisters(profile, model, registers.data(), register_count);
  }
  return 0;
}
