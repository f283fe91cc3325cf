#include "app/detail_demo.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <future>
#include <vector>

#include "app/capture_demo.h"
#include "app/rig_demo.h"
#include "capture/capture_config.h"
#include "core/file_util.h"
#include "core/marker_tracks.h"
#include "core/take.h"
#include "detail/marker_input.h"
#include "detail/masquerade.h"
#include "eval/metrics.h"
#include "reconstruct/pipeline.h"
#include "reconstruct/session_input.h"
#include "report/face_render.h"
#include "sim/performance.h"
#include "sim/sim_capture.h"

namespace facedyn::app {
namespace {

Status WritePng(const std::string& path, const std::vector<unsigned char>& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
  if (!out) return UnavailableError(path + ": write failed");
  return Status::Ok();
}

}  // namespace

DetailDemoOptions DetailDemoOptions::ForDemo(bool quick, uint64_t seed) {
  DetailDemoOptions options;
  options.quick = quick;
  options.seed = seed;
  if (quick) {  // the range of motion stays whole (31 poses in 10.7 s), sampled more sparsely
    options.rom_fps = 15.0;
    options.rom_frames = 160;
    options.global_frames = 60;
    options.hmc_seconds = 0.5;
  }
  return options;
}

StatusOr<Json> RunDetailDemoStage(const FaceRig& face, const eval::SimulatedCameraRig& cameras,
                                  const DetailDemoOptions& options, const std::string& out_dir) {
  const std::string dir = JoinPath(out_dir, "detail");
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(dir));
  const auto lips = face.regions.find("lips");
  if (lips == face.regions.end()) return NotFoundError("the demo face has no 'lips' region");

  // The HMC: its config names the cameras and the painted layout (what the studio painted, not
  // the truth).
  FACEDYN_ASSIGN_OR_RETURN(const std::string config_dir, FindConfigDir());
  const std::string config_path = JoinPath(config_dir, "capture/hmc.yaml");
  FACEDYN_ASSIGN_OR_RETURN(capture::CaptureConfig config, capture::LoadCaptureConfig(config_path));
  if (!config.sim) return InvalidArgumentError(config_path + " has no sim: section");
  config.duration_s = options.hmc_seconds;
  FACEDYN_ASSIGN_OR_RETURN(
      const sim::SimCaptureOptions sim_options,
      sim::ParseSimCaptureOptions(*config.sim, JoinPath(config_dir, "capture")));
  FACEDYN_ASSIGN_OR_RETURN(const std::vector<Marker> layout,
                           sim::PaintedMarkers(face, sim_options, config.cameras));
  std::printf("\nFine detail from a head-mounted camera (Masquerade, %zu HMC markers)\n",
              layout.size());

  // 2 (first, as it needs nothing from 1). The HMC take: filmed through the capture path,
  // reconstructed by the head-mounted path, on a thread of its own beside the range-of-motion
  // simulation (one core). The future's destructor waits for it on any early return.
  const std::string session_dir = JoinPath(dir, "hmc-session");
  const std::string take_name = "dialogue";
  struct HmcTake {
    std::string take_dir;
    double diameter_px = 0.0;  // the dots' diameter in the images, at the layout's mean depth
    double detect_s = 0.0;
    reconstruct::Reconstruction reconstruction;
  };
  FaceRig painted = face;
  painted.markers = layout;
  std::future<StatusOr<HmcTake>> hmc_future =
      std::async(std::launch::async, [&]() -> StatusOr<HmcTake> {
        HmcTake hmc;
        FACEDYN_ASSIGN_OR_RETURN(hmc.take_dir, CaptureSimulatedTake(config, session_dir, take_name));
        double depth = 0.0;
        for (const Marker& m : layout) {
          depth +=
              (config.cameras[0].cam_from_world * m.point.Evaluate(face.neutral.positions_mm)).z();
        }
        hmc.diameter_px = layout.front().diameter_mm * config.cameras[0].fx() * layout.size() /
                          std::max(1e-9, depth);
        reconstruct::SessionInputOptions input_options;
        input_options.detection = reconstruct::MarkerDetectionOptionsForDiameter(hmc.diameter_px);
        FACEDYN_ASSIGN_OR_RETURN(const reconstruct::SessionDetections input,
                                 reconstruct::DetectSessionTake(session_dir, take_name,
                                                                input_options));
        hmc.detect_s = input.detect_s;
        FACEDYN_ASSIGN_OR_RETURN(
            hmc.reconstruction,
            reconstruct::ReconstructTake(painted, input.cameras, input.detections, input.fps,
                                         input.head_mounted
                                             ? reconstruct::HeadMountedReconstructionOptions()
                                             : reconstruct::ReconstructionOptions()));
        return hmc;
      });

  // 1. Training: a range-of-motion performance (no head motion) reconstructed on the multi-view
  // rig, stabilised into the skull frame: Masquerade's high-resolution captures.
  // The same simulator films it as films the HMC take (sim/performance.h "range_of_motion"):
  // rendered by the rig's 8 cameras, dots detected (eval::FilmSimulatedTake).
  auto start = std::chrono::steady_clock::now();
  sim::PerformanceOptions rom_options;
  rom_options.expression = "range_of_motion";
  rom_options.motion.kind = sim::MotionKind::kNone;
  rom_options.fps = options.rom_fps;
  rom_options.seconds = options.rom_frames / rom_options.fps;
  rom_options.seed = options.seed;
  FACEDYN_ASSIGN_OR_RETURN(const Take rom, sim::SimulatePerformance(face, rom_options));
  FACEDYN_ASSIGN_OR_RETURN(const reconstruct::Reconstruction rom_reconstruction,
                           eval::FilmSimulatedTake(face, cameras, rom, options.seed));
  detail::DetailTrainingSet set;
  set.subject = face.name;
  set.neutral = face.neutral;
  set.markers = layout;
  for (int f = 0; f < rom_reconstruction.take.frame_count(); ++f) {
    set.frames_mm.push_back(rom_reconstruction.take.world_from_skull[f].Inverse().Apply(
        rom_reconstruction.take.FramePositions(f)));
  }
  detail::MasqueradeOptions masquerade_options;
  masquerade_options.global_frames = options.global_frames;
  detail::MasqueradeTrainingSummary summary;
  FACEDYN_ASSIGN_OR_RETURN(const detail::MasqueradeModel model,
                           detail::MasqueradeModel::Train(set, masquerade_options, &summary));
  const std::string model_path = JoinPath(dir, "detail.bin");
  FACEDYN_RETURN_IF_ERROR(model.Save(model_path));
  const double train_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("  trained on %zu reconstructed range-of-motion frames (%zu selected) in %.1f s\n",
              set.frames_mm.size(), summary.global_frames.size(), train_s);

  // 2. The HMC take (captured and reconstructed beside step 1, above).
  FACEDYN_ASSIGN_OR_RETURN(const HmcTake hmc, hmc_future.get());
  const std::string& take_dir = hmc.take_dir;
  const double diameter_px = hmc.diameter_px;
  const reconstruct::Reconstruction& reconstruction = hmc.reconstruction;
  const MarkerTracks tracks = reconstruct::MarkerTracksOf(painted, reconstruction);
  FACEDYN_ASSIGN_OR_RETURN(const detail::MarkerFrames markers,
                           detail::MarkersFromTracks(tracks, reconstruction.take.world_from_skull,
                                                     layout, face.neutral));
  const int frames = reconstruction.take.frame_count();
  std::vector<Eigen::Matrix3Xd> upsampled(frames), large(frames), truth(frames);
  start = std::chrono::steady_clock::now();
  FACEDYN_RETURN_IF_ERROR(model.ApplyFrames(markers.markers_mm, &upsampled, &large));
  const double upsample_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  // 3. Scoring only: the simulator's skin in the skull frame.
  FACEDYN_ASSIGN_OR_RETURN(const Take simulated, LoadTake(JoinPath(take_dir, "ground_truth/take")));
  if (simulated.frame_count() < frames) {
    return InternalError("the HMC take's truth has fewer frames than its reconstruction");
  }
  std::vector<double> marker_errors;
  int observed = 0;
  for (int f = 0; f < frames; ++f) {
    truth[f] = simulated.world_from_skull[f].Inverse().Apply(simulated.FramePositions(f));
    for (int m = 0; m < tracks.marker_count(); ++m) {
      if (tracks.state[f][m] != MarkerTrackState::kObserved) continue;
      ++observed;
      marker_errors.push_back(
          (tracks.world_mm.block(3 * m, f, 3, 1) - layout[m].point.Evaluate(truth[f])).norm());
    }
  }
  std::vector<double> sorted = marker_errors;
  std::sort(sorted.begin(), sorted.end());
  const eval::DetailErrors masquerade = eval::ScoreDetail(upsampled, truth, lips->second);
  const eval::DetailErrors large_only = eval::ScoreDetail(large, truth, lips->second);
  std::printf(
      "  HMC take: %d frames, %.0f%% of marker-frames observed, markers %.3f mm median "
      "off their true positions\n",
      frames, 100.0 * observed / std::max<size_t>(1, frames * layout.size()),
      sorted.empty() ? 0.0 : sorted[sorted.size() / 2]);
  std::printf("  %-22s %10s %10s %10s %10s\n", "method", "face mean", "face p95", "lips mean",
              "lips p95");
  for (const auto& [name, e] :
       {std::pair<const char*, eval::DetailErrors>{"large-scale only", large_only},
        {"Masquerade", masquerade}}) {
    std::printf("  %-22s %10.3f %10.3f %10.3f %10.3f\n", name, e.face_mean_mm, e.face_p95_mm,
                e.lips_mean_mm, e.lips_p95_mm);
  }

  // Takes for the viewer and other tools: the upsampled and large-scale skins (skull frame =
  // the helmet's, the reconstruction's identity pose).
  for (const auto& [name, skins] :
       {std::pair<const char*, const std::vector<Eigen::Matrix3Xd>*>{"hmc_masquerade", &upsampled},
        {"hmc_large_scale", &large}}) {
    Take take = reconstruction.take;
    take.channels.clear();
    for (int f = 0; f < frames; ++f) {
      take.positions.Frame(f) = take.world_from_skull[f].Apply((*skins)[f]).cast<float>();
    }
    take.info.source = std::string("detail apply (") + name + ")";
    take.info.metadata["detail_model"] = model_path;
    FACEDYN_RETURN_IF_ERROR(SaveTake(take, JoinPath(out_dir, std::string("takes/") + name)));
  }

  // Renders of the frame where the large-scale skin is worst over the lips: the shapes, then the
  // signed error along the normal (red out of the true skin, green into it).
  int shown = 0;
  double worst = -1.0;
  for (int f = 0; f < frames; ++f) {
    double lips_error = 0.0;
    for (int v : lips->second) lips_error += (large[f].col(v) - truth[f].col(v)).norm();
    if (lips_error > worst) {
      worst = lips_error;
      shown = f;
    }
  }
  const std::string render_dir = JoinPath(out_dir, "renders");
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(render_dir));
  report::OffsetRenderOptions render_options;
  render_options.width_px = 240;
  render_options.height_px = 293;
  render_options.range_mm = 1.0;
  const Eigen::Matrix3Xf zero = Eigen::Matrix3Xf::Zero(3, face.vertex_count());
  struct View {
    const char* name;
    const Eigen::Matrix3Xd* shape;
    bool error;
  };
  const View views[] = {{"truth (simulator)", &truth[shown], false},
                        {"Masquerade", &upsampled[shown], false},
                        {"large-scale only", &large[shown], false},
                        {"Masquerade - truth", &upsampled[shown], true},
                        {"large-scale only - truth", &large[shown], true}};
  Json images = Json::array();
  int index = 0;
  for (const View& view : views) {
    const Eigen::Matrix3Xf shape = view.shape->cast<float>();
    const Eigen::Matrix3Xf offsets =
        view.error ? Eigen::Matrix3Xf((*view.shape - truth[shown]).cast<float>()) : zero;
    const std::string path =
        JoinPath("renders", fmt::format("detail_{:02d}_frame{:04d}.png", index++, shown));
    FACEDYN_RETURN_IF_ERROR(
        WritePng(JoinPath(out_dir, path),
                 report::RenderSignedOffsetPng(face.neutral, shape, offsets, render_options)));
    images.push_back(
        {{"view", view.name}, {"path", path}, {"frame", shown}, {"error", view.error}});
  }

  Json json;
  json["training"] = {
      {"rom_frames", set.frames_mm.size()},
      {"selected_frames", summary.global_frames.size()},
      {"reconstructed_from", "filmed (rendered by the rig's 8 cameras, dots detected)"},
      {"train_s", train_s},
      {"model", model_path},
      {"model_bytes", model.MemoryBytes()}};
  json["hmc"] = {
      {"config", config_path},
      {"performance", sim_options.performance.expression + ", head motion " +
                          sim::MotionKindName(sim_options.performance.motion.kind)},
      {"session", session_dir},
      {"frames", frames},
      {"markers", layout.size()},
      {"marker_diameter_px", diameter_px},
      {"observed_fraction", double(observed) / std::max<size_t>(1, frames * layout.size())},
      {"marker_frames_filled", markers.filled},
      {"marker_error_median_mm", sorted.empty() ? 0.0 : sorted[sorted.size() / 2]},
      {"marker_error_p95_mm", eval::Percentile95(sorted)},
      {"detect_s", hmc.detect_s},
      {"upsample_frames_per_s", frames / std::max(1e-9, upsample_s)}};
  json["methods"] = {{"large_scale_only", eval::DetailErrorsJson(large_only)},
                     {"masquerade", eval::DetailErrorsJson(masquerade)}};
  json["masquerade_over_large_scale_face_mean"] =
      masquerade.face_mean_mm / std::max(1e-12, large_only.face_mean_mm);
  json["images"] = images;
  json["range_mm"] = render_options.range_mm;
  return json;
}

}  // namespace facedyn::app
