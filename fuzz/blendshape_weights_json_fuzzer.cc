// ReadBlendshapeWeightsJson (core/blendshape_weights.h): the JSON twin of a solve's weights,
// which `facedyn solve apply --weights W.json` and `facedyn export --weights` read (and other
// tools may write).
#include <cstddef>
#include <cstdint>

#include "core/blendshape_weights.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("weights.json", data, size);
  const auto track = facedyn::ReadBlendshapeWeightsJson(path);
  // What the reader accepts must be a valid track (the exporter and DriveRig rely on it).
  if (track.ok() && !track->Validate().ok()) __builtin_trap();
  return 0;
}
