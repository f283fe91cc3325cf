// End-to-end tests of the `facedyn` executable: exit codes, messages and files on disk.

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::FacedynExecutable;
using ::facedyn::testing::ReadBytes;
using ::facedyn::testing::RunCommand;
using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

std::string Facedyn(const std::string& args) { return FacedynExecutable() + " " + args; }

// Runs `facedyn demo --quick --joint-training` once for the whole suite (it simulates a face, which
// takes a few seconds) and returns the folder of its small rigid take; tests copy what they modify.
const TempDir& DemoDir() {
  static const TempDir* dir = [] {
    auto* d = new TempDir();
    std::string out;
    // With the joint F/H training (a short one: its wiring, not its figures, is tested here).
    const int rc = RunCommand(
        Facedyn("--quiet demo --quick --joint-training --joint-steps 100 --joint-early-stopping "
                "--out " +
                d->Join("demo")),
        &out);
    EXPECT_EQ(rc, 0) << out;
    return d;
  }();
  return *dir;
}

std::string MakeDemoTake(const TempDir& dir) {
  const std::string copy = dir.Join("platform_8hz");
  std::filesystem::copy(DemoDir().Join("demo/takes/platform_8hz"), copy);
  return copy;
}

template <typename T>
T Read(const std::string& bytes, size_t offset) {
  T value;
  std::memcpy(&value, bytes.data() + offset, sizeof(T));
  return value;
}

TEST(Cli, VersionAndHelp) {
  std::string out;
  EXPECT_EQ(RunCommand(Facedyn("--version"), &out), 0);
  EXPECT_THAT(out, HasSubstr("facedyn 0."));
  EXPECT_EQ(RunCommand(Facedyn("--help"), &out), 0);
  for (const char* command : {"take", "export", "demo"}) EXPECT_THAT(out, HasSubstr(command));
  EXPECT_EQ(RunCommand(Facedyn("export --help"), &out), 0);
  EXPECT_THAT(out, HasSubstr("--format"));
}

TEST(Cli, BadCommandLineExitsTwo) {
  std::string out;
  EXPECT_EQ(RunCommand(Facedyn("no-such-command"), &out), 2);
  EXPECT_EQ(RunCommand(Facedyn("export --take x --format xyz --out y"), &out), 2);
  EXPECT_THAT(out, HasSubstr("xyz"));
  EXPECT_EQ(RunCommand(Facedyn("take info"), &out), 2);
  EXPECT_THAT(out, HasSubstr("TAKE"));
}

TEST(Cli, DemoWritesTakeAndExports) {
  TempDir dir;
  const std::string take = MakeDemoTake(dir);
  for (const char* file : {"take.json", "topology.obj", "positions.pc2", "skull.csv"}) {
    EXPECT_TRUE(std::filesystem::exists(take + "/" + file)) << file;
  }
  EXPECT_TRUE(std::filesystem::exists(DemoDir().Join("demo/export/obj/frame_000063.obj")));
  EXPECT_TRUE(std::filesystem::exists(DemoDir().Join("demo/export/pc2/positions.pc2")));
  // The simulated platform take carries the exact quasistatic channel.
  const std::string sim = DemoDir().Join("demo/takes/sim_neutral_11hz");
  for (const char* file :
       {"take.json", "positions.pc2", "quasistatic.pc2", "dynamic_offset.pc2", "jaw.csv"}) {
    EXPECT_TRUE(std::filesystem::exists(sim + "/" + file)) << file;
  }
  EXPECT_TRUE(std::filesystem::exists(DemoDir().Join("demo/face/face_rig.json")));
}

// The demo's metrics.json has every stage's section, its figures are consistent with what the
// stages measure, and the report embeds its renders and plots (no network needed).
TEST(Cli, DemoMetricsAndReport) {
  const std::string metrics_path = DemoDir().Join("demo/metrics.json");
  ASSERT_TRUE(std::filesystem::exists(metrics_path));
  const auto metrics = nlohmann::json::parse(ReadBytes(metrics_path));
  for (const char* section : {"rig", "simulation", "capture", "reconstruct", "simulated_reference",
                              "dynamics", "renders", "stages_s", "total_s"}) {
    EXPECT_TRUE(metrics.contains(section)) << section;
  }
  // Rig: every step held its target, and the time series covers every step's ramp and hold.
  const auto& rig = metrics["rig"];
  ASSERT_FALSE(rig["steps"].empty());
  const auto& series = rig["time_series"];
  ASSERT_GT(series["t_s"].size(), 20u);
  for (const char* line : {"measured_hz", "true_hz", "setpoint_hz"}) {
    EXPECT_EQ(series[line].size(), series["t_s"].size()) << line;
  }
  double previous_end_s = 0.0;
  for (const auto& step : rig["steps"]) {
    EXPECT_NEAR(step["measured_mean_hz"].get<double>(), step["target_hz"].get<double>(), 0.05);
    EXPECT_NEAR(step["start_s"].get<double>(), previous_end_s, 1e-9);
    EXPECT_LT(step["start_s"].get<double>(), step["hold_start_s"].get<double>());
    EXPECT_LT(step["hold_start_s"].get<double>(), step["hold_end_s"].get<double>());
    previous_end_s = step["hold_end_s"].get<double>();
  }
  EXPECT_LE(previous_end_s, series["t_s"].back().get<double>());
  EXPECT_TRUE(metrics["capture"]["session_complete"].get<bool>());
  // Reconstruction: 8 cameras calibrated, each with its reprojection error.
  const auto& reconstruct = metrics["reconstruct"];
  EXPECT_GT(reconstruct["dynamic_offset_correlation"].get<double>(), 0.9);
  // The jaw from the jaw markers, against the simulator's (reconstruct/jaw_pose.h).
  ASSERT_TRUE(reconstruct.contains("jaw_angle_rms_deg")) << reconstruct.dump();
  EXPECT_LT(reconstruct["jaw_angle_rms_deg"].get<double>(), 0.5);
  ASSERT_EQ(reconstruct["calibration_per_camera"].size(), 8u);
  for (const auto& camera : reconstruct["calibration_per_camera"]) {
    EXPECT_GT(camera["rms_px"].get<double>(), 0.0);
    EXPECT_LT(camera["rms_px"].get<double>(), 1.0);
    EXPECT_GT(camera["corners"].get<int>(), 0);
  }
  // Simulated-data reference (exact targets on simulated takes).
  const auto& reference = metrics["simulated_reference"];
  ASSERT_FALSE(reference["removal"].empty());
  for (const auto& entry : reference["removal"]) {
    for (const char* method : {"F_exact_targets", "no_removal", "lowpass", "moving_average"}) {
      EXPECT_TRUE(entry["methods"].contains(method)) << method;
    }
  }
  EXPECT_TRUE(reference.contains("synthesis"));

  // Dynamics on reconstructed takes.
  const auto& dynamics = metrics["dynamics"];
  for (const char* section :
       {"setup", "reconstruction", "removal", "removal_performance", "removal_walk",
        "removal_by_training_frequencies", "synthesis", "retarget", "training"}) {
    ASSERT_TRUE(dynamics.contains(section)) << section;
  }
  // A's training performances (--joint-training: speech at the first and last training
  // frequency), then the held-out performance and walk.
  const auto& train_hz = dynamics["setup"]["train_hz"];
  ASSERT_EQ(dynamics["setup"]["training_performances"],
            nlohmann::json::array({fmt::format("speech@{:g}Hz", train_hz.front().get<double>()),
                                   fmt::format("speech@{:g}Hz", train_hz.back().get<double>())}));
  EXPECT_EQ(dynamics["reconstruction"].size(),
            dynamics["setup"]["training_takes"].get<size_t>() +
                dynamics["retarget"]["training_takes"].get<size_t>() + 2 + 2);
  for (const auto& take : dynamics["reconstruction"]) {
    EXPECT_LT(take["sample_rms_mm"].get<double>(), 1.0) << take["take"];
  }
  const auto& methods = dynamics["removal"]["methods"];
  for (const char* method :
       {"F", "F_exact_targets_simulated", "no_removal", "lowpass", "moving_average"}) {
    ASSERT_TRUE(methods.contains(method)) << method;
  }
  const double f_mm = methods["F"]["jiggle_mean_mm"].get<double>();
  // The held-out take's removal must at least remove most of the dynamics. Whether F beats the
  // low-pass is a comparison, which needs replicates (README): this one-seed test makes no such
  // claim. It checks the protocol instead: the low-pass cutoff by rule (a third of the recorded
  // 11 Hz), the oracle labelled as such, the scored frames after the hold start, and the lower
  // reference (Eq. 7 with the exact offsets in the estimated skull frame) well below no removal.
  EXPECT_GT(dynamics["removal"]["reconstruction_error_mm"].get<double>(), 0.0);
  EXPECT_NEAR(methods["lowpass"]["cutoff_hz"].get<double>(), 11.0 / 3, 1e-3);
  ASSERT_TRUE(methods.contains("lowpass_oracle"));
  EXPECT_TRUE(methods["lowpass_oracle"]["oracle"].get<bool>());
  EXPECT_GE(dynamics["removal"]["scored_frames"][0].get<int>(),
            static_cast<int>(0.55 * 128));  // hold_start_s 0.3 s + 0.25 s at 128 fps
  for (const char* method : {"F", "lowpass", "no_removal"}) {
    EXPECT_GT(methods[method]["skull_frame_jiggle_mean_mm"].get<double>(), 0.0) << method;
  }
  const double reference_mm = dynamics["removal"]["exact_offsets_removed_mm"].get<double>();
  EXPECT_GT(reference_mm, 0.0);
  EXPECT_LT(reference_mm, 0.5 * methods["no_removal"]["jiggle_mean_mm"].get<double>());
  EXPECT_EQ(dynamics["removal"]["F_targets"], "platform-synchronous-else-held-mean");
  EXPECT_LT(f_mm, 0.5 * methods["no_removal"]["jiggle_mean_mm"].get<double>());
  // The performance (speech) on the held-out frequency, never trained on.
  ASSERT_TRUE(dynamics.contains("removal_performance"));
  const auto& performance = dynamics["removal_performance"]["methods"];
  for (const char* method : {"F", "no_removal", "lowpass", "moving_average"}) {
    ASSERT_TRUE(performance.contains(method)) << method;
  }
  EXPECT_LT(performance["F"]["jiggle_mean_mm"].get<double>(),
            0.5 * performance["no_removal"]["jiggle_mean_mm"].get<double>());
  // The walk at a step rate no training walk has, reconstructed: every method is scored, and
  // the lower reference (exact offsets removed in the estimated skull frame) is below no
  // removal. Whether F helps on the walk is not asserted: on this one-seed quick demo it does
  // not (F 0.445 mm against 0.397 mm without removal, README), which is issue 20's to fix.
  const auto& walk_removal = dynamics["removal_walk"]["methods"];
  for (const char* method : {"F", "no_removal", "lowpass", "lowpass_oracle", "moving_average"}) {
    ASSERT_TRUE(walk_removal.contains(method)) << method;
    EXPECT_GT(walk_removal[method]["jiggle_mean_mm"].get<double>(), 0.0) << method;
  }
  EXPECT_GT(dynamics["removal_walk"]["exact_offsets_removed_mm"].get<double>(), 0.0);
  EXPECT_LT(dynamics["removal_walk"]["exact_offsets_removed_mm"].get<double>(),
            walk_removal["no_removal"]["jiggle_mean_mm"].get<double>());
  // Fig. 5: every bar, the full set included, with exactly the same number of Adam steps.
  // The full set trains subset_epochs; a subset of fewer rows trains more epochs.
  const auto& bars = dynamics["removal_by_training_frequencies"]["subsets"];
  ASSERT_GE(bars.size(), 2u);
  EXPECT_EQ(bars.back()["epochs"].get<int>(), dynamics["setup"]["subset_epochs"].get<int>());
  EXPECT_GT(bars.front()["epochs"].get<int>(), bars.back()["epochs"].get<int>());
  EXPECT_LT(bars.front()["training_rows"].get<long>(), bars.back()["training_rows"].get<long>());
  EXPECT_GT(bars.back()["optimizer_steps"].get<long>(), 0);
  for (const auto& bar : bars) {
    EXPECT_EQ(bar["optimizer_steps"].get<long>(), bars.back()["optimizer_steps"].get<long>())
        << bar.dump();
  }
  EXPECT_EQ(dynamics["removal_by_training_frequencies"]["subsets"].size(),
            dynamics["setup"]["train_hz"].size());
  const auto& synthesis = dynamics["synthesis"];
  EXPECT_GT(synthesis["resynthesis"]["resynthesis_residual_mm"].get<double>(), 0.0);
  // Resynthesis restores dynamics: closer to the input than the removed take is.
  EXPECT_LT(synthesis["resynthesis"]["resynthesis_residual_mm"].get<double>(),
            synthesis["resynthesis"]["removed_without_synthesis_mm"].get<double>());
  // Fig. 7 also on the held-out performance, and by the modal model as the synthesiser.
  ASSERT_TRUE(synthesis.contains("resynthesis_performance"));
  EXPECT_NE(synthesis["resynthesis_performance"]["take"], synthesis["resynthesis"]["take"]);
  for (const char* fig : {"resynthesis", "resynthesis_performance"}) {
    EXPECT_GT(synthesis[fig]["modal_resynthesis_residual_mm"].get<double>(), 0.0) << fig;
    EXPECT_GT(synthesis[fig]["mean_dynamic_offset_mm"].get<double>(), 0.0) << fig;
  }
  for (const char* method : {"H", "modal", "no_dynamics"}) {
    EXPECT_TRUE(synthesis["walk"]["methods"].contains(method)) << method;
  }
  for (const char* method :
       {"H_B_retarget", "modal_B_retarget", "naive_delta_transfer", "no_dynamics"}) {
    EXPECT_TRUE(dynamics["retarget"]["methods"].contains(method)) << method;
  }
  for (const char* model : {"F", "H", "F_B", "H_B", "modal_A", "modal_B", "joint"}) {
    EXPECT_TRUE(dynamics["training"].contains(model)) << model;
  }
  // The joint training: its steps, its cycle on the training performances' frames, and F_joint
  // scored on every held-out take beside F, and H_joint resynthesising F_joint's removals.
  const auto& joint = dynamics["training"]["joint"];
  EXPECT_EQ(joint["steps"].get<int>(), 100);
  EXPECT_EQ(joint["performances"].size(), 2u);
  EXPECT_GT(joint["performance_frames"].get<long>(), 0);
  EXPECT_GT(joint["final_cycle_loss"].get<double>(), 0.0);
  // --joint-early-stopping: the kept report is one of the reports (100 steps: the one).
  EXPECT_TRUE(joint["early_stopping"].get<bool>());
  EXPECT_EQ(joint["reports"].get<long>(), 1);
  EXPECT_EQ(joint["kept_report"].get<long>(), 0);
  // The validation losses early stopping reads: F's and H's on their held-out held-take rows
  // and the cycle's on held-out performance frames, one per report.
  for (const char* loss : {"f_validation_loss", "h_validation_loss", "cycle_validation_loss"}) {
    ASSERT_EQ(joint[loss].size(), 1u) << loss;
    EXPECT_GT(joint[loss][0].get<double>(), 0.0) << loss;
  }
  EXPECT_TRUE(joint["cycle_trains_h"].get<bool>());
  for (const char* section : {"removal", "removal_performance", "removal_walk"}) {
    const auto& scored = dynamics[section]["methods"];
    ASSERT_TRUE(scored.contains("F_joint")) << section;
    EXPECT_GT(scored["F_joint"]["jiggle_mean_mm"].get<double>(), 0.0) << section;
  }
  for (const char* fig : {"resynthesis", "resynthesis_performance"}) {
    ASSERT_TRUE(synthesis[fig].contains("H_joint_resynthesis_residual_mm")) << fig;
    EXPECT_LT(synthesis[fig]["H_joint_resynthesis_residual_mm"].get<double>(),
              synthesis[fig]["F_joint_removed_without_synthesis_mm"].get<double>())
        << fig;
    // The cross pairings: F_joint's removal resynthesised by H, F's by H_joint.
    ASSERT_TRUE(synthesis[fig].contains("F_joint_then_H_resynthesis_residual_mm")) << fig;
    EXPECT_LT(synthesis[fig]["F_joint_then_H_resynthesis_residual_mm"].get<double>(),
              synthesis[fig]["F_joint_removed_without_synthesis_mm"].get<double>())
        << fig;
    ASSERT_TRUE(synthesis[fig].contains("F_then_H_joint_resynthesis_residual_mm")) << fig;
    EXPECT_LT(synthesis[fig]["F_then_H_joint_resynthesis_residual_mm"].get<double>(),
              synthesis[fig]["removed_without_synthesis_mm"].get<double>())
        << fig;
  }
  for (const char* model : {"F.pt", "H.pt", "H_B.pt", "F_joint.pt", "H_joint.pt"}) {
    EXPECT_TRUE(std::filesystem::exists(DemoDir().Join(std::string("demo/models/") + model)))
        << model;
  }

  // Renders: the held-out take (3 views), the walk (2) and the retargeting (4: B's H, B's modal
  // synthesis, naive transfer, the truth), two frames each.
  EXPECT_EQ(metrics["renders"]["groups"].size(), 3u);
  EXPECT_EQ(metrics["renders"]["images"].size(), 18u);
  // Named relative to the output folder, so the folder can move.
  for (const auto& image : metrics["renders"]["images"]) {
    EXPECT_TRUE(std::filesystem::path(image["path"].get<std::string>()).is_relative());
    EXPECT_TRUE(std::filesystem::exists(DemoDir().Join("demo/" + image["path"].get<std::string>())))
        << image["path"];
  }
  const std::string report = ReadBytes(DemoDir().Join("demo/report.html"));
  EXPECT_THAT(report, HasSubstr("<svg"));
  EXPECT_THAT(report, HasSubstr("<polyline"));
  EXPECT_THAT(report, HasSubstr("data:image/png;base64,"));
  for (const char* figure :
       {"Platform frequency during the sweep", "Reprojection RMS per camera", "never trained on",
        "paper Fig. 5", "paper Fig. 7", "New head motion", "retargeting to a second subject",
        "Time per stage", "Removal from a performance", "Removal from a new head motion",
        "F_joint then H_joint residual"}) {
    EXPECT_THAT(report, HasSubstr(figure));
  }
  // Self-contained: nothing is loaded from elsewhere (the SVG namespace URI is not a fetch).
  for (const char* remote : {"src=\"http", "href=\"http", "url(http", "@import"}) {
    EXPECT_EQ(report.find(remote), std::string::npos) << "the report loads " << remote;
  }
}

// Rig solving (issue 21): the demo solves the reconstructed performance before and after
// dynamics removal into the puppet's controls, writes both weights CSVs and drives subject B with
// them; solving after removal is closer to the reference weights (the exact quasistatic skin's)
// than solving the take with its jiggle (quick demo, seed 1: 0.025 against 0.098 weight RMSE).
TEST(Cli, DemoSolvesThePerformanceBeforeAndAfterRemoval) {
  const auto metrics = nlohmann::json::parse(ReadBytes(DemoDir().Join("demo/metrics.json")));
  ASSERT_TRUE(metrics.contains("solve"));
  const auto& solve = metrics["solve"];
  const int frames = solve["frames"].get<int>();
  EXPECT_GT(frames, 10);
  for (const char* source : {"from_reconstructed", "from_removed"}) {
    for (const char* method : {"network", "network_finetuned"}) {
      const auto& f = solve[source][method];
      for (const char* figure : {"weight_rmse", "jaw_weight_rmse", "marker_rmse_mm"}) {
        EXPECT_GT(f[figure].get<double>(), 0.0) << source << " " << method << " " << figure;
      }
    }
    const std::string csv = ReadBytes(solve[source]["weights_csv"].get<std::string>());
    EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), frames + 1) << source;
  }
  // The jiggle is what the solve picks up: removal brings the weights towards the reference and
  // leaves less marker residual that the puppet cannot explain.
  EXPECT_LT(solve["from_removed"]["network"]["weight_rmse"].get<double>(),
            0.75 * solve["from_reconstructed"]["network"]["weight_rmse"].get<double>());
  EXPECT_LT(solve["from_removed"]["network_finetuned"]["weight_rmse"].get<double>(),
            0.75 * solve["from_reconstructed"]["network_finetuned"]["weight_rmse"].get<double>());
  EXPECT_LT(solve["from_removed"]["network_finetuned"]["marker_rmse_mm"].get<double>(),
            solve["from_reconstructed"]["network_finetuned"]["marker_rmse_mm"].get<double>());
  ASSERT_EQ(solve["curves"]["channels"].size(), 3u);
  EXPECT_EQ(solve["curves"]["channels"][0]["reference"].size(), static_cast<size_t>(frames));
  // Subject B driven by the solved weights: a take of B's own topology, frame for frame.
  const std::string driven = solve["driven"]["take"].get<std::string>();
  std::string out;
  ASSERT_EQ(RunCommand(Facedyn("take info --json " + driven), &out), 0) << out;
  const auto info = nlohmann::json::parse(out.substr(out.find('{')));
  EXPECT_EQ(info["frames"].get<int>(), frames);
  EXPECT_EQ(solve["driven"]["rig"], "procedural-b");
  const std::string report = ReadBytes(DemoDir().Join("demo/report.html"));
  EXPECT_THAT(report, HasSubstr("Rig solving (FDLS)"));
  EXPECT_THAT(report, HasSubstr("Weight of '"));
}

// The physical twin (issue 23): the demo fits subject B's twin from B's reconstructed platform
// take, moving it from the prior most of the way to B's configured tissue (quick demo, seed 1:
// 8.28 Hz for 8.5, prior 11; damping 0.178 for 0.170), and F trained with the twin's nod and
// shake takes removes more of B's held-out nod and shake than F trained on B's captured takes
// alone (figures in README "The subject's physical twin").
TEST(Cli, DemoFitsTheTwinAndTrainsWithItsTakes) {
  const auto metrics = nlohmann::json::parse(ReadBytes(DemoDir().Join("demo/metrics.json")));
  ASSERT_TRUE(metrics.contains("twin"));
  const auto& fit = metrics["twin"]["fit"];
  const double true_hz = fit["true_hz"].get<double>();
  EXPECT_LT(std::abs(fit["fitted_hz"].get<double>() - true_hz),
            0.2 * std::abs(fit["prior_hz"].get<double>() - true_hz));
  EXPECT_NEAR(fit["fitted_damping_ratio"].get<double>(), fit["true_damping_ratio"].get<double>(),
              0.1 * fit["true_damping_ratio"].get<double>());
  EXPECT_TRUE(std::filesystem::exists(fit["twin"].get<std::string>()));
  // The augmented F trains on more rows for exactly the dynamics stage's F_B's steps; F_B is
  // the captured F (not trained a second time).
  const auto& f_b = metrics["dynamics"]["training"]["F_B"];
  EXPECT_GT(metrics["twin"]["training"]["rows_augmented"].get<long>(),
            f_b["training_rows"].get<long>());
  EXPECT_EQ(metrics["twin"]["training"]["optimizer_steps"].get<long>(),
            f_b["optimizer_steps"].get<long>());
  ASSERT_EQ(metrics["twin"]["removal"].size(), 2u);
  for (const auto& take : metrics["twin"]["removal"]) {
    const auto& methods = take["methods"];
    EXPECT_LT(methods["F_augmented"]["jiggle_mean_mm"].get<double>(),
              0.8 * methods["F_captured"]["jiggle_mean_mm"].get<double>())
        << take["take"];
  }
  EXPECT_THAT(ReadBytes(DemoDir().Join("demo/report.html")), HasSubstr("physical twin"));
  // Targeting (issue 23): B's smile filmed lying back by 45 degrees, fitted by the blendshapes
  // and by the twin. Gravity turned by 2 g sin(22.5 deg) = 7508 mm/s^2 in the skull frame (less
  // the estimated skull pose's error); the twin's marker residual is within the 10% of
  // the blendshape fit's (bench/twin_bench: 0.35-1.02 of it lying back, README).
  ASSERT_TRUE(metrics["twin"].contains("targeting"));
  const auto& targeting = metrics["twin"]["targeting"];
  EXPECT_NEAR(targeting["gravity_change_mm_s2"].get<double>(), 7508, 150);
  EXPECT_GT(targeting["frames"].get<int>(), 0);
  // Issue 23's "within 10%" on the markers both (robust) fits hold; each fit's RMS over every
  // marker includes the gross errors it chose to ignore, different ones for each.
  EXPECT_LT(targeting["twin"]["common_inlier_rms_mm"].get<double>(),
            1.1 * targeting["blendshape"]["common_inlier_rms_mm"].get<double>());
  EXPECT_GT(targeting["twin"]["common_inlier_markers"].get<int>(), 100);  // of 150
  EXPECT_THAT(ReadBytes(DemoDir().Join("demo/report.html")), HasSubstr("Targeting a held frame"));
}

// `facedyn report` draws the same report from metrics.json, also after the folder moved.
TEST(Cli, ReportRedrawsTheDemoReportFromItsMetrics) {
  TempDir dir;
  const std::string moved = dir.Join("moved");
  std::filesystem::create_directories(moved);
  std::filesystem::copy(DemoDir().Join("demo/metrics.json"), moved + "/metrics.json");
  std::filesystem::copy(DemoDir().Join("demo/renders"), moved + "/renders");
  std::filesystem::copy(DemoDir().Join("demo/viewers"), moved + "/viewers");  // linked, not inlined
  std::string out;
  ASSERT_EQ(
      RunCommand("cd " + dir.path() + " && " + Facedyn("report --metrics moved/metrics.json 2>&1"),
                 &out),
      0)
      << out;
  EXPECT_THAT(out, HasSubstr("moved/report.html"));
  EXPECT_EQ(ReadBytes(moved + "/report.html"), ReadBytes(DemoDir().Join("demo/report.html")));
  // Bad input names the file and writes nothing.
  EXPECT_EQ(RunCommand(Facedyn("report --metrics " + dir.Join("none.json") + " --out " +
                               dir.Join("r1.html") + " 2>&1"),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("none.json"));
  WriteBytes(dir.Join("bad.json"), "{\"rig\": ");
  EXPECT_EQ(RunCommand(Facedyn("report --metrics " + dir.Join("bad.json") + " --out " +
                               dir.Join("r2.html") + " 2>&1"),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("bad.json: not JSON"));
  // A render gone: DataLoss naming it.
  std::filesystem::remove_all(moved + "/renders");
  EXPECT_EQ(RunCommand(Facedyn("report --metrics " + moved + "/metrics.json --out " +
                               dir.Join("r3.html") + " 2>&1"),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("render missing"));
  for (const char* name : {"r1.html", "r2.html", "r3.html"}) {
    EXPECT_FALSE(std::filesystem::exists(dir.Join(name))) << name;
  }
}

TEST(Cli, TakeInfoJsonReportsCountsAndSkullRange) {
  TempDir dir;
  const std::string take = MakeDemoTake(dir);
  std::string out;
  ASSERT_EQ(RunCommand(Facedyn("take info --json " + take + " 2>/dev/null"), &out), 0) << out;
  const auto json = nlohmann::json::parse(out);
  EXPECT_EQ(json["frames"], 64);
  EXPECT_EQ(json["fps"], 128.0);
  EXPECT_EQ(json["vertices"], 33 * 33);
  EXPECT_NEAR(json["duration_s"].get<double>(), 0.5, 1e-12);
  // The demo head oscillates +-2 mm vertically with +-0.5 deg of pitch; 64 frames at 8 Hz and
  // 128 fps cover 4 full periods, so the peaks are sampled exactly.
  EXPECT_NEAR(json["skull_motion"]["translation_range_mm"][1].get<double>(), 4.0, 1e-6);
  EXPECT_NEAR(json["skull_motion"]["max_rotation_deg"].get<double>(), 0.5, 1e-4);
}

TEST(Cli, ExportPc2HeaderReadIndependently) {
  TempDir dir;
  const std::string take = MakeDemoTake(dir);
  std::string out;
  ASSERT_EQ(
      RunCommand(Facedyn("export --take " + take + " --format pc2 --out " + dir.Join("pc2")), &out),
      0)
      << out;
  const std::string bytes = ReadBytes(dir.Join("pc2/positions.pc2"));
  ASSERT_GE(bytes.size(), 32u);
  // ARCHITECTURE.md: "POINTCACHE2\0", int32 version=1, int32 vertex count, float32 start
  // frame, float32 sampling, int32 frame count, then float32 xyz.
  EXPECT_EQ(std::memcmp(bytes.data(), "POINTCACHE2\0", 12), 0);
  EXPECT_EQ(Read<int32_t>(bytes, 12), 1);
  const int32_t vertices = Read<int32_t>(bytes, 16);
  EXPECT_EQ(vertices, 33 * 33);
  EXPECT_EQ(Read<float>(bytes, 20), 0.0f);
  EXPECT_EQ(Read<float>(bytes, 24), 1.0f);
  const int32_t frames = Read<int32_t>(bytes, 28);
  EXPECT_EQ(frames, 64);
  EXPECT_EQ(bytes.size(), 32u + size_t(vertices) * size_t(frames) * 12u);
  // Frame 0 equals the exported topology's rest pose moved by skull pose 0 (identity at
  // phase 0), i.e. the first "v" line of topology.obj.
  const std::string obj = ReadBytes(dir.Join("pc2/topology.obj"));
  const size_t v = obj.find("\nv ");
  ASSERT_NE(v, std::string::npos);
  float x, y, z;
  ASSERT_EQ(std::sscanf(obj.c_str() + v + 3, "%f %f %f", &x, &y, &z), 3);
  EXPECT_NEAR(Read<float>(bytes, 32), x, 1e-4);
  EXPECT_NEAR(Read<float>(bytes, 36), y, 1e-4);
  EXPECT_NEAR(Read<float>(bytes, 40), z, 1e-4);
}

TEST(Cli, ExportPerFrameObjAndPly) {
  TempDir dir;
  const std::string take = MakeDemoTake(dir);
  std::string out;
  ASSERT_EQ(RunCommand(
                Facedyn("--quiet export --take " + take + " --format ply --out " + dir.Join("ply")),
                &out),
            0)
      << out;
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir.Join("ply"))) {
    EXPECT_EQ(entry.path().extension(), ".ply");
    ++count;
  }
  EXPECT_EQ(count, 64);
}

TEST(Cli, TakeInfoErrorsNameTheProblem) {
  TempDir dir;
  std::string out;
  EXPECT_EQ(RunCommand(Facedyn("take info " + dir.Join("missing")), &out), 1);
  EXPECT_THAT(out, HasSubstr("missing: no such take folder"));

  const std::string take = MakeDemoTake(dir);
  // Truncate the point cache: the error names the file and the incomplete frame.
  std::filesystem::resize_file(take + "/positions.pc2", 32 + 12 * 33 * 33 * 10 + 7);
  EXPECT_EQ(RunCommand(Facedyn("take info " + take), &out), 1);
  EXPECT_THAT(out, HasSubstr("positions.pc2: truncated"));
  EXPECT_THAT(out, HasSubstr("frame 10 is incomplete"));
}

TEST(Cli, ExportErrorLeavesNoCrash) {
  TempDir dir;
  const std::string take = MakeDemoTake(dir);
  // The output path is an existing file, not a folder.
  testing::WriteBytes(dir.Join("file"), "x");
  std::string out;
  EXPECT_EQ(RunCommand(Facedyn("export --take " + take + " --format pc2 --out " + dir.Join("file")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("file"));
}

// Every format the help names is accepted (mdd once was not), and the rig's glb export
// refuses what it cannot do with a message naming it, writing nothing under the final name.
TEST(Cli, ExportFormatsAndRigGlbErrors) {
  TempDir dir;
  const std::string take = MakeDemoTake(dir);
  std::string out;
  for (const char* format : {"mdd", "glb"}) {
    EXPECT_EQ(RunCommand(Facedyn("--quiet export --take " + take + " --format " + format +
                                 " --out " + dir.Join(format)),
                         &out),
              0)
        << out;
  }
  EXPECT_TRUE(std::filesystem::exists(dir.Join("mdd/positions.mdd")));
  EXPECT_TRUE(std::filesystem::exists(dir.Join("glb/take.glb")));
  const std::string face = DemoDir().Join("demo/face");
  EXPECT_EQ(RunCommand(Facedyn("export --rig " + face + " --format pc2 --out " + dir.Join("r")), &out), 1);
  EXPECT_THAT(out, HasSubstr("--format glb"));
  EXPECT_EQ(RunCommand(Facedyn("export --format glb --out " + dir.Join("r")), &out), 1);
  EXPECT_THAT(out, HasSubstr("--take TAKE or --rig FACE"));
  EXPECT_EQ(RunCommand(Facedyn("export --take " + take + " --rig " + face + " --format glb --out " +
                               dir.Join("r")),
                       &out),
            2);
  testing::WriteBytes(dir.Join("w.csv"), "time_s,no_such_shape\n0,1\n");
  EXPECT_EQ(RunCommand(Facedyn("export --rig " + face + " --weights " + dir.Join("w.csv") +
                               " --format glb --out " + dir.Join("r")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("'no_such_shape'"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("r/rig.glb")));
  testing::WriteBytes(dir.Join("w.csv"), "time_s,smile\n0,1\n0.5,0\n");
  EXPECT_EQ(RunCommand(Facedyn("--quiet export --rig " + face + " --weights " + dir.Join("w.csv") +
                               " --format glb --out " + dir.Join("r")),
                       &out),
            0)
      << out;
  EXPECT_TRUE(std::filesystem::exists(dir.Join("r/rig.glb")));
}

TEST(Cli, SimFaceAndPerformWriteATakeWithQuasistaticChannel) {
  TempDir dir;
  std::string out;
  ASSERT_EQ(RunCommand(Facedyn("--quiet sim face --vertices 4000 --out " + dir.Join("face")), &out),
            0)
      << out;
  ASSERT_EQ(
      RunCommand(
          Facedyn("--quiet sim perform --face " + dir.Join("face") +
                  " --expression smile --motion platform --hz 9 --seconds 0.25 --fps 96 --out " +
                  dir.Join("take")),
          &out),
      0)
      << out;
  ASSERT_EQ(RunCommand(Facedyn("take info --json " + dir.Join("take") + " 2>/dev/null"), &out), 0)
      << out;
  const auto json = nlohmann::json::parse(out);
  EXPECT_EQ(json["frames"], 24);
  EXPECT_EQ(json["fps"], 96.0);
  EXPECT_EQ(json["expression"], "smile");
  EXPECT_EQ(json["platform_hz"], 9.0);
  EXPECT_EQ(json["channels"], nlohmann::json({"dynamic_offset", "quasistatic"}));
  EXPECT_EQ(json["has_jaw"], true);
}

TEST(Cli, SimPerformBadArgumentsAreClearErrors) {
  TempDir dir;
  std::string out;
  EXPECT_EQ(RunCommand(Facedyn("sim perform --motion wobble --out " + dir.Join("t")), &out), 1);
  EXPECT_THAT(out, HasSubstr("wobble"));
  EXPECT_EQ(
      RunCommand(Facedyn("sim perform --expression grimace --seconds 0.1 --out " + dir.Join("t")),
                 &out),
      1);
  EXPECT_THAT(out, HasSubstr("grimace"));
  EXPECT_EQ(
      RunCommand(Facedyn("sim perform --face " + dir.Join("nope") + " --out " + dir.Join("t")),
                 &out),
      1);
  EXPECT_THAT(out, HasSubstr("nope"));
  EXPECT_EQ(RunCommand(Facedyn("sim perform --seconds -1 --out " + dir.Join("t")), &out), 1);
  EXPECT_THAT(out, HasSubstr("seconds"));
  EXPECT_EQ(
      RunCommand(Facedyn("sim face --ict " + dir.Join("no-ict") + " --out " + dir.Join("f")), &out),
      1);
  EXPECT_THAT(out, HasSubstr("no-ict"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("t/take.json")));
}

// A bad demo flag is refused before any stage runs (nothing is written).
TEST(Cli, DemoRefusesUnknownRemovalTargets) {
  TempDir dir;
  std::string out;
  EXPECT_NE(
      RunCommand(Facedyn("demo --quick --removal-targets exact --out " + dir.Join("d")), &out), 0);
  EXPECT_THAT(out, HasSubstr("--removal-targets"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("d/metrics.json")));
}

// The joint training's options are checked before any stage runs.
TEST(Cli, DemoRefusesBadJointTrainingOptions) {
  TempDir dir;
  std::string out;
  EXPECT_NE(
      RunCommand(Facedyn("demo --quick --joint-training --joint-steps 0 --out " + dir.Join("d")),
                 &out),
      0);
  EXPECT_THAT(out, HasSubstr("--joint-steps"));
  EXPECT_NE(
      RunCommand(Facedyn("demo --quick --joint-training --cycle-weight -1 --out " + dir.Join("d")),
                 &out),
      0);
  EXPECT_THAT(out, HasSubstr("--cycle-weight"));
  // The joint phase's settings without the joint training would be silently ignored: refused.
  for (const char* flag : {"--joint-early-stopping", "--joint-cycle-trains-f-only"}) {
    EXPECT_NE(
        RunCommand(Facedyn(std::string("demo --quick ") + flag + " --out " + dir.Join("d")), &out),
        0)
        << flag;
    EXPECT_THAT(out, HasSubstr("--joint-training")) << flag;
  }
  EXPECT_FALSE(std::filesystem::exists(dir.Join("d")));
}

// --seeds: a repeated seed or one that is not a number is refused before any stage runs.
TEST(Cli, DemoRefusesRepeatedOrMalformedSeeds) {
  TempDir dir;
  std::string out;
  EXPECT_NE(RunCommand(Facedyn("demo --quick --seeds 1,2,1 --out " + dir.Join("d")), &out), 0);
  EXPECT_THAT(out, HasSubstr("--seeds: 1 is given twice"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("d")));
  EXPECT_NE(RunCommand(Facedyn("demo --quick --seeds 1,x --out " + dir.Join("e")), &out), 0);
  EXPECT_THAT(out, HasSubstr("--seeds"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("e")));
}

}  // namespace
}  // namespace facedyn
