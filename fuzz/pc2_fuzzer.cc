// ReadPc2 (core/pc2.h) on arbitrary bytes: a Take's positions.pc2 and every <channel>.pc2.
#include <cstddef>
#include <cstdint>

#include "core/pc2.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("input.pc2", data, size);
  const auto cache = facedyn::ReadPc2(path);
  if (!cache.ok()) return 0;
  // A cache that was accepted must be usable as the header says: every frame mapped in full.
  volatile float sum = 0.0f;
  for (int f = 0; f < cache->frame_count(); ++f) sum = sum + cache->Frame(f).sum();
  return 0;
}
