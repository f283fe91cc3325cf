// ModalSynthesisModel::Load (dynamics/modal_synthesis.h): the binary model file `facedyn
// dynamics remove | synthesize | retarget --model` reads, which may come from another machine or
// be cut short by a full disk.
#include <cstddef>
#include <cstdint>

#include "dynamics/modal_synthesis.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("modal.bin", data, size);
  const auto model = facedyn::dynamics::ModalSynthesisModel::Load(path);
  // A model the loader accepts must be consistent: W has one column per sample coordinate, and
  // the resonators lie below Nyquist.
  if (model.ok()) {
    if (model->weights().cols() != 3 * model->sample_count()) __builtin_trap();
    for (double hz : model->resonator_hz()) {
      if (!(hz > 0) || !(hz < model->fps() / 2)) __builtin_trap();
    }
  }
  return 0;
}
