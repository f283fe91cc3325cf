// ReadTransformCsv (core/take.h): a Take's skull.csv and jaw.csv.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/take.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("skull.csv", data, size);
  std::vector<double> time_s;
  std::vector<facedyn::Rigid3> transforms;
  const facedyn::Status status = facedyn::ReadTransformCsv(path, &time_s, &transforms);
  if (status.ok() && time_s.size() != transforms.size()) __builtin_trap();
  return 0;
}
