// ReadSessionLog (rig/session_log.h): the rig's rig_log.jsonl journal, which
// `facedyn sweep --resume` reads back.
#include <cstddef>
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "rig/session_log.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("rig_log.jsonl", data, size);
  bool truncated = false;
  const auto records = facedyn::rig::ReadSessionLog(path, &truncated);
  if (records.ok()) {
    for (const auto& record : *records) {
      if (!record.is_object()) __builtin_trap();  // documented: every record is an object
    }
  }
  return 0;
}
