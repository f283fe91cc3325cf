// CheckSession (capture/session.h) reading an arbitrary events.jsonl, the session's
// append-only event log, in a session folder written by SessionWriter (one camera, no takes).
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include "capture/session.h"
#include "fuzz/fuzz_util.h"

namespace {

const std::string& SessionDir() {
  static const std::string dir = [] {
    const std::string out = facedyn::fuzz::ScratchDir() + "/session";
    facedyn::capture::SessionCameraInfo camera;
    camera.name = "cam0";
    camera.backend = "sim";
    camera.width_px = 32;
    camera.height_px = 16;
    auto writer = facedyn::capture::SessionWriter::Open(out, "virtual", {camera},
                                                        facedyn::Json::object());
    if (!writer.ok()) {
      std::fprintf(stderr, "cannot write the fuzz session: %s\n",
                   writer.status().ToString().c_str());
      std::abort();
    }
    return out;
  }();
  return dir;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string& dir = SessionDir();
  facedyn::fuzz::WriteScratchFile("session/events.jsonl", data, size);
  const auto check = facedyn::capture::CheckSession(dir);
  if (check.ok()) {
    (void)check->ToJson().dump();
    (void)check->ToText();
  }
  return 0;
}
