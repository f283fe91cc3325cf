// LoadMarkerTracks (core/marker_tracks.h): a take's marker_tracks.csv.
#include <cstddef>
#include <cstdint>

#include "core/marker_tracks.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path =
      facedyn::fuzz::WriteScratchFile("marker_tracks/marker_tracks.csv", data, size);
  const std::string dir = path.substr(0, path.rfind('/'));
  const auto tracks = facedyn::LoadMarkerTracks(dir);
  if (tracks.ok() && !tracks->Validate().ok()) __builtin_trap();  // accepted means consistent
  return 0;
}
