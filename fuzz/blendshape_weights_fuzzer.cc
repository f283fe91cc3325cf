// ReadBlendshapeWeightsCsv (core/blendshape_weights.h): a solve's weights over time, which
// `facedyn export --rig ... --weights` reads (and other tools may write).
#include <cstddef>
#include <cstdint>

#include "core/blendshape_weights.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("weights.csv", data, size);
  const auto track = facedyn::ReadBlendshapeWeightsCsv(path);
  // What the reader accepts must be a valid track (the exporter relies on it).
  if (track.ok() && !track->Validate().ok()) __builtin_trap();
  return 0;
}
