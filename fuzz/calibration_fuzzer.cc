// ReadCameraModels (capture/camera_model.h): a session's calibration.yaml (OpenCV FileStorage
// YAML, written by `facedyn calibrate`), which CAPTURE.yaml and reconstruct read.
#include <cstddef>
#include <cstdint>

#include "capture/camera_model.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("calibration.yaml", data, size);
  const auto cameras = facedyn::capture::ReadCameraModels(path);
  if (cameras.ok()) {
    for (const auto& camera : *cameras) {
      if (!camera.Check().ok()) __builtin_trap();  // documented: each camera is checked
    }
  }
  return 0;
}
