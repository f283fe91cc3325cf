// `facedyn demo`: the main job on the simulated stage (issue 8). Stages, in order: the simulated
// drive behind a real Modbus TCP server and a scripted sweep (app/rig_demo.h); the take format's
// save/reload/export round trip; a simulated face on the platform; a simulated multi-view capture
// (app/capture_demo.h); calibration and reconstruction of the 11 Hz take (app/reconstruct_demo.h);
// a simulated-data reference study with exact targets (eval/dynamics_study.h); removal,
// synthesis and retargeting trained on reconstructed takes (app/demo_dynamics.h); rig solving
// (app/solve_demo.h); fine detail for a head-mounted camera's markers (app/detail_demo.h); the
// subject's physical twin (app/twin_demo.h); renders, metrics.json and the self-contained
// report.html (report/report.h).

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "app/capture_demo.h"
#include "app/command.h"
#include "app/demo_dynamics.h"
#include "app/detail_demo.h"
#include "app/reconstruct_demo.h"
#include "app/rig_demo.h"
#include "app/solve_demo.h"
#include "app/twin_demo.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "core/mesh_primitives.h"
#include "core/take.h"
#include "core/take_summary.h"
#include "dynamics/modal_synthesis.h"
#include "eval/dynamics_study.h"
#include "eval/replicates.h"
#include "export/take_export.h"
#include "report/report.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"

namespace facedyn::app {
namespace {

struct DemoOptions {
  std::string out_dir = "facedyn-demo";
  bool quick = false;
  // F's targets on the reconstructed takes (DemoDynamicsOptions::removal_targets).
  std::string removal_targets = "platform-synchronous-else-held-mean";
  // Seeds of the dynamics stage: the first is the demo's (renders, viewers, models); each further
  // seed runs the stage again (its own training takes, test performance and walk, and
  // initialisation) under <out>/replicates/seed-N, and the report compares methods by mean and
  // spread over all of them (eval/replicates.h).
  std::vector<uint64_t> seeds = {1};
  // The modal models' ridge rule (dynamics::ParseRidgeRule).
  std::string modal_ridge_rule = "minimum";
  // Joint F/H training (DemoDynamicsOptions::training_performance_hz): subject A also performs
  // speech at the first and last training frequency, and F_joint and H_joint are scored
  // beside F and H.
  bool joint_training = false;
  int joint_steps = DemoDynamicsOptions().joint_steps;
  double cycle_weight = DemoDynamicsOptions().joint_cycle_weight;
  bool joint_early_stopping = false;
  bool joint_cycle_trains_f_only = false;
};

// Distinct seeds, at least one. Names the flag.
Status CheckSeeds(const std::vector<uint64_t>& seeds) {
  if (seeds.empty()) return InvalidArgumentError("--seeds: at least one seed");
  for (size_t i = 0; i < seeds.size(); ++i) {
    for (size_t j = 0; j < i; ++j) {
      if (seeds[i] == seeds[j]) {
        return InvalidArgumentError(fmt::format("--seeds: {} is given twice", seeds[i]));
      }
    }
  }
  return Status::Ok();
}

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
  // Parsed before any stage runs, so a bad value costs nothing.
  FACEDYN_ASSIGN_OR_RETURN(const dynamics::RemovalTargets removal_targets,
                           dynamics::ParseRemovalTargets(options.removal_targets));
  FACEDYN_RETURN_IF_ERROR(CheckSeeds(options.seeds));
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
  clock.Lap("capture: cameras, recording, check");

  // Reconstruction: calibrate the simulated rig, reconstruct the 11 Hz take, compare with truth.
  Json reconstruct_metrics;
  eval::SimulatedCameraRig cameras;
  Take reconstructed;
  FACEDYN_RETURN_IF_ERROR(RunReconstructDemoStage(face, simulated, options.out_dir, options.quick,
                                                  &reconstruct_metrics, &cameras, &reconstructed));
  metrics["reconstruct"] = reconstruct_metrics;
  clock.Lap("calibration and reconstruction");

  // Simulated-data reference: F trained on SIMULATED takes with the exact quasistatic as target,
  // which only a simulator can give (eval/dynamics_study.h); its F is also applied to the
  // reconstructed held-out take below, next to F trained on reconstructed takes.
  // Small: the demo's main dynamics work is on reconstructed takes below.
  eval::DynamicsStudyOptions study;
  study.train_hz = options.quick ? std::vector<double>{8, 10} : std::vector<double>{6, 8, 10};
  study.expressions = options.quick ? std::vector<std::string>{"neutral"}
                                    : std::vector<std::string>{"neutral", "smile"};
  study.seconds = 1.5;
  study.speech_hz = 0;
  study.train_speech = false;
  study.removal_epochs = options.quick ? 5 : 8;
  study.synthesis_epochs = options.quick ? 3 : 15;
  study.platform_targets = false;
  study.moving_average_targets = false;  // the reconstructed-take stage trains on those
  study.frequency_subsets = false;       // Fig. 5 is drawn from the reconstructed takes
  study.test_hz = 11;
  study.vertices = sim::ProceduralFaceOptions().target_vertex_count;  // the demo's face
  std::printf("\nSimulated-data reference: removal F trained on simulated takes, exact targets\n");
  eval::DynamicsStudyArtifacts study_artifacts;
  FACEDYN_ASSIGN_OR_RETURN(const Json study_metrics, eval::RunDynamicsStudy(study, &study_artifacts));
  std::printf("  %-16s %-26s %10s %10s\n", "take", "method", "mean mm", "of offset");
  for (const Json& entry : study_metrics["removal"]) {
    for (const auto& [method, figures] : entry["methods"].items()) {
      std::printf("  %-16s %-26s %10.3f %9.1f%%\n", entry["take"].get<std::string>().c_str(),
                  method.c_str(), figures["jiggle_mean_mm"].get<double>(),
                  100 * figures["relative_to_offset"].get<double>());
    }
  }
  metrics["simulated_reference"] = study_metrics;
  clock.Lap("reference: F, H on simulated takes");

  // Dynamics on reconstructed takes (app/demo_dynamics.h): F, H, walk synthesis, retargeting.
  DemoDynamicsArtifacts artifacts;
  Json dynamics_metrics;
  DemoDynamicsOptions dynamics_options = DemoDynamicsOptions::ForDemo(options.quick);
  dynamics_options.removal_targets = removal_targets;
  FACEDYN_ASSIGN_OR_RETURN(dynamics_options.modal_ridge_rule,
                           dynamics::ParseRidgeRule(options.modal_ridge_rule));
  dynamics_options.seed = options.seeds.front();
  if (options.joint_training) {
    dynamics_options.training_performance_hz = {dynamics_options.train_hz.front(),
                                                dynamics_options.train_hz.back()};
  }
  dynamics_options.joint_steps = options.joint_steps;
  dynamics_options.joint_cycle_weight = options.cycle_weight;
  dynamics_options.joint_early_stopping = options.joint_early_stopping;
  dynamics_options.joint_cycle_trains_f_only = options.joint_cycle_trains_f_only;
  FACEDYN_RETURN_IF_ERROR(RunDemoDynamicsStage(
      face, cameras, simulated, reconstructed, dynamics_options, options.out_dir,
      &study_artifacts.removal_model, &dynamics_metrics, &artifacts));
  clock.Lap("dynamics on reconstructed takes");
  if (options.seeds.size() > 1) {
    // Replicates: the whole stage again per seed; only its figures are kept.
    std::vector<Json> stages = {dynamics_metrics};
    for (size_t r = 1; r < options.seeds.size(); ++r) {
      const uint64_t seed = options.seeds[r];
      std::printf("\nReplicate %zu of %zu: the dynamics stage with seed %llu\n", r + 1,
                  options.seeds.size(), static_cast<unsigned long long>(seed));
      std::fflush(stdout);
      DemoDynamicsOptions replicate = dynamics_options;
      replicate.seed = seed;
      Json replicate_metrics;
      FACEDYN_RETURN_IF_ERROR(RunDemoDynamicsStage(
          face, cameras, simulated, reconstructed, replicate,
          JoinPath(options.out_dir, fmt::format("replicates/seed-{}", seed)),
          &study_artifacts.removal_model, &replicate_metrics, nullptr));
      stages.push_back(std::move(replicate_metrics));
    }
    metrics["dynamics_replicates"] = eval::SummariseDemoReplicates(stages, options.seeds);
    eval::PrintReplicateSummary(metrics["dynamics_replicates"]);
    dynamics_metrics["replicates_note"] = fmt::format(
        "This section is seed {} alone; the Replicates section compares the methods over all "
        "{} seeds.",
        options.seeds.front(), options.seeds.size());
    clock.Lap(fmt::format("dynamics replicates ({} more seeds)", options.seeds.size() - 1));
  }
  metrics["dynamics"] = dynamics_metrics;
  // Rig solving (FDLS) of the reconstructed performance, before and after removal.
  FACEDYN_ASSIGN_OR_RETURN(
      metrics["solve"],
      RunSolveDemoStage(face, artifacts,
                        SolveDemoOptions::ForDemo(options.quick, options.seeds.front()),
                        options.out_dir));
  clock.Lap("rig solving (FDLS)");
  // Fine detail for a head-mounted camera's sparse markers (Masquerade).
  FACEDYN_ASSIGN_OR_RETURN(
      metrics["detail"],
      RunDetailDemoStage(face, cameras,
                         DetailDemoOptions::ForDemo(options.quick, options.seeds.front()),
                         options.out_dir));
  clock.Lap("fine detail from a head-mounted camera (Masquerade)");
  // The physical twin of subject B (issue 23): its material identified from B's reconstructed
  // platform takes, and removal under head motions nobody captured, with and without the twin's
  // takes in training.
  CapturedRemoval captured_b;
  captured_b.model = artifacts.second_subject_removal ? &*artifacts.second_subject_removal : nullptr;
  captured_b.targets = artifacts.second_subject_removal_targets;
  captured_b.optimizer_steps = artifacts.second_subject_removal_steps;
  captured_b.batch_size = artifacts.second_subject_removal_batch;
  captured_b.seed = options.seeds.front();
  FACEDYN_ASSIGN_OR_RETURN(
      metrics["twin"],
      RunTwinDemoStage(artifacts.second_face, artifacts.second_subject_tissue,
                       artifacts.second_subject_reconstructed, captured_b, cameras,
                       TwinDemoOptions::ForDemo(options.quick, options.seeds.front()),
                       options.out_dir));
  artifacts.second_subject_reconstructed.clear();
  clock.Lap("the subject's physical twin");
  FACEDYN_ASSIGN_OR_RETURN(metrics["renders"],
                           RenderDemoDynamics(face, artifacts, options.out_dir));
  clock.Lap("renders");
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  metrics["stages_s"] = clock.ToJson();
  metrics["total_s"] = seconds;
  FACEDYN_RETURN_IF_ERROR(WriteJsonFile(JoinPath(options.out_dir, "metrics.json"), metrics));
  const std::string report = JoinPath(options.out_dir, "report.html");
  FACEDYN_RETURN_IF_ERROR(report::WriteDemoReport(metrics, report));
  std::printf(
      "\nDemo stages: simulated drive and sweep; take I/O and export; simulated face and "
      "soft-tissue\n"
      "physics; simulated multi-view capture; calibration and reconstruction; dynamics removal,\n"
      "synthesis and retargeting on reconstructed takes (%.1f s).\n"
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
  command
      ->add_option("--removal-targets", options->removal_targets,
                   "Targets of the removal network on the reconstructed takes: "
                   "platform-synchronous-else-held-mean (platform takes fitted at their recorded "
                   "frequency, walks their held mean), platform-synchronous-where-known (platform "
                   "takes fitted, walks moving-average), moving-average (the paper's Eq. 5-6) or "
                   "held-mean (each take's mean shape in the skull frame over its held frames)")
      ->check(CLI::IsMember([] {
        // Not platform-synchronous alone: the demo's training walks record no platform frequency.
        std::vector<std::string> names = dynamics::RemovalTargetsNames(/*include_exact=*/false);
        names.erase(std::remove(names.begin(), names.end(), "platform-synchronous"), names.end());
        return names;
      }()))
      ->capture_default_str();
  command
      ->add_option("--seeds", options->seeds,
                   "Seeds of the dynamics stage, comma-separated (e.g. 1,2,3): the first is "
                   "the demo's; each further seed runs the stage again and the report compares "
                   "methods by mean and spread over all of them (a difference inside the spread "
                   "is a tie)")
      ->delimiter(',')
      ->capture_default_str();
  command
      ->add_option("--modal-ridge-rule", options->modal_ridge_rule,
                   "How the modal models choose their ridge from the leave-one-take-out errors: "
                   "minimum (the least error) or one-standard-error (the largest ridge within "
                   "one standard error of it)")
      ->check(CLI::IsMember(dynamics::RidgeRuleNames()))
      ->capture_default_str();
  CLI::Option* joint_training = command->add_flag(
      "--joint-training", options->joint_training,
      "Also film subject A performing speech at the first and last training "
      "frequency, fine-tune F and H together with the cycle loss on those "
      "performances (no target read) and score F_joint and H_joint beside F and H");
  command
      ->add_option("--joint-steps", options->joint_steps,
                   "Adam steps of the joint fine-tuning (with --joint-training)")
      ->needs(joint_training)
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  command
      ->add_option("--cycle-weight", options->cycle_weight,
                   "Weight of the cycle loss against F's and H's own (with --joint-training)")
      ->needs(joint_training)
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  command
      ->add_flag("--joint-early-stopping", options->joint_early_stopping,
                 "Keep the joint fine-tuning's parameters from its report of least validation "
                 "objective (F's and H's held-out losses on held-take rows plus the cycle's on "
                 "held-out performance frames; with --joint-training)")
      ->needs(joint_training);
  command
      ->add_flag("--joint-cycle-trains-f-only", options->joint_cycle_trains_f_only,
                 "Keep the cycle's gradient from H in the joint fine-tuning (H then fine-tunes "
                 "on its own loss only; with --joint-training)")
      ->needs(joint_training);
  command->callback([options, selected] { *selected = [options] { return RunDemo(*options); }; });
}

}  // namespace facedyn::app
