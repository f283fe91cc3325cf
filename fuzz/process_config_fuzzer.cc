// LoadProcessConfig (process/process_config.h): PROCESS.yaml.
#include <cstddef>
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "process/process_config.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("process/input.yaml", data, size);
  const auto config = facedyn::process::LoadProcessConfig(path);
  // Accepted means usable: the graph builder relies on these.
  if (config.ok() && (config->takes.empty() || config->threads < 1 || config->removal.epochs < 1)) {
    __builtin_trap();
  }
  return 0;
}
