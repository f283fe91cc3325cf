// `facedyn demo`: the main job on the simulated stage.
//
// Today (foundation) it exercises the data path every later stage uses: it builds a small
// Take from a procedural surface carried by a rigidly oscillating head (platform motion,
// no soft tissue yet), saves it, reloads it, checks the reload is bit-identical, exports it
// as OBJ frames and PC2, and says which stages will join. Each later stage extends it.

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "app/capture_demo.h"
#include "app/command.h"
#include "app/dynamics_study.h"
#include "app/face_render.h"
#include "app/reconstruct_demo.h"
#include "app/report.h"
#include "app/rig_demo.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "core/mesh_primitives.h"
#include "core/take.h"
#include "core/take_export.h"
#include "core/take_summary.h"
#include "dynamics/evaluate.h"
#include "dynamics/removal_model.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"

namespace facedyn::app {
namespace {

struct DemoOptions {
  std::string out_dir = "facedyn-demo";
  bool quick = false;
};

// A head-sized surface on a platform oscillating vertically at `platform_hz`, with the
// small pitch a real platform adds. Rigid: secondary dynamics arrive with sim/ physics.
Take MakeRigidPlatformTake(double platform_hz, double fps, int frame_count) {
  Take take;
  take.info.fps = fps;
  take.info.subject = "procedural-patch";
  take.info.expression = "neutral";
  take.info.motion = "platform";
  take.info.platform_hz = platform_hz;
  take.info.source = "demo (rigid, no soft tissue)";
  take.topology = MakeEllipsoidPatch(75.0, 95.0, 90.0, 1.2, 1.0, 32, 32);
  constexpr double kAmplitudeMm = 2.0;
  constexpr double kPitchDeg = 0.5;
  const int v = take.topology.vertex_count();
  take.positions.vertex_count = v;
  take.positions.positions.resize(3 * v, frame_count);
  for (int f = 0; f < frame_count; ++f) {
    const double phase = 2 * M_PI * platform_hz * f / fps;
    const Rigid3 world_from_skull =
        Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), kPitchDeg * M_PI / 180 * std::sin(phase),
                              Eigen::Vector3d(0, kAmplitudeMm * std::sin(phase), 0));
    take.world_from_skull.push_back(world_from_skull);
    take.positions.Frame(f) = world_from_skull.Apply(take.topology.positions_mm).cast<float>();
  }
  take.SetUniformTimes();
  return take;
}

// Positions of frame t in the skull frame (3 x V): T(t)^-1 x(t).
Eigen::Matrix3Xf InSkull(const Take& take, const PointCache& cache, int t) {
  return take.world_from_skull[t].Inverse().Apply(cache.Frame(t).cast<double>()).cast<float>();
}

// Renders of the first held-out test take at two extremal frames of its oscillation (the
// frame of largest mean true offset in the second half, and half a platform period later):
// coloured by signed offset from the exact quasistatic before and after removal, and the
// synthesised dynamics on the removed take. PNGs under <out>/renders; returns their metadata.
StatusOr<Json> RenderDynamics(const DynamicsStudyArtifacts& artifacts, const std::string& out_dir) {
  const Take& take = artifacts.test_take;
  const PointCache& truth = take.channels.at("quasistatic");
  const PointCache& true_offsets = take.channels.at("dynamic_offset");
  const int frames = take.frame_count();
  const int skip = static_cast<int>(std::lround(0.08 * take.info.fps));
  int peak = frames / 2;
  double best = -1;
  for (int t = frames / 2; t < frames - skip; ++t) {
    const double mean = true_offsets.Frame(t).colwise().norm().mean();
    if (mean > best) best = mean, peak = t;
  }
  const double hz = take.info.platform_hz.value_or(11.0);
  const int half_period = std::max(1, static_cast<int>(std::lround(take.info.fps / (2 * hz))));
  std::vector<int> chosen = {peak, std::min(frames - 1, peak + half_period)};
  const std::string dir = JoinPath(out_dir, "renders");
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(dir));
  Json renders = Json::array();
  for (int t : chosen) {
    const Eigen::Matrix3Xf truth_in_skull = InSkull(take, truth, t);
    const Eigen::Matrix3Xf dynamic_in_skull = InSkull(take, take.positions, t);
    const Eigen::Matrix3Xf removed_in_skull =
        InSkull(artifacts.removed, artifacts.removed.positions, t);
    struct View {
      std::string name;
      Eigen::Matrix3Xf positions, offsets;
    };
    std::vector<View> views = {
        {"captured (dynamic) - exact quasistatic", dynamic_in_skull,
         dynamic_in_skull - truth_in_skull},
        {"after removal - exact quasistatic", removed_in_skull, removed_in_skull - truth_in_skull}};
    if (artifacts.resynthesised.frame_count() == frames) {
      const Eigen::Matrix3Xf synth_in_skull =
          InSkull(artifacts.resynthesised, artifacts.resynthesised.positions, t);
      views.push_back(
          {"resynthesised - removed", synth_in_skull, synth_in_skull - removed_in_skull});
    }
    for (size_t k = 0; k < views.size(); ++k) {
      const std::vector<unsigned char> png =
          RenderSignedOffsetPng(take.topology, views[k].positions, views[k].offsets);
      const std::string path = JoinPath(dir, fmt::format("frame{:04d}_{}.png", t, k));
      FILE* file = std::fopen(path.c_str(), "wb");
      if (file == nullptr) return UnavailableError(path + ": cannot open for writing");
      const size_t written = std::fwrite(png.data(), 1, png.size(), file);
      const bool closed = std::fclose(file) == 0;
      if (written != png.size() || !closed) return UnavailableError(path + ": write failed");
      renders.push_back({{"frame", t},
                         {"view", views[k].name},
                         {"path", path},
                         {"max_abs_offset_mm", views[k].offsets.colwise().norm().maxCoeff()}});
    }
  }
  return Json{{"take", take.info.expression + "@" + fmt::format("{:g}Hz", hz)},
              {"range_mm", 5.0},
              {"images", renders}};
}

// Wall time of each stage, in the order they ran (metrics.json "stages_s").
class StageClock {
 public:
  void Lap(const std::string& stage) {
    const auto now = std::chrono::steady_clock::now();
    times_.push_back({stage, std::chrono::duration<double>(now - last_).count()});
    last_ = now;
  }
  Json ToJson() const {
    Json json = Json::array();
    for (const auto& [stage, seconds] : times_)
      json.push_back({{"stage", stage}, {"seconds", seconds}});
    return json;
  }

 private:
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
  std::vector<std::pair<std::string, double>> times_;
};

Status RunDemo(const DemoOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  StageClock clock;
  Json metrics;
  metrics["quick"] = options.quick;
  const double fps = 128.0;
  const int frames = options.quick ? 64 : 256;
  spdlog::info("facedyn demo -> {}", options.out_dir);
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(options.out_dir));

  // Rig: the simulated drive behind a real Modbus TCP server, a short scripted sweep.
  Json rig_metrics;
  FACEDYN_RETURN_IF_ERROR(RunRigDemoStage(options.out_dir, options.quick, &rig_metrics));
  metrics["rig"] = rig_metrics;
  clock.Lap("rig: simulated drive and sweep");

  const Take take = MakeRigidPlatformTake(8.0, fps, frames);
  const std::string take_dir = JoinPath(options.out_dir, "takes/platform_8hz");
  FACEDYN_RETURN_IF_ERROR(SaveTake(take, take_dir));
  spdlog::info("saved take {} ({} frames, {} vertices)", take_dir, take.frame_count(),
               take.vertex_count());

  FACEDYN_ASSIGN_OR_RETURN(const Take reloaded, LoadTake(take_dir));
  if (reloaded.positions.positions != take.positions.positions ||
      !SameTopology(reloaded.topology, take.topology)) {
    return InternalError("demo: the reloaded take differs from the saved one");
  }
  spdlog::info("reloaded take: positions bit-identical, topology identical");

  FACEDYN_ASSIGN_OR_RETURN(
      const ExportSummary pc2,
      ExportTake(reloaded, ExportFormat::kPc2, JoinPath(options.out_dir, "export/pc2")));
  FACEDYN_ASSIGN_OR_RETURN(
      const ExportSummary obj,
      ExportTake(reloaded, ExportFormat::kObj, JoinPath(options.out_dir, "export/obj")));
  spdlog::info("exported {} PC2 files and {} OBJ frames under {}/export", pc2.files_written,
               obj.files_written, options.out_dir);

  std::printf("%s", TakeSummaryToText(reloaded, SummarizeTake(reloaded)).c_str());

  // Simulated face on the vibrating platform: dynamic skin and its exact quasistatic twin.
  FACEDYN_ASSIGN_OR_RETURN(const FaceRig face,
                           sim::MakeProceduralFace(sim::ProceduralFaceOptions()));
  FACEDYN_RETURN_IF_ERROR(SaveFaceRig(face, JoinPath(options.out_dir, "face")));
  sim::PerformanceOptions performance;
  performance.expression = "neutral";
  performance.motion.kind = sim::MotionKind::kPlatform;
  performance.motion.platform_hz = 11.0;
  performance.seconds = options.quick ? 1.5 : 3.0;
  sim::PerformanceSummary sim_summary;
  FACEDYN_ASSIGN_OR_RETURN(const Take simulated,
                           sim::SimulatePerformance(face, performance, &sim_summary));
  const std::string sim_dir = JoinPath(options.out_dir, "takes/sim_neutral_11hz");
  FACEDYN_RETURN_IF_ERROR(SaveTake(simulated, sim_dir));
  FACEDYN_ASSIGN_OR_RETURN(const auto peaks, sim::PeakOffsetByRegionMm(face, simulated));
  std::printf("\nSimulated platform take %s (%d frames, %d vertices, %.1f s to simulate)\n",
              sim_dir.c_str(), simulated.frame_count(), simulated.vertex_count(),
              sim_summary.simulate_s);
  std::printf("peak dynamic offset (dynamic - quasistatic) by region, after the first 0.5 s:\n");
  for (const auto& [region, peak_mm] : peaks)
    std::printf("  %-14s %6.2f mm\n", region.c_str(), peak_mm);
  metrics["simulation"] = {{"take", sim_dir},
                           {"frames", simulated.frame_count()},
                           {"vertices", simulated.vertex_count()},
                           {"simulate_s", sim_summary.simulate_s},
                           {"peak_offset_mm_by_region", peaks}};
  clock.Lap("take I/O and simulated face");

  // Capture: a short trigger-synchronised multi-view take from the simulated cameras.
  Json capture_metrics;
  FACEDYN_RETURN_IF_ERROR(RunCaptureDemoStage(options.out_dir, options.quick, &capture_metrics));
  metrics["capture"] = capture_metrics;
  clock.Lap("capture: simulated cameras, recording, session check");

  // Reconstruction: calibrate the simulated rig, reconstruct the 11 Hz take, compare with truth.
  Json reconstruct_metrics;
  FACEDYN_RETURN_IF_ERROR(RunReconstructDemoStage(face, simulated, options.out_dir, options.quick,
                                                  &reconstruct_metrics));
  metrics["reconstruct"] = reconstruct_metrics;
  clock.Lap("reconstruct: calibration, markers, skull, dense fit");

  // Dynamics: train the removal network F on simulated platform takes, remove the dynamics of a
  // frequency held out of training, compare with the baselines against the exact quasistatic;
  // then train H on F's decomposition and resynthesise (app/dynamics_study.h).
  DynamicsStudyOptions study;
  if (options.quick) {
    study.train_hz = {8, 10};
    study.expressions = {"neutral"};
    study.seconds = 1.5;
    study.speech_hz = 0;
    study.train_speech = false;
    study.removal_epochs = 8;
    study.synthesis_epochs = 5;
  } else {
    study.train_hz = {6, 7, 8, 9, 10};
    study.expressions = {"neutral", "smile"};
    study.seconds = 1.5;
    study.train_speech = false;  // keeps the default run under 20 minutes on 2 cores
    study.removal_epochs = 15;
    study.synthesis_epochs = 15;
  }
  study.moving_average_targets = !options.quick;
  study.frequency_subsets = true;
  study.subset_epochs = options.quick ? 4 : 6;
  study.test_hz = 11;
  study.vertices = sim::ProceduralFaceOptions().target_vertex_count;  // the demo's face
  DynamicsStudyArtifacts artifacts;
  FACEDYN_ASSIGN_OR_RETURN(const Json dynamics_metrics, RunDynamicsStudy(study, &artifacts));
  std::printf("\nSecondary dynamics removal, trained at");
  for (double hz : study.train_hz) std::printf(" %g", hz);
  std::printf(
      " Hz, tested on takes never seen (error vs the exact quasistatic, jiggling vertices):\n");
  std::printf("  %-16s %-26s %10s %10s\n", "take", "method", "mean mm", "of offset");
  for (const Json& entry : dynamics_metrics["removal"]) {
    for (const auto& [method, figures] : entry["methods"].items()) {
      std::printf("  %-16s %-26s %10.3f %9.1f%%\n", entry["take"].get<std::string>().c_str(),
                  method.c_str(), figures["jiggle_mean_mm"].get<double>(),
                  100 * figures["relative_to_offset"].get<double>());
    }
  }
  if (dynamics_metrics.contains("synthesis")) {
    for (const Json& entry : dynamics_metrics["synthesis"]["takes"]) {
      std::printf("  %-16s %-26s %10.3f %9.1f%%\n", entry["take"].get<std::string>().c_str(),
                  "remove+resynthesise resid.", entry["resynthesis_residual_mm"].get<double>(),
                  100 * entry["relative_to_offset"].get<double>());
    }
  }
  metrics["dynamics"] = dynamics_metrics;
  clock.Lap("dynamics: simulate, train, remove, resynthesise");
  FACEDYN_ASSIGN_OR_RETURN(metrics["renders"], RenderDynamics(artifacts, options.out_dir));

  // End to end: F (trained on simulated takes) removes the dynamics of the take that went
  // through the simulated cameras and the reconstruction, measured against the exact
  // quasistatic of the simulation that was filmed.
  {
    FACEDYN_ASSIGN_OR_RETURN(const Take reconstructed,
                             LoadTake(reconstruct_metrics["take"].get<std::string>()));
    FACEDYN_ASSIGN_OR_RETURN(
        const Take removed, dynamics::RemoveDynamics(artifacts.removal_model, reconstructed, face));
    dynamics::EvaluateOptions evaluate;
    FACEDYN_ASSIGN_OR_RETURN(
        const dynamics::Evaluation evaluation,
        dynamics::Evaluate(removed, simulated, &reconstructed, &face, evaluate));
    Json methods = Json::object();
    for (const dynamics::ErrorReport& report : evaluation.reports) {
      const std::string name = report.name == "prediction" ? "F_exact_targets" : report.name;
      methods[name] = {{"mean_mm", report.face.mean_mm},
                       {"p95_mm", report.face.p95_mm},
                       {"max_mm", report.face.max_mm}};
    }
    metrics["end_to_end"] = {{"take", "reconstructed neutral@11Hz"},
                             {"truth", "exact quasistatic of the filmed simulation"},
                             {"methods", methods}};
    std::printf(
        "\nEnd to end (simulated cameras -> reconstruction -> removal), mean error over the "
        "face vs the exact quasistatic:\n");
    for (const auto& [name, figures] : methods.items()) {
      std::printf("  %-18s %8.3f mm (p95 %.3f)\n", name.c_str(), figures["mean_mm"].get<double>(),
                  figures["p95_mm"].get<double>());
    }
  }
  clock.Lap("end to end: removal on the reconstructed take");
  clock.Lap("renders");
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  metrics["stages_s"] = clock.ToJson();
  metrics["total_s"] = seconds;
  FACEDYN_RETURN_IF_ERROR(WriteJsonFile(JoinPath(options.out_dir, "metrics.json"), metrics));
  const std::string report = JoinPath(options.out_dir, "report.html");
  FACEDYN_RETURN_IF_ERROR(WriteDemoReport(metrics, report));
  std::printf(
      "\nDemo stages: simulated drive and sweep; take I/O and export; simulated face and "
      "soft-tissue\n"
      "physics; simulated multi-view capture; calibration and reconstruction; dynamics removal\n"
      "and synthesis (%.1f s).\n"
      "Output: %s (figures in metrics.json)\n"
      "Report: %s\n",
      seconds, options.out_dir.c_str(), report.c_str());
  return Status::Ok();
}

}  // namespace

void AddDemoCommand(CLI::App& app, CommandRunner* selected) {
  auto options = std::make_shared<DemoOptions>();
  auto* command = app.add_subcommand("demo", "Run the main job end to end on the simulated stage");
  command->add_option("--out", options->out_dir, "Output folder")->capture_default_str();
  command->add_flag("--quick", options->quick, "A shorter run for smoke tests");
  command->callback([options, selected] { *selected = [options] { return RunDemo(*options); }; });
}

}  // namespace facedyn::app
