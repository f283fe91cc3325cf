// `facedyn solve train|run|apply`: FDLS rig solving (solve/) from the command line. The work is
// solve/'s; this file reads flags and files and writes results.

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "app/command.h"
#include "core/json_io.h"
#include "core/parallel_for.h"
#include "core/take.h"
#include "solve/anchor.h"
#include "solve/fdls_solver.h"
#include "solve/marker_fit.h"
#include "solve/solve_config.h"
#include "solve/solve_io.h"
#include "solve/training_data.h"

namespace facedyn::app {
namespace {

std::vector<std::string> SplitCommas(const std::string& list) {
  std::vector<std::string> items;
  std::stringstream stream(list);
  std::string item;
  while (std::getline(stream, item, ',')) {
    if (!item.empty()) items.push_back(item);
  }
  return items;
}

}  // namespace

void AddSolveCommands(CLI::App& app, CommandRunner* selected) {
  auto* solve =
      app.add_subcommand("solve", "Rig solving after Weta's FDLS: markers to a rig's controls");
  solve->require_subcommand(1);

  struct TrainOptions {
    std::string rig = "procedural";
    std::string config;
    std::string out;
    int epochs = 0;
    uint64_t seed = 1;
    int threads = 1;
    int networks_at_once = 0;  // 0: the machine's cores
    bool json = false;
  };
  auto train_options = std::make_shared<TrainOptions>();
  auto* train =
      solve->add_subcommand("train", "Train the jaw and region networks on the rig's puppet");
  train->add_option("--rig", train_options->rig, "FaceRig folder, or 'procedural'")
      ->capture_default_str();
  train->add_option("--config", train_options->config,
                    "Region tables (YAML); default: the embedded procedural tables");
  train->add_option("--out", train_options->out, "Solver folder to write")->required();
  train->add_option("--epochs", train_options->epochs, "Epochs (0: the tables' value)");
  train->add_option("--seed", train_options->seed, "Training data and initialisation seed")
      ->capture_default_str();
  train->add_option("--threads", train_options->threads, "LibTorch threads per network")
      ->capture_default_str();
  train
      ->add_option("--networks-at-once", train_options->networks_at_once,
                   "Networks trained at once, one per thread (0: the machine's cores); the "
                   "result is the same whatever the count")
      ->capture_default_str();
  train->add_flag("--json", train_options->json, "Print the training summary as JSON");
  train->callback([train_options, selected] {
    *selected = [train_options]() -> Status {
      const TrainOptions& o = *train_options;
      if (o.epochs < 0 || o.threads < 1 || o.networks_at_once < 0) {
        return InvalidArgumentError(
            "--epochs must be >= 0, --threads >= 1 and --networks-at-once >= 0");
      }
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(o.rig));
      FACEDYN_ASSIGN_OR_RETURN(const solve::Puppet puppet, solve::MakePuppet(rig));
      solve::SolveConfig config;
      if (o.config.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(config, solve::ProceduralSolveConfig());
      } else {
        FACEDYN_ASSIGN_OR_RETURN(config, solve::ReadSolveConfig(o.config));
      }
      FACEDYN_ASSIGN_OR_RETURN(solve::ResolvedConfig resolved,
                               solve::ResolveSolveConfig(config, rig, puppet));
      if (o.epochs > 0) resolved.network.epochs = o.epochs;
      solve::TrainingDataOptions data_options;
      data_options.seed = o.seed;
      data_options.jaw_channels = resolved.jaw.channels;
      FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd weights,
                               solve::MakeTrainingWeights(puppet, data_options));
      FACEDYN_ASSIGN_OR_RETURN(const solve::TrainingSet data,
                               solve::MakeTrainingSet(puppet, weights, data_options));
      solve::FdlsTrainOptions train_settings;
      train_settings.seed = o.seed;
      train_settings.num_threads = o.threads;
      train_settings.concurrent_networks =
          o.networks_at_once > 0 ? o.networks_at_once : ParallelThreadCount(0, 1 << 20);
      train_settings.show_progress = !o.json;
      std::vector<solve::RegionTrainSummary> summaries;
      FACEDYN_ASSIGN_OR_RETURN(
          const solve::FdlsSolver solver,
          solve::FdlsSolver::Train(puppet, resolved, data, train_settings, &summaries));
      FACEDYN_RETURN_IF_ERROR(solver.Save(o.out));
      Json out = {{"rig", rig.name},
                  {"tuples", data.sample_count()},
                  {"out", o.out},
                  {"regions", Json::array()}};
      for (const solve::RegionTrainSummary& s : summaries) {
        out["regions"].push_back({{"region", s.region},
                                  {"markers", s.markers},
                                  {"channels", s.outputs},
                                  {"validation_weight_rmse", s.validation_rmse},
                                  {"train_s", s.train_s}});
      }
      if (o.json) {
        std::printf("%s\n", out.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      } else {
        spdlog::info("wrote FDLS solver for rig '{}' to {} ({} training tuples)", rig.name, o.out,
                     data.sample_count());
      }
      return Status::Ok();
    };
  });

  struct RunOptions {
    std::string markers;
    std::string take;
    std::string rig = "procedural";
    std::string channel;
    std::string from = "auto";
    std::string model;
    std::string out;
    int anchor = -1;
    std::string finetune;
    double smoothness = 0.0;
    bool json = false;
  };
  auto run_options = std::make_shared<RunOptions>();
  auto* run = solve->add_subcommand(
      "run", "Solve labelled markers (a CSV, or read off a take) into a weights CSV");
  auto* markers_option =
      run->add_option("--markers", run_options->markers,
                      "Labelled markers CSV (time_s, <marker>_x,_y,_z; skull frame, mm)");
  auto* take_option = run->add_option(
      "--take", run_options->take,
      "Take in the rig's topology (e.g. reconstructed): its markers in the skull frame");
  markers_option->excludes(take_option);
  run->add_option("--rig", run_options->rig,
                  "With --take: the take's FaceRig folder, or 'procedural'")
      ->capture_default_str();
  run->add_option("--channel", run_options->channel,
                  "With --take: solve a channel of the take (e.g. a removal's output) instead of "
                  "its positions");
  run->add_option("--from", run_options->from,
                  "With --take: 'tracks' (the reconstruction's labelled markers, "
                  "marker_tracks.csv), 'mesh' (the markers' points on the fitted mesh) or 'auto' "
                  "(tracks when the take has them and no --channel is given)")
      ->check(CLI::IsMember({"auto", "tracks", "mesh"}))
      ->capture_default_str();
  run->add_option("--model", run_options->model, "Solver folder (facedyn solve train --out)")
      ->required();
  run->add_option("--out", run_options->out,
                  "Weights CSV to write (time_s, one column per channel); its JSON twin goes "
                  "beside it (W.csv -> W.json)")
      ->required();
  run->add_option("--anchor", run_options->anchor,
                  "Neutral-ish anchor frame for shape alignment (FDLS 4.4.2); -1: none")
      ->capture_default_str();
  run->add_option(
      "--finetune", run_options->finetune,
      "Channels to fine-tune on the marker residual (FDLS 4.5), comma-separated, or 'all'");
  run->add_option("--smoothness", run_options->smoothness,
                  "Temporal smoothness of the fine-tuning (mm^2)")
      ->capture_default_str();
  run->add_flag("--json", run_options->json, "Print the figures as JSON");
  run->callback([run_options, selected] {
    *selected = [run_options]() -> Status {
      const RunOptions& o = *run_options;
      FACEDYN_ASSIGN_OR_RETURN(const solve::FdlsSolver solver, solve::FdlsSolver::Load(o.model));
      const solve::Puppet& puppet = solver.puppet();
      if (o.markers.empty() == o.take.empty()) {
        return InvalidArgumentError("solve run needs exactly one of --markers CSV or --take TAKE");
      }
      solve::MarkerFrames frames;
      if (!o.take.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(o.rig));
        FACEDYN_ASSIGN_OR_RETURN(const Take take, LoadTake(o.take));
        if (o.from == "tracks" && !o.channel.empty()) {
          return InvalidArgumentError(
              "--from tracks solves the labelled markers; --channel is "
              "for --from mesh");
        }
        const auto tracks = LoadMarkerTracks(o.take);
        if (!tracks.ok() &&
            (o.from == "tracks" || tracks.status().code() != StatusCode::kNotFound)) {
          return tracks.status();
        }
        if (tracks.ok() && (o.from == "tracks" || (o.from == "auto" && o.channel.empty()))) {
          if (tracks->frame_count() != take.frame_count()) {
            return InvalidArgumentError(fmt::format("{}: marker tracks have {} frames, the take {}",
                                                    o.take, tracks->frame_count(),
                                                    take.frame_count()));
          }
          spdlog::info("solving the take's labelled marker tracks ({})", kMarkerTracksFile);
          FACEDYN_ASSIGN_OR_RETURN(
              frames, solve::MarkersFromTracks(puppet, *tracks, take.world_from_skull));
        } else {
          FACEDYN_ASSIGN_OR_RETURN(frames, solve::MarkersFromTake(puppet, rig, take, o.channel));
        }
      } else {
        if (!o.channel.empty()) return InvalidArgumentError("--channel needs --take");
        if (o.from != "auto") return InvalidArgumentError("--from needs --take");
        FACEDYN_ASSIGN_OR_RETURN(frames, solve::ReadMarkersCsv(o.markers, puppet));
      }
      const std::string source = o.take.empty() ? o.markers : o.take;
      const int n = static_cast<int>(frames.time_s.size());
      Eigen::MatrixXd markers = frames.markers_in_skull;
      if (o.anchor >= 0) {
        if (o.anchor >= n) {
          return InvalidArgumentError(
              fmt::format("--anchor {}: {} has frames 0..{}", o.anchor, source, n - 1));
        }
        if (!frames.present.col(o.anchor).all()) {
          return InvalidArgumentError(
              fmt::format("--anchor {}: a marker is missing in that frame", o.anchor));
        }
        FACEDYN_ASSIGN_OR_RETURN(
            const Eigen::VectorXd offsets,
            solve::AnchorOffsets(puppet, markers, o.anchor,
                                 Eigen::VectorXd::Zero(puppet.channel_count())));
        FACEDYN_ASSIGN_OR_RETURN(markers, solve::AlignToAnchor(markers, offsets));
      }
      FACEDYN_ASSIGN_OR_RETURN(Eigen::MatrixXd weights, solver.Solve(markers, frames.present));
      const double network_rmse_mm = solve::MarkerRmseMm(puppet, weights, markers, &frames.present);
      Json out = {{"frames", n}, {"network_marker_rmse_mm", network_rmse_mm}};
      if (!o.finetune.empty()) {
        solve::MarkerFitOptions fit;
        fit.smoothness = o.smoothness;
        if (o.finetune != "all") {
          for (const std::string& name : SplitCommas(o.finetune)) {
            const int c = puppet.ChannelIndex(name);
            if (c < 0) {
              return InvalidArgumentError(fmt::format(
                  "--finetune: '{}' is not a channel of rig '{}'", name, puppet.rig_name));
            }
            fit.free_channels.push_back(c);
          }
        }
        solve::MarkerFitSummary summary;
        FACEDYN_ASSIGN_OR_RETURN(
            weights,
            solve::FitWeightsToMarkers(puppet, markers, weights, &frames.present, fit, &summary));
        out["finetuned_marker_rmse_mm"] = summary.final_rmse_mm;
        out["finetune_converged"] = summary.converged;
      }
      FACEDYN_RETURN_IF_ERROR(solve::WriteWeightsCsv(o.out, puppet, frames.time_s, weights));
      const std::string json_twin = solve::WeightsJsonTwinPath(o.out);
      FACEDYN_RETURN_IF_ERROR(solve::WriteWeightsJson(json_twin, puppet, frames.time_s, weights));
      out["weights_csv"] = o.out;
      out["weights_json"] = json_twin;
      if (o.json) {
        std::printf("%s\n", out.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      } else {
        spdlog::info("solved {} frames into {} and {} (marker RMSE {:.3f} mm)", n, o.out, json_twin,
                     out.value("finetuned_marker_rmse_mm", network_rmse_mm));
      }
      return Status::Ok();
    };
  });

  struct ApplyOptions {
    std::string weights;
    std::string rig = "procedural";
    std::string out;
  };
  auto apply_options = std::make_shared<ApplyOptions>();
  auto* apply =
      solve->add_subcommand("apply", "Drive a rig with a weights CSV or JSON; write a Take");
  apply
      ->add_option("--weights", apply_options->weights,
                   "Weights CSV (time_s, one column per channel), or its JSON twin (.json)")
      ->required();
  apply->add_option("--rig", apply_options->rig, "FaceRig folder, or 'procedural'")
      ->capture_default_str();
  apply->add_option("--out", apply_options->out, "Take folder to write")->required();
  apply->callback([apply_options, selected] {
    *selected = [apply_options]() -> Status {
      const ApplyOptions& o = *apply_options;
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(o.rig));
      FACEDYN_ASSIGN_OR_RETURN(const BlendshapeWeightsTrack track,
                               ReadBlendshapeWeights(o.weights));
      FACEDYN_ASSIGN_OR_RETURN(const Take take, solve::DriveRig(rig, track, o.weights));
      FACEDYN_RETURN_IF_ERROR(SaveTake(take, o.out));
      spdlog::info("drove rig '{}' with {} frames of {} into {}", rig.name, track.sample_count(),
                   o.weights, o.out);
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
