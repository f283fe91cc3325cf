// `facedyn detail train` and `facedyn detail apply`: fine-scale detail for sparse HMC markers
// (Masquerade, detail/masquerade.h). app/ only wires: takes in, model file or take out.
//
// Training reads markers from takes in the rig's topology: the model's marker surface points
// evaluated on each frame's skin in the skull frame (T(t)^-1 x), Masquerade's virtual markers on
// high-resolution captures. `apply` reads the take's labelled marker tracks when it has them (a
// reconstructed head-mounted-camera take, config/capture/hmc.yaml; missing markers held, see
// detail/marker_input.h), else the same virtual markers on the take's skin (`--markers-from`).

#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "app/command.h"
#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/marker_tracks.h"
#include "core/parallel_for.h"
#include "core/progress.h"
#include "core/take.h"
#include "detail/marker_input.h"
#include "detail/masquerade.h"

namespace facedyn::app {
namespace {

Eigen::Matrix3Xd SkinInSkull(const Take& take, int f) {
  return take.world_from_skull[f].Inverse().Apply(take.FramePositions(f));
}

}  // namespace

void AddDetailCommands(CLI::App& app, CommandRunner* selected) {
  auto* detail = app.add_subcommand(
      "detail",
      "Fine-scale detail for sparse head-mounted-camera markers (Masquerade, Moser et al. 2017)");
  detail->require_subcommand(1);

  struct TrainOptions {
    std::vector<std::string> takes;
    std::string face = "procedural";
    std::string markers = "80";
    std::string out;
    int frames = 80;
    int per_region = 0;
    double region_sigma_mm = detail::MasqueradeOptions{}.region_sigma_mm;
    double feature_sigma_mm = detail::MasqueradeOptions{}.feature_sigma_mm;
    double pose_cell_mm = detail::MasqueradeOptions{}.pose_cell_mm;
    std::string output_energy = "1";
    bool json = false;
  };
  auto train_options = std::make_shared<TrainOptions>();
  auto* train = detail->add_subcommand("train",
                                       "Learn a detail model from high-resolution takes of one "
                                       "subject (virtual markers on their skin)");
  train->add_option("--takes", train_options->takes, "High-resolution takes in the rig's topology")
      ->required();
  train->add_option("--face", train_options->face, "FaceRig folder, or 'procedural'")
      ->capture_default_str();
  train
      ->add_option("--markers", train_options->markers,
                   "Marker layout: a count (the rig's first N markers) or a file of marker names")
      ->capture_default_str();
  train->add_option("--out", train_options->out, "Model file to write")->required();
  train
      ->add_option("--frames", train_options->frames,
                   "Greedy global training frames (0: every frame)")
      ->capture_default_str();
  train
      ->add_option("--per-region", train_options->per_region,
                   "Greedy frames per region among the global ones (0: all of them)")
      ->capture_default_str();
  train
      ->add_option("--region-sigma-mm", train_options->region_sigma_mm,
                   "Falloff of the region blend weights")
      ->capture_default_str();
  train
      ->add_option("--feature-sigma-mm", train_options->feature_sigma_mm,
                   "Falloff of a region's pose triangles")
      ->capture_default_str();
  train
      ->add_option("--pose-cell-mm", train_options->pose_cell_mm,
                   "Cell of the pose's quadrature: one triangle carries each connected patch "
                   "of this size (0: every triangle; smaller model, larger cell)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  train
      ->add_option("--output-energy", train_options->output_energy,
                   "Fraction in (0, 1] of each region's offset energy its RBF keeps (principal "
                   "directions; 1: all, exact at the training frames; less: a smaller model), or "
                   "'auto': chosen on the training frames --frames left out")
      ->check([](const std::string& text) -> std::string {
        if (text == "auto") return "";
        try {
          size_t used = 0;
          const double value = std::stod(text, &used);
          if (used == text.size() && value > 0 && value <= 1) return "";
        } catch (const std::exception&) {
        }
        return "must be a number in (0, 1] or 'auto', got '" + text + "'";
      })
      ->capture_default_str();
  train->add_flag("--json", train_options->json, "Print a JSON summary on stdout");
  train->callback([train_options, selected] {
    *selected = [train_options]() -> Status {
      const TrainOptions& o = *train_options;
      if (o.frames < 0)
        return InvalidArgumentError("--frames must be >= 0, got " + std::to_string(o.frames));
      if (o.per_region < 0)
        return InvalidArgumentError("--per-region must be >= 0, got " +
                                    std::to_string(o.per_region));
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(o.face));
      detail::DetailTrainingSet set;
      set.subject = rig.name;
      set.neutral = rig.neutral;
      FACEDYN_ASSIGN_OR_RETURN(set.markers, SelectMarkerLayout(rig, o.markers, "--markers"));
      for (const std::string& dir : o.takes) {
        FACEDYN_ASSIGN_OR_RETURN(const Take take, LoadTake(dir));
        if (take.vertex_count() != rig.vertex_count()) {
          return FailedPreconditionError(dir + ": " + std::to_string(take.vertex_count()) +
                                         " vertices, rig '" + rig.name + "' has " +
                                         std::to_string(rig.vertex_count()));
        }
        for (int f = 0; f < take.frame_count(); ++f) set.frames_mm.push_back(SkinInSkull(take, f));
      }
      detail::MasqueradeOptions options;
      options.global_frames = o.frames;
      options.per_region_frames = o.per_region;
      options.region_sigma_mm = o.region_sigma_mm;
      options.feature_sigma_mm = o.feature_sigma_mm;
      options.pose_cell_mm = o.pose_cell_mm;
      options.output_energy =
          o.output_energy == "auto" ? detail::kChooseOutputEnergy : std::stod(o.output_energy);
      detail::MasqueradeTrainingSummary summary;
      FACEDYN_ASSIGN_OR_RETURN(const detail::MasqueradeModel model,
                               detail::MasqueradeModel::Train(set, options, &summary));
      FACEDYN_RETURN_IF_ERROR(model.Save(o.out));
      if (o.json) {
        const Json json = {
            {"model", o.out},
            {"subject", rig.name},
            {"markers", set.markers.size()},
            {"training_frames", set.frames_mm.size()},
            {"selected_frames", summary.global_frames.size()},
            {"mean_frames_per_region", summary.mean_frames_per_region},
            {"memory_bytes", model.MemoryBytes()},
            {"pose_cell_mm", options.pose_cell_mm},
            {"output_energy", summary.output_energy},
            {"output_energy_validation_frames", summary.output_energy_validation_frames},
            {"train_s", summary.train_s}};
        std::printf("%s\n", json.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      } else {
        spdlog::info("trained on {} frames ({} selected) with {} markers; wrote {}",
                     set.frames_mm.size(), summary.global_frames.size(), set.markers.size(), o.out);
      }
      return Status::Ok();
    };
  });

  struct ApplyOptions {
    std::string take;
    std::string model;
    std::string out;
    std::string markers_from = "auto";
    int threads = 0;
    bool json = false;
  };
  auto apply_options = std::make_shared<ApplyOptions>();
  auto* apply = detail->add_subcommand(
      "apply",
      "Upsample a take: the model's markers read from it, the fine detail added, a take out");
  apply->add_option("--take", apply_options->take, "Input take in the model's rig topology")
      ->required();
  apply->add_option("--model", apply_options->model, "Model file from `facedyn detail train`")
      ->required();
  apply->add_option("--out", apply_options->out, "Output take folder")->required();
  apply
      ->add_option("--markers-from", apply_options->markers_from,
                   "tracks: the take's labelled marker tracks (a reconstructed HMC take); skin: "
                   "the markers' points on the take's skin; auto: tracks when the take has them")
      ->check(CLI::IsMember({"auto", "tracks", "skin"}))
      ->capture_default_str();
  apply
      ->add_option("--threads", apply_options->threads,
                   "Threads upsampling frames side by side (0: one per core)")
      ->check(CLI::Range(0, 256))
      ->capture_default_str();
  apply->add_flag("--json", apply_options->json, "Print a JSON summary on stdout");
  apply->callback([apply_options, selected] {
    *selected = [apply_options]() -> Status {
      const ApplyOptions& o = *apply_options;
      FACEDYN_ASSIGN_OR_RETURN(const detail::MasqueradeModel model,
                               detail::MasqueradeModel::Load(o.model));
      FACEDYN_ASSIGN_OR_RETURN(Take take, LoadTake(o.take));
      // The output keeps the take's topology, so only the vertex count must agree; the markers
      // must be the model's, by name.
      FACEDYN_RETURN_IF_ERROR(model.CheckCompatible(detail::MarkerNames(model.markers()),
                                                    take.vertex_count(), "take " + o.take));
      std::vector<Eigen::Matrix3Xd> marker_frames(take.frame_count());
      std::string source = "skin";
      detail::MarkerFrames tracked;
      if (o.markers_from != "skin") {
        StatusOr<MarkerTracks> tracks = LoadMarkerTracks(o.take);
        if (tracks.ok()) {
          FACEDYN_ASSIGN_OR_RETURN(
              tracked, detail::MarkersFromTracks(*tracks, take.world_from_skull, model.markers(),
                                                 model.neutral()));
          marker_frames = tracked.markers_mm;
          source = "tracks";
          if (!tracked.never_seen.empty()) {
            spdlog::warn("{} of the model's markers were never tracked (held at neutral): {}",
                         tracked.never_seen.size(), tracked.never_seen.front());
          }
        } else if (o.markers_from == "tracks" || tracks.status().code() != StatusCode::kNotFound) {
          return tracks.status().WithContext("--markers-from " + o.markers_from);
        }
      }
      if (source == "skin") {
        for (int f = 0; f < take.frame_count(); ++f) {
          const Eigen::Matrix3Xd in_skull = SkinInSkull(take, f);
          marker_frames[f].resize(3, static_cast<int>(model.markers().size()));
          for (size_t m = 0; m < model.markers().size(); ++m) {
            marker_frames[f].col(static_cast<int>(m)) = model.markers()[m].point.Evaluate(in_skull);
          }
        }
      }
      const auto start = std::chrono::steady_clock::now();
      std::vector<Eigen::Matrix3Xd> skins;
      {
        Progress progress("upsample", take.frame_count());
        FACEDYN_RETURN_IF_ERROR(
            model.ApplyFrames(marker_frames, &skins, nullptr, o.threads, &progress)
                .WithContext(o.take));
        progress.Finish();
      }
      const double seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      for (int f = 0; f < take.frame_count(); ++f) {
        take.positions.Frame(f) = take.world_from_skull[f].Apply(skins[f]).cast<float>();
      }
      take.channels.clear();  // the input's channels describe the input, not the result
      take.info.source = "detail apply";
      take.info.metadata["detail_model"] = o.model;
      take.info.metadata["detail_markers_from"] = source;
      FACEDYN_RETURN_IF_ERROR(SaveTake(take, o.out));
      if (o.json) {
        const Json json = {{"take", o.out},
                           {"frames", take.frame_count()},
                           {"markers", model.markers().size()},
                           {"markers_from", source},
                           {"marker_frames_filled", tracked.filled},
                           {"markers_never_tracked", tracked.never_seen},
                           {"threads", ParallelThreadCount(o.threads, take.frame_count())},
                           {"frames_per_s", seconds > 0 ? take.frame_count() / seconds : 0.0}};
        std::printf("%s\n", json.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      } else {
        spdlog::info("upsampled {} frames with {}; wrote {}", take.frame_count(), o.model, o.out);
      }
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
