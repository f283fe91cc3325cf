// ReadPriorSweep (rig/sweep_resume.h): how `facedyn sweep --resume` interprets a session's
// rig_log.jsonl (step instances done and interrupted, exposure so far) for config/sweeps/demo.yaml.
// The JSON Lines layer has its own target (rig_log); this one reaches the record semantics.
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "rig/sweep.h"
#include "rig/sweep_resume.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const auto script =
      facedyn::rig::LoadSweepScript(facedyn::fuzz::SourcePath("config/sweeps/demo.yaml"));
  if (!script.ok()) __builtin_trap();  // the shipped sweep must load
  const int instances = static_cast<int>(script->InstanceCount());
  const std::string path = facedyn::fuzz::WriteScratchFile("resume/rig_log.jsonl", data, size);
  const auto prior = facedyn::rig::ReadPriorSweep(path, *script, instances);
  if (!prior.ok()) return 0;
  // Documented guarantees: every instance in range, exposure finite and non-negative.
  for (const auto& [instance, result] : prior->done) {
    if (instance < 0 || instance >= instances || result.instance != instance) __builtin_trap();
  }
  if (prior->interrupted < -1 || prior->interrupted >= instances) __builtin_trap();
  for (const double v : {prior->vibrating_s, prior->dose_m2_s3, prior->peak_rms_m_s2}) {
    if (!std::isfinite(v) || v < 0.0) __builtin_trap();
  }
  return 0;
}
