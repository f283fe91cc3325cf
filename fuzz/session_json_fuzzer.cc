// ReadSession and CheckSession (capture/session.h): a session folder's session.json and one
// take's takes/t1/capture.json. The input is session.json, optionally followed by a line
// "=== capture.json ===" and the take's manifest.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "capture/session.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  static const std::string kSeparator = "\n=== capture.json ===\n";
  const size_t split = input.find(kSeparator);
  const std::string dir = facedyn::fuzz::ScratchDir() + "/session";
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  facedyn::fuzz::WriteScratchFile("session/session.json", input.substr(0, split));
  facedyn::fuzz::WriteScratchFile("session/events.jsonl", "{\"event\":\"session_open\"}\n");
  if (split != std::string::npos) {
    facedyn::fuzz::WriteScratchFile("session/takes/t1/capture.json",
                                    input.substr(split + kSeparator.size()));
  }
  const auto info = facedyn::capture::ReadSession(dir);
  const auto check = facedyn::capture::CheckSession(dir);
  if (check.ok()) {
    (void)check->ToJson().dump();
    (void)check->ToText();
  }
  (void)info;
  return 0;
}
