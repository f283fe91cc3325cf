// LoadTake (core/take.h) with an arbitrary take.json beside a small valid take (12 vertices,
// 4 frames, written once per process): the metadata parser and the cross-file checks that
// compare take.json's counts, fps and channels with the other files.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include "core/file_util.h"
#include "core/mesh_primitives.h"
#include "core/take.h"
#include "fuzz/fuzz_util.h"

namespace {

const std::string& TakeDir() {
  static const std::string dir = [] {
    facedyn::Take take;
    take.info.fps = 30.0;
    take.info.subject = "fuzz";
    take.info.expression = "neutral";
    take.info.motion = "none";
    take.info.source = "fuzz";
    take.topology = facedyn::MakeEllipsoidPatch(60, 80, 50, 0.8, 0.6, 3, 2);
    const int frames = 4;
    take.positions.vertex_count = take.topology.vertex_count();
    take.positions.positions.resize(3 * take.positions.vertex_count, frames);
    for (int f = 0; f < frames; ++f) {
      take.positions.Frame(f) = take.topology.positions_mm.cast<float>();
    }
    take.SetUniformTimes();
    take.world_from_skull.assign(frames, facedyn::Rigid3::Identity());
    take.channels["quasistatic"] = take.positions;
    const std::string out = facedyn::fuzz::ScratchDir() + "/take";
    const facedyn::Status saved = facedyn::SaveTake(take, out);
    if (!saved.ok()) {
      std::fprintf(stderr, "cannot write the fuzz take: %s\n", saved.ToString().c_str());
      std::abort();
    }
    return out;
  }();
  return dir;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string& dir = TakeDir();
  facedyn::fuzz::WriteScratchFile("take/take.json", data, size);
  const auto take = facedyn::LoadTake(dir);
  if (take.ok()) {
    if (!take->Validate().ok()) __builtin_trap();  // documented: loading validates
    (void)facedyn::FirstHeldFrame(*take);
  }
  return 0;
}
