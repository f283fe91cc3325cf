// MasqueradeModel::Load (detail/masquerade.h): the binary model file `facedyn detail apply`
// reads, which may come from another machine or be cut short by a full disk.
#include <cstddef>
#include <cstdint>

#include "detail/masquerade.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("model.bin", data, size);
  const auto model = facedyn::detail::MasqueradeModel::Load(path);
  // A model the loader accepts must be consistent enough to describe itself.
  if (model.ok() && model->vertex_count() < 0) __builtin_trap();
  return 0;
}
