// LoadCaptureConfig (capture/capture_config.h): CAPTURE.yaml, written beside a copy of
// config/capture so relative references resolve as in the tree.
#include <cstddef>
#include <cstdint>

#include "capture/capture_config.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  facedyn::fuzz::CopyConfigFolder("capture");
  const std::string path = facedyn::fuzz::WriteScratchFile("capture/input.yaml", data, size);
  const auto config = facedyn::capture::LoadCaptureConfig(path);
  if (config.ok() && !config->Check().ok()) __builtin_trap();  // accepted means checked
  return 0;
}
