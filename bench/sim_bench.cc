// sim_bench: how long `facedyn sim perform` takes for a 3 s, 128 fps platform take (dynamic +
// quasistatic), on the procedural face and optionally the ICT-FaceKit face region, next to
// the machine's own dense GEMM rate measured in the same run (machines are shared and noisy:
// compare ratios, not absolute seconds). Prints JSON on stdout.
//
// "twin_perform" (issue 23's speed figure: a 3 s twin take at 128 fps within the simulator's
// own 10 s budget): the procedural face nodding (2 Hz, 15 degrees) for --seconds at 128 fps,
// as `sim perform` builds it (material calibrated by an eigensolve) and as `twin perform` does
// (an explicit material: here the calibrated one, so both simulate the same face), alternated
// max(3, --repeats) times; medians and the ratio of the whole SimulatePerformance call.
//
//   sim_bench [--ict DIR] [--seconds S] [--repeats N]

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "bench/bench_flags.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/progress.h"
#include "physics/soft_tissue.h"
#include "sim/ict_import.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"

namespace {

using facedyn::Json;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); }

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// Dense double GEMM rate (GFLOP/s) of this machine, single call of 512^3, median of 5.
double GemmGflops() {
  const int n = 512;
  Eigen::MatrixXd a = Eigen::MatrixXd::Random(n, n), b = Eigen::MatrixXd::Random(n, n), c(n, n);
  std::vector<double> rates;
  for (int i = 0; i < 5; ++i) {
    const auto start = Clock::now();
    c.noalias() = a * b;
    rates.push_back(2.0 * n * n * n / Seconds(start) / 1e9);
  }
  return Median(rates) + 0 * c(0, 0);
}

Json BenchFace(const std::string& label, const facedyn::FaceRig& rig, double generate_s, double seconds, int repeats) {
  facedyn::sim::PerformanceOptions options;
  options.expression = "neutral";
  options.motion.platform_hz = 11.0;
  options.seconds = seconds;
  options.fps = 128;
  std::vector<double> times;
  Json peaks;
  facedyn::sim::PerformanceSummary summary;
  int frames = 0;
  for (int r = 0; r < repeats; ++r) {
    const auto start = Clock::now();
    auto take = facedyn::sim::SimulatePerformance(rig, options, &summary);
    times.push_back(Seconds(start));
    if (!take.ok()) return {{"face", label}, {"error", take.status().message()}};
    frames = take->frame_count();
    auto region_peaks = facedyn::sim::PeakOffsetByRegionMm(rig, *take);
    if (region_peaks.ok()) peaks = *region_peaks;
  }
  return {{"face", label},
          {"vertices", rig.vertex_count()},
          {"face_build_s", generate_s},
          {"take_seconds", seconds},
          {"frames", frames},
          {"substeps_per_frame", summary.substeps_per_frame},
          {"simulate_s_median", Median(times)},
          {"simulate_s_all", times},
          {"peak_offset_mm_by_region_11hz", peaks}};
}

// sim perform's path against twin perform's on the same material (see the header).
Json BenchTwinPerform(const facedyn::FaceRig& rig, double seconds, int repeats) {
  facedyn::sim::PerformanceOptions options;
  options.expression = "neutral";
  options.motion.kind = facedyn::sim::MotionKind::kNod;
  options.seconds = seconds;
  options.fps = 128;
  auto model = facedyn::physics::SoftTissueModel::Create(rig, options.tissue);
  if (!model.ok()) return {{"error", model.status().message()}};
  const facedyn::physics::TissueMaterial material = (*model)->material();
  model->reset();
  std::vector<double> calibrated_s, explicit_s;
  for (int r = 0; r < repeats; ++r) {
    for (bool twin : {false, true}) {
      facedyn::sim::PerformanceOptions run = options;
      if (twin) run.material = material;
      const auto start = Clock::now();
      auto take = facedyn::sim::SimulatePerformance(rig, run);
      (twin ? explicit_s : calibrated_s).push_back(Seconds(start));
      if (!take.ok()) return {{"error", take.status().message()}};
    }
  }
  return {{"motion", "nod 2 Hz 15 deg"},
          {"take_seconds", seconds},
          {"fps", 128},
          {"sim_perform_s_median", Median(calibrated_s)},
          {"twin_perform_s_median", Median(explicit_s)},
          {"twin_over_sim", Median(explicit_s) / Median(calibrated_s)},
          {"sim_perform_s_all", calibrated_s},
          {"twin_perform_s_all", explicit_s},
          {"budget_s", 10.0}};
}

}  // namespace

int main(int argc, char** argv) {
  std::string ict_dir;
  double seconds = 3.0;
  int repeats = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--ict" && i + 1 < argc) ict_dir = argv[++i];
    else if (arg == "--seconds" && i + 1 < argc) seconds = facedyn::bench::FlagNumber("sim_bench", arg, argv[++i]);
    else if (arg == "--repeats" && i + 1 < argc) repeats = std::max(
          1, static_cast<int>(facedyn::bench::FlagInteger("sim_bench", arg, argv[++i])));
    else {
      std::fprintf(stderr, "usage: sim_bench [--ict DIR] [--seconds S] [--repeats N]\n");
      return 2;
    }
  }
  facedyn::InitLogging(facedyn::Verbosity::kQuiet);
  facedyn::SetDefaultProgressMode(facedyn::ProgressMode::kSilent);
  Json out;
  out["gemm_gflops_512"] = GemmGflops();
  Json faces = Json::array();
  auto start = Clock::now();
  auto procedural = facedyn::sim::MakeProceduralFace(facedyn::sim::ProceduralFaceOptions());
  if (!procedural.ok()) {
    std::fprintf(stderr, "%s\n", procedural.status().message().c_str());
    return 1;
  }
  faces.push_back(BenchFace("procedural", *procedural, Seconds(start), seconds, repeats));
  out["twin_perform"] = BenchTwinPerform(*procedural, seconds, std::max(3, repeats));
  if (!ict_dir.empty()) {
    facedyn::sim::IctImportOptions options;
    options.dir = ict_dir;
    start = Clock::now();
    auto ict = facedyn::sim::ImportIctFaceKit(options);
    if (!ict.ok()) {
      std::fprintf(stderr, "%s\n", ict.status().message().c_str());
      return 1;
    }
    faces.push_back(BenchFace("ict", *ict, Seconds(start), seconds, repeats));
  }
  out["faces"] = faces;
  std::printf("%s\n", out.dump(2).c_str());
  return 0;
}
