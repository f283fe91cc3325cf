#include "app/solve_demo.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <vector>

#include "core/file_util.h"
#include "core/take.h"
#include "solve/fdls_solver.h"
#include "solve/marker_fit.h"
#include "solve/puppet.h"
#include "solve/solve_config.h"
#include "solve/solve_io.h"
#include "solve/training_data.h"

namespace facedyn::app {
namespace {

double Round4(double v) { return std::round(v * 1e4) / 1e4; }

// RMS over frames and channels of solved - reference; the jaw channels alone in *jaw_rmse.
double WeightRmse(const Eigen::MatrixXd& solved, const Eigen::MatrixXd& reference,
                  const std::vector<int>& jaw, double* jaw_rmse) {
  double jaw_sum = 0.0;
  for (int c : jaw) jaw_sum += (solved.row(c) - reference.row(c)).squaredNorm();
  *jaw_rmse =
      jaw.empty() ? 0.0 : std::sqrt(jaw_sum / static_cast<double>(jaw.size() * solved.cols()));
  return std::sqrt((solved - reference).squaredNorm() / static_cast<double>(solved.size()));
}

// Frame-to-frame RMS change of the weights (per frame step): jiggle picked up by a solve shows
// as fast wiggle on otherwise smooth curves.
double WeightRoughness(const Eigen::MatrixXd& weights) {
  if (weights.cols() < 2) return 0.0;
  const Eigen::MatrixXd steps =
      weights.rightCols(weights.cols() - 1) - weights.leftCols(weights.cols() - 1);
  return std::sqrt(steps.squaredNorm() / static_cast<double>(steps.size()));
}

}  // namespace

SolveDemoOptions SolveDemoOptions::ForDemo(bool quick, uint64_t seed) {
  SolveDemoOptions options;
  options.quick = quick;
  options.seed = seed;
  options.epochs = quick ? 6 : 20;
  return options;
}

StatusOr<Json> RunSolveDemoStage(const FaceRig& face, const DemoDynamicsArtifacts& artifacts,
                                 const SolveDemoOptions& options, const std::string& out_dir) {
  const Take& filmed = artifacts.performance_reconstructed;
  const Take& removed = artifacts.performance_removed;
  const Take& simulated = artifacts.performance_simulated;
  if (filmed.frame_count() < 2 || removed.frame_count() != filmed.frame_count() ||
      simulated.frame_count() != filmed.frame_count()) {
    return FailedPreconditionError(
        "demo solve stage: the dynamics stage made no performance take (or its reconstructed, "
        "removed and simulated takes differ in length)");
  }
  const auto start = std::chrono::steady_clock::now();
  std::printf("\nRig solving (FDLS): the reconstructed %s take into the puppet's controls\n",
              filmed.info.expression.c_str());
  FACEDYN_ASSIGN_OR_RETURN(const solve::Puppet puppet, solve::MakePuppet(face));
  FACEDYN_ASSIGN_OR_RETURN(const solve::SolveConfig tables, solve::ProceduralSolveConfig());
  FACEDYN_ASSIGN_OR_RETURN(solve::ResolvedConfig config,
                           solve::ResolveSolveConfig(tables, face, puppet));
  config.network.epochs = options.epochs;
  solve::TrainingDataOptions data_options;
  data_options.seed = options.seed;
  data_options.jaw_channels = config.jaw.channels;
  if (options.quick) {
    data_options.random_combos = 600;
    data_options.rom_clips = 20;
    data_options.augment_copies = 1;
  }
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd poses,
                           solve::MakeTrainingWeights(puppet, data_options));
  FACEDYN_ASSIGN_OR_RETURN(const solve::TrainingSet data,
                           solve::MakeTrainingSet(puppet, poses, data_options));
  solve::FdlsTrainOptions train_options;
  train_options.seed = options.seed;
  // One LibTorch thread per network, two networks at once (the jaw's and the regions' are
  // independent): the default demo's solve stage took 23 s with two LibTorch threads and one
  // network at a time, 15-22 s this way (one run each; the solves are identical).
  train_options.num_threads = 1;
  train_options.concurrent_networks = 2;
  train_options.show_progress = true;
  std::vector<solve::RegionTrainSummary> summaries;
  FACEDYN_ASSIGN_OR_RETURN(
      const solve::FdlsSolver solver,
      solve::FdlsSolver::Train(puppet, config, data, train_options, &summaries));
  const double train_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const std::string solve_dir = JoinPath(out_dir, "solve");
  FACEDYN_RETURN_IF_ERROR(solver.Save(JoinPath(solve_dir, "solver")));

  // Reference weights, for scoring only: the QP solve of the simulator's exact quasistatic skin
  // (the same take without secondary dynamics, in the simulator's true skull frame).
  Take quasistatic = simulated;
  quasistatic.positions = simulated.channels.at("quasistatic");
  quasistatic.channels.clear();
  FACEDYN_ASSIGN_OR_RETURN(const solve::MarkerFrames reference_markers,
                           solve::MarkersFromTake(puppet, face, quasistatic));
  FACEDYN_ASSIGN_OR_RETURN(
      const Eigen::MatrixXd reference,
      solve::SolveMarkersQp(puppet, reference_markers.markers_in_skull, nullptr, nullptr));

  Json figures;
  std::vector<std::pair<std::string, Eigen::MatrixXd>> curves;  // for the plot
  std::printf("  %-28s %-20s %12s %10s %12s %10s\n", "markers from", "method", "weight RMSE",
              "jaw RMSE", "marker RMSE", "roughness");
  for (const auto& [key, take] :
       {std::pair<const char*, const Take*>{"from_reconstructed", &filmed},
        {"from_removed", &removed}}) {
    // Marker points on each frame's mesh (the dynamics stage's takes carry no marker tracks).
    FACEDYN_ASSIGN_OR_RETURN(const solve::MarkerFrames markers,
                             solve::MarkersFromTake(puppet, face, *take));
    FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd network, solver.Solve(markers.markers_in_skull));
    solve::MarkerFitSummary fit_summary;
    FACEDYN_ASSIGN_OR_RETURN(
        const Eigen::MatrixXd tuned,
        solve::FitWeightsToMarkers(puppet, markers.markers_in_skull, network, nullptr,
                                   solve::MarkerFitOptions{}, &fit_summary));
    for (const auto& [method, weights] :
         {std::pair<const char*, const Eigen::MatrixXd*>{"network", &network},
          {"network_finetuned", &tuned}}) {
      double jaw_rmse = 0.0;
      const double rmse = WeightRmse(*weights, reference, config.jaw.channels, &jaw_rmse);
      const double marker_rmse = solve::MarkerRmseMm(puppet, *weights, markers.markers_in_skull);
      const double roughness = WeightRoughness(*weights);
      figures[key][method] = {{"weight_rmse", Round4(rmse)},
                              {"jaw_weight_rmse", Round4(jaw_rmse)},
                              {"marker_rmse_mm", Round4(marker_rmse)},
                              {"weight_step_rms", Round4(roughness)}};
      std::printf("  %-28s %-20s %12.4f %10.4f %9.3f mm %10.4f\n",
                  key == std::string("from_reconstructed") ? "reconstructed (with jiggle)"
                                                           : "after removal (F)",
                  method, rmse, jaw_rmse, marker_rmse, roughness);
    }
    const std::string csv = JoinPath(solve_dir, std::string(key) + "_weights.csv");
    FACEDYN_RETURN_IF_ERROR(solve::WriteWeightsCsv(csv, puppet, markers.time_s, tuned));
    const std::string json_twin = solve::WeightsJsonTwinPath(csv);
    FACEDYN_RETURN_IF_ERROR(solve::WriteWeightsJson(json_twin, puppet, markers.time_s, tuned));
    figures[key]["weights_csv"] = csv;
    figures[key]["weights_json"] = json_twin;
    curves.emplace_back(key, tuned);
  }
  {
    figures["reference"] = {
        {"what",
         "QP solve of the simulator's exact quasistatic skin (scoring only; never seen by the "
         "solver)"},
        {"weight_step_rms", Round4(WeightRoughness(reference))},
        {"marker_rmse_mm",
         Round4(solve::MarkerRmseMm(puppet, reference, reference_markers.markers_in_skull))}};
  }

  // The plot: the channels that move most in the reference, three of them.
  std::vector<int> order(puppet.channel_count());
  std::iota(order.begin(), order.end(), 0);
  Eigen::VectorXd spread(puppet.channel_count());
  for (int c = 0; c < puppet.channel_count(); ++c)
    spread[c] = reference.row(c).maxCoeff() - reference.row(c).minCoeff();
  std::sort(order.begin(), order.end(), [&](int a, int b) { return spread[a] > spread[b]; });
  order.resize(std::min<size_t>(3, order.size()));
  Json channels = Json::array();
  for (int c : order) {
    auto row = [&](const Eigen::MatrixXd& m) {
      std::vector<double> v(m.cols());
      for (Eigen::Index f = 0; f < m.cols(); ++f) v[f] = Round4(m(c, f));
      return v;
    };
    channels.push_back({{"channel", puppet.channel_names[c]},
                        {"reference", row(reference)},
                        {"from_reconstructed", row(curves[0].second)},
                        {"from_removed", row(curves[1].second)}});
  }
  std::vector<double> time_s(filmed.time_s.begin(), filmed.time_s.end());
  for (double& t : time_s) t -= filmed.time_s.front();
  std::vector<double> plot_time_s = time_s;
  for (double& t : plot_time_s) t = Round4(t);
  figures["curves"] = {{"time_s", plot_time_s}, {"channels", channels}};

  // A second character with the same channel names driven by the removed take's weights.
  if (artifacts.second_face.vertex_count() > 0) {
    FACEDYN_ASSIGN_OR_RETURN(const BlendshapeWeightsTrack track,
                             solve::WeightsToTrack(puppet, time_s, curves[1].second));
    FACEDYN_ASSIGN_OR_RETURN(Take driven,
                             solve::DriveRig(artifacts.second_face, track, "the solved weights"));
    driven.info.source = "demo: subject B driven by A's solved weights (after removal)";
    const std::string driven_dir = JoinPath(out_dir, "takes/solve_driven_B");
    FACEDYN_RETURN_IF_ERROR(SaveTake(driven, driven_dir));
    figures["driven"] = {{"rig", artifacts.second_face.name},
                         {"take", driven_dir},
                         {"frames", driven.frame_count()}};
    std::printf("  drove %s with the solved weights: %s\n", artifacts.second_face.name.c_str(),
                driven_dir.c_str());
  }
  figures["training"] = {{"tuples", data.sample_count()},
                         {"epochs", config.network.epochs},
                         {"networks", summaries.size()},
                         {"train_s", Round4(train_s)}};
  figures["take"] = filmed.info.expression;
  figures["frames"] = filmed.frame_count();
  figures["note"] =
      "Markers are read off each frame's mesh (the filmed speech take's reconstruction, then "
      "after F's removal); the reference weights are scoring only.";
  return figures;
}

}  // namespace facedyn::app
