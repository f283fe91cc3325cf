// ReadMdd (export/mdd.h) on arbitrary bytes: a point cache a studio tool exported as MDD.
#include <cstddef>
#include <cstdint>

#include "export/mdd.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("input.mdd", data, size);
  const auto cache = facedyn::ReadMdd(path);
  if (!cache.ok()) return 0;
  // What an accepted cache promises: one time per frame, never decreasing, every frame mapped in
  // full with finite values.
  if (cache->time_s.size() != static_cast<size_t>(cache->points.frame_count())) __builtin_trap();
  for (size_t f = 1; f < cache->time_s.size(); ++f) {
    if (!(cache->time_s[f] >= cache->time_s[f - 1])) __builtin_trap();
  }
  for (int f = 0; f < cache->points.frame_count(); ++f) {
    // allFinite, not a sum: finite coordinates near FLT_MAX sum to inf (the first run's
    // "finding" was this check).
    if (!cache->points.Frame(f).allFinite()) __builtin_trap();
  }
  return 0;
}
