// Sizes and write times of what `facedyn export --format glb` and `facedyn view` produce for
// the take size the issue names: 3 s at 128 fps (384 frames) of a 9,409-vertex face (here a
// 97 x 97 grid patch with a 10 Hz jiggle and a slow expression drift; sizes depend only on the
// counts, times little on the motion). Prints JSON.
//
//   build/bench/export_bench [--seconds S] [--fps N] [--side N] [--dir DIR] [--keep]
// --keep leaves DIR/facedyn_export_bench_<pid>/{take.glb,view.html} (to open them).
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "bench/bench_flags.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/mesh_primitives.h"
#include "export/gltf_export.h"
#include "report/take_viewer.h"

namespace {

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

int main(int argc, char** argv) {
  using namespace facedyn;
  InitLogging(Verbosity::kQuiet);
  double seconds = 3.0, fps = 128.0;
  long long side = 97;
  std::string dir = "/tmp";
  bool keep = false;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--keep") {
      keep = true;
      continue;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "%s: %s needs a value\n", argv[0], flag.c_str());
      return 2;
    }
    if (flag == "--seconds") seconds = bench::FlagNumber(argv[0], flag, argv[++i]);
    else if (flag == "--fps") fps = bench::FlagNumber(argv[0], flag, argv[++i]);
    else if (flag == "--side") side = bench::FlagInteger(argv[0], flag, argv[++i]);
    else if (flag == "--dir") dir = argv[++i];
    else {
      std::fprintf(stderr, "%s: unknown flag %s (--seconds, --fps, --side, --dir, --keep)\n", argv[0], flag.c_str());
      return 2;
    }
  }
  if (side < 2 || !(seconds > 0) || !(fps > 0)) {
    std::fprintf(stderr, "%s: need --side >= 2, --seconds > 0, --fps > 0\n", argv[0]);
    return 2;
  }
  const int frames = std::max(1, static_cast<int>(std::lround(seconds * fps)));
  Take take;
  take.info.fps = fps;
  take.info.subject = "bench";
  take.topology = MakeEllipsoidPatch(80, 100, 90, 0.8, 0.8, static_cast<int>(side - 1), static_cast<int>(side - 1));
  const int v_count = take.topology.vertex_count();
  take.positions.vertex_count = v_count;
  take.positions.positions.resize(3 * v_count, frames);
  for (int f = 0; f < frames; ++f) {
    const double t = f / fps;
    Eigen::Matrix3Xd frame = take.topology.positions_mm;
    for (int v = 0; v < v_count; ++v) {
      const double x = frame(0, v), y = frame(1, v);
      frame(2, v) += 0.5 * std::sin(2 * M_PI * 10 * t + 0.01 * x) * std::exp(-(x * x + y * y) / 900.0) +
                     2.0 * std::sin(2 * M_PI * 0.5 * t) * (y < 0 ? -y / 60.0 : 0.0);
    }
    take.positions.Frame(f) = frame.cast<float>();
    take.time_s.push_back(f / fps);
    take.world_from_skull.push_back(Rigid3::Identity());
  }
  const std::string out_dir = dir + "/facedyn_export_bench_" + std::to_string(::getpid());
  std::filesystem::create_directories(out_dir);
  Json out;
  out["take"] = {{"vertices", v_count}, {"frames", frames}, {"fps", fps}, {"seconds", frames / fps}};

  auto start = std::chrono::steady_clock::now();
  const auto glb = WriteTakeGlb(take, out_dir + "/take.glb");
  if (!glb.ok()) {
    std::fprintf(stderr, "export_bench: %s\n", glb.status().message().c_str());
    return 1;
  }
  out["glb"] = {{"bytes", glb->bytes}, {"megabytes", glb->bytes / 1e6}, {"write_s", SecondsSince(start)},
                {"bytes_per_vertex_frame", static_cast<double>(glb->bytes) / (static_cast<double>(v_count) * frames)}};

  start = std::chrono::steady_clock::now();
  const auto page = report::WriteTakeViewer({{"bench", take}}, report::ViewerOptions(), out_dir + "/view.html");
  if (!page.ok()) {
    std::fprintf(stderr, "export_bench: %s\n", page.status().message().c_str());
    return 1;
  }
  out["viewer"] = {{"bytes", page->bytes}, {"megabytes", page->bytes / 1e6}, {"write_s", SecondsSince(start)},
                   {"limit_megabytes", 40.0}, {"under_limit", page->bytes < 40e6}};
  if (keep) {
    out["dir"] = out_dir;
  } else {
    std::filesystem::remove_all(out_dir);
  }
  std::printf("%s\n", out.dump(2).c_str());
  return 0;
}
