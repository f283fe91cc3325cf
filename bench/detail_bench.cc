// detail_bench: the figures of issue 22 (fine-scale detail from sparse HMC markers, Masquerade),
// printed as JSON.
//
// Data, as Masquerade built its evaluation (Moser et al. 2017, section 3): a high-resolution
// range-of-motion performance of one subject for training, virtual HMC markers attached to
// those meshes, and a held-out dialogue-like performance for testing. Here the subject is the
// procedural FaceRig (sim/procedural_face.h) and a frame is its skin in the skull frame for a
// blendshape weight vector (the quasistatic skin: no head motion, no jiggle), so the truth is
// exact:
//   - training: a range of motion, `--train-frames` frames (default 320, the paper's count) at
//     30 fps of a sequence through every expression at full and half weight and each mouth
//     shape with the jaw half open, 3 poses per second (sim/expression_curve.h);
//   - test: a speech-like sequence through the visemes sim/performance.cc uses for "speech"
//     (4.5 syllables/s), `--test-frames` frames at 60 fps, another seed;
//   - markers: the first `--markers` of the rig's painted markers (farthest-point order, so any
//     prefix is spread over the face).
// Methods, all on the same markers: large-scale only (Laplacian deformation), Bickel et al.
// 2008 (per-vertex RBFs on marker-graph edge strain, 80 greedy frames), Masquerade (per-region
// RBFs on deformation gradients) with every frame, 80 global greedy frames, 40 and 20 per
// region. Errors: |x - x_true| per vertex and frame (mm), mean and 95th percentile over the face
// (every vertex of the rig) and over the lips (rig region "lips").
// Output compression ("masquerade_global_80_compressed"): the 80-global model with each region
// RBF keeping the leading principal directions of its offsets (MasqueradeOptions::
// output_energy), the energy chosen among 0.9999, 0.999, 0.99, 0.9 on a validation speech draw
// (seed + 2000, never the test) as the smallest whose validation face mean error is within 5% of
// the uncompressed model's; "output_compression_candidates" lists each candidate's validation
// error and size. "masquerade_global_80_auto": the energy `detail train --output-energy auto`
// chooses by the same rule on the training frames the global selection left out (no
// validation take: what a studio's training data alone allows).
// Speed: upsampling frames/s over the test markers (ApplyFrames), on one thread and on every
// core (frames side by side), five passes of each alternated, medians; on this machine.
//
// Head-mounted camera ("hmc" in each run; skipped with --no-hmc): the layout the simulated HMC
// paints (config/capture/hmc.yaml: the markers both helmet cameras see within its
// markers_max_view_angle_deg), the three methods (large-scale only, Bickel 80, Masquerade 80
// global) trained on that layout's virtual markers, and tested twice on the held-out speech:
// from the clean virtual markers, and from markers filmed by the HMC — every test frame rendered
// by both cameras (sim/virtual_camera.h, the config's render options and noise), detected,
// triangulated and labelled by reconstruct's head-mounted path (reconstruct/pipeline.h
// HeadMountedReconstructionOptions), missing markers held (detail/marker_input.h). The cameras
// are the config's exact models (no calibration error). Reported beside the errors: the filmed
// markers' error against their true positions and how many marker-frames were filled.
//
//   detail_bench [--vertices N] [--markers N] [--train-frames N] [--test-frames N]
//                [--global-frames N] [--sigma-mm S] [--feature-sigma-mm S] [--edge-sigma-mm S]
//                [--seed N] [--seeds 1,2,3] [--quick] [--no-hmc] [--ict DIR]
//
// --ict DIR: the subject is the ICT-FaceKit face region (sim/ict_import.h; 9,409 vertices, the
// speed figure issue 22 names) instead of the procedural face; its expressions are the ARKit
// combinations of sim/expressions.h.
//
// --seeds: one run per seed (the seed draws both performances' timing and pose order), then a
// "summary" with each figure's mean and sample standard deviation over the seeds.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "bench/bench_flags.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/parallel_for.h"
#include "detail/bickel.h"
#include "capture/capture_config.h"
#include "core/marker_tracks.h"
#include "detail/marker_input.h"
#include "detail/masquerade.h"
#include "eval/metrics.h"
#include "reconstruct/marker_detection.h"
#include "reconstruct/pipeline.h"
#include "sim/expression_curve.h"
#include "sim/expressions.h"
#include "sim/ict_import.h"
#include "sim/procedural_face.h"
#include "sim/sim_capture.h"
#include "sim/virtual_camera.h"

namespace {

using facedyn::Json;
using Clock = std::chrono::steady_clock;
namespace detail = facedyn::detail;

double Seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}
double Number(const char* text, const std::string& flag) {
  return facedyn::bench::FlagNumber("detail_bench", flag, text);
}
long long Integer(const char* text, const std::string& flag) {
  return facedyn::bench::FlagInteger("detail_bench", flag, text);
}

struct Settings {
  int vertices = 9409;  // the ICT-FaceKit face region's count (issue 22's speed figure)
  int markers = 80;
  int train_frames = 320;
  int test_frames = 300;
  int global_frames = 80;
  // Falloffs chosen on `--quick --seed 1` (region 4/6/10, feature 10/20/30, edge 5/6/10/20 mm,
  // each method's lowest mean face error); report figures with other seeds.
  double sigma_mm = 4.0;           // region blend falloff
  double feature_sigma_mm = 20.0;  // falloff of the triangles in a region's pose
  double edge_sigma_mm = 20.0;     // Bickel: falloff of a vertex's edge weights
  double pose_cell_mm = detail::MasqueradeOptions{}.pose_cell_mm;  // the pose's quadrature cell
  bool hmc = true;
  std::string ict_dir;  // --ict: the ICT-FaceKit face region (9,409 vertices) instead
};

std::vector<Eigen::Matrix3Xd> Frames(const facedyn::FaceRig& rig,
                                     const facedyn::sim::ExpressionCurve& curve, int count,
                                     double fps) {
  std::vector<Eigen::Matrix3Xd> frames;
  for (int f = 0; f < count; ++f) frames.push_back(rig.Evaluate(curve.Weights(f / fps)));
  return frames;
}

// Upsampling speed over the test markers: `apply_frames(threads)` upsamples every frame (the
// models' ApplyFrames), run five times on one thread and five times on every core, alternated so
// both see the same machine; the medians in frames/s.
// Where a Masquerade model's bytes are (MasqueradeModel::MemoryBreakdown).
Json MemoryPartsJson(const detail::MasqueradeModel& model) {
  const detail::MasqueradeModel::MemoryParts parts = model.MemoryBreakdown();
  return {{"rbf_centres", parts.rbf_centres},
          {"rbf_coefficients", parts.rbf_coefficients},
          {"rbf_output_bases", parts.rbf_output_bases},
          {"region_vertices", parts.region_vertices},
          {"feature_triangles", parts.feature_triangles}};
}

struct UpsampleSpeed {
  double one_thread = 0.0;
  double all_cores = 0.0;
  int threads = 1;
  Json ToJson() const {
    return {{"upsample_frames_per_s_1_thread", one_thread},
            {"upsample_frames_per_s", all_cores},
            {"upsample_threads", threads}};
  }
};

template <typename F>
facedyn::StatusOr<UpsampleSpeed> MeasureUpsampleSpeed(int frames, F&& apply_frames) {
  std::vector<double> one, all;
  for (int pass = 0; pass < 5; ++pass) {
    for (int threads : {1, 0}) {
      const auto start = Clock::now();
      FACEDYN_RETURN_IF_ERROR(apply_frames(threads));
      (threads == 1 ? one : all).push_back(frames / Seconds(start));
    }
  }
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  UpsampleSpeed speed;
  speed.one_thread = median(one);
  speed.all_cores = median(all);
  speed.threads = facedyn::ParallelThreadCount(0, frames);
  return speed;
}

facedyn::Status ApplyAll(const facedyn::detail::MasqueradeModel& model,
                         const std::vector<Eigen::Matrix3Xd>& markers,
                         std::vector<Eigen::Matrix3Xd>* skins, int threads) {
  return model.ApplyFrames(markers, skins, nullptr, threads);
}
facedyn::Status ApplyAll(const facedyn::detail::BickelModel& model,
                         const std::vector<Eigen::Matrix3Xd>& markers,
                         std::vector<Eigen::Matrix3Xd>* skins, int threads) {
  return model.ApplyFrames(markers, skins, threads);
}

// MeasureUpsampleSpeed of a trained model over `markers`.
template <typename Model>
facedyn::StatusOr<UpsampleSpeed> SpeedOf(const Model& model,
                                         const std::vector<Eigen::Matrix3Xd>& markers) {
  std::vector<Eigen::Matrix3Xd> skins;
  return MeasureUpsampleSpeed(static_cast<int>(markers.size()), [&](int threads) {
    return ApplyAll(model, markers, &skins, threads);
  });
}

// The markers of `layout` on every `truth` frame (skull frame) as the simulated HMC films them:
// rendered by each camera, detected, triangulated and labelled with the head-mounted options,
// missing markers held. *marker_errors receives |filmed - true| per observed marker-frame.
facedyn::StatusOr<facedyn::detail::MarkerFrames> FilmHmcMarkers(
    const facedyn::FaceRig& rig, const std::vector<facedyn::Marker>& layout,
    const std::vector<facedyn::capture::CameraModel>& cameras,
    const facedyn::sim::RenderOptions& render, const std::vector<Eigen::Matrix3Xd>& truth,
    double fps, std::vector<double>* marker_errors, Json* stats) {
  namespace reconstruct = facedyn::reconstruct;
  facedyn::FaceRig painted = rig;
  painted.markers = layout;
  const facedyn::sim::FaceRenderer renderer(painted, render);
  // The dots' diameter in the images: at the layout's mean depth in camera 0.
  double depth = 0.0;
  for (const facedyn::Marker& m : layout) {
    depth += (cameras[0].cam_from_world * m.point.Evaluate(rig.neutral.positions_mm)).z();
  }
  depth /= layout.size();
  const double diameter_px = layout.front().diameter_mm * cameras[0].fx() / depth;
  reconstruct::MarkerDetectionOptions detection =
      reconstruct::MarkerDetectionOptionsForDiameter(diameter_px);
  detection.occlusion_refit = false;  // as reconstruct/session_input.h does for HMC takes
  std::vector<std::vector<std::vector<reconstruct::ImageObservation>>> detections(truth.size());
  std::vector<facedyn::sim::RenderWorkspace> workspaces(cameras.size());
  const auto start = Clock::now();
  for (size_t f = 0; f < truth.size(); ++f) {
    std::vector<cv::Mat> images;
    for (size_t c = 0; c < cameras.size(); ++c) {
      cv::Mat image(cameras[c].height_px, cameras[c].width_px, CV_8UC1);
      renderer.Render(cameras[c], truth[f], (uint64_t{c} << 40) ^ f, &workspaces[c], image.data);
      images.push_back(image);
    }
    const auto found = reconstruct::DetectMarkersInImages(images, detection);
    detections[f].resize(cameras.size());
    for (size_t c = 0; c < cameras.size(); ++c) {
      if (!found[c].ok()) return found[c].status();
      for (const reconstruct::MarkerDetection& d : *found[c]) {
        reconstruct::ImageObservation o;  // as reconstruct/session_input.cc builds them
        o.camera = static_cast<int>(c);
        o.detection = static_cast<int>(detections[f][c].size());
        o.pixel = d.center_px;
        o.weight = d.quality;
        detections[f][c].push_back(o);
      }
    }
  }
  const double film_s = Seconds(start);
  FACEDYN_ASSIGN_OR_RETURN(
      const reconstruct::Reconstruction reconstruction,
      reconstruct::ReconstructTake(painted, cameras, detections, fps,
                                   reconstruct::HeadMountedReconstructionOptions()));
  const facedyn::MarkerTracks tracks = reconstruct::MarkerTracksOf(painted, reconstruction);
  FACEDYN_ASSIGN_OR_RETURN(
      facedyn::detail::MarkerFrames frames,
      facedyn::detail::MarkersFromTracks(tracks, reconstruction.take.world_from_skull, layout,
                                         rig.neutral));
  int observed = 0;
  for (int f = 0; f < tracks.frame_count(); ++f) {
    for (int m = 0; m < tracks.marker_count(); ++m) {
      if (tracks.state[f][m] != facedyn::MarkerTrackState::kObserved) continue;
      ++observed;
      marker_errors->push_back(
          (tracks.world_mm.block(3 * m, f, 3, 1) - layout[m].point.Evaluate(truth[f])).norm());
    }
  }
  std::vector<double> sorted = *marker_errors;
  std::sort(sorted.begin(), sorted.end());
  double sq = 0;
  for (double e : sorted) sq += e * e;
  *stats = {{"marker_diameter_px", diameter_px},
            {"observed_fraction", double(observed) / (tracks.frame_count() * layout.size())},
            {"marker_frames_filled", frames.filled},
            {"markers_never_tracked", frames.never_seen.size()},
            {"marker_error_median_mm", sorted.empty() ? 0.0 : sorted[sorted.size() / 2]},
            {"marker_error_rms_mm", sorted.empty() ? 0.0 : std::sqrt(sq / sorted.size())},
            {"marker_error_p95_mm", facedyn::eval::Percentile95(sorted)},
            {"render_and_detect_s", film_s}};
  return frames;
}

// The HMC comparison of one seed (see the header).
facedyn::StatusOr<Json> RunHmc(const Settings& s, const facedyn::FaceRig& rig,
                               const std::vector<Eigen::Matrix3Xd>& rom,
                               const std::vector<Eigen::Matrix3Xd>& truth,
                               const std::vector<int>& lips) {
  namespace sim = facedyn::sim;
  const std::string config_path = std::string(FACEDYN_SOURCE_DIR) + "/config/capture/hmc.yaml";
  FACEDYN_ASSIGN_OR_RETURN(const facedyn::capture::CaptureConfig config,
                           facedyn::capture::LoadCaptureConfig(config_path));
  if (!config.sim) return facedyn::InvalidArgumentError(config_path + " has no sim: section");
  FACEDYN_ASSIGN_OR_RETURN(
      const sim::SimCaptureOptions options,
      sim::ParseSimCaptureOptions(*config.sim, std::string(FACEDYN_SOURCE_DIR) + "/config/capture"));
  FACEDYN_ASSIGN_OR_RETURN(const std::vector<facedyn::Marker> layout,
                           sim::PaintedMarkers(rig, options, config.cameras));
  if (layout.size() < 4) return facedyn::FailedPreconditionError("the HMC sees < 4 markers");
  detail::DetailTrainingSet set;
  set.subject = rig.name;
  set.neutral = rig.neutral;
  set.markers = layout;
  set.frames_mm = rom;
  std::vector<Eigen::Matrix3Xd> clean;
  for (const auto& x : truth) clean.push_back(set.MarkersOn(x));
  std::vector<double> marker_errors;
  Json film;
  FACEDYN_ASSIGN_OR_RETURN(
      const detail::MarkerFrames filmed,
      FilmHmcMarkers(rig, layout, config.cameras, options.render, truth, 60.0, &marker_errors,
                     &film));
  std::fprintf(stderr, "detail_bench: HMC filmed %zu frames\n", truth.size());

  detail::MasqueradeOptions masquerade_options;
  masquerade_options.region_sigma_mm = s.sigma_mm;
  masquerade_options.feature_sigma_mm = s.feature_sigma_mm;
  masquerade_options.pose_cell_mm = s.pose_cell_mm;
  masquerade_options.global_frames = s.global_frames;
  FACEDYN_ASSIGN_OR_RETURN(const detail::MasqueradeModel masquerade,
                           detail::MasqueradeModel::Train(set, masquerade_options));
  detail::BickelOptions bickel_options;
  bickel_options.edge_sigma_mm = s.edge_sigma_mm;
  bickel_options.frames = s.global_frames;
  FACEDYN_ASSIGN_OR_RETURN(const detail::BickelModel bickel,
                           detail::BickelModel::Train(set, bickel_options));
  Json methods = Json::object();
  for (const auto& [input, markers] :
       {std::pair<const char*, const std::vector<Eigen::Matrix3Xd>*>{"clean", &clean},
        {"filmed", &filmed.markers_mm}}) {
    std::vector<Eigen::Matrix3Xd> result(truth.size()), large(truth.size()),
        bickel_result(truth.size());
    for (size_t f = 0; f < truth.size(); ++f) {
      FACEDYN_RETURN_IF_ERROR(masquerade.Apply((*markers)[f], &result[f], &large[f]));
      FACEDYN_RETURN_IF_ERROR(bickel.Apply((*markers)[f], &bickel_result[f]));
    }
    methods[input] = {
        {"large_scale_only", facedyn::eval::DetailErrorsJson(facedyn::eval::ScoreDetail(large, truth, lips))},
        {"bickel2008_80", facedyn::eval::DetailErrorsJson(facedyn::eval::ScoreDetail(bickel_result, truth, lips))},
        {"masquerade_global_80", facedyn::eval::DetailErrorsJson(facedyn::eval::ScoreDetail(result, truth, lips))}};
  }
  return Json{{"config", "config/capture/hmc.yaml"},
              {"markers", layout.size()},
              {"film", film},
              {"methods", methods}};
}

facedyn::StatusOr<Json> Run(const Settings& s, uint64_t seed) {
  namespace sim = facedyn::sim;
  facedyn::FaceRig rig;
  if (s.ict_dir.empty()) {
    sim::ProceduralFaceOptions face_options;
    face_options.target_vertex_count = s.vertices;
    FACEDYN_ASSIGN_OR_RETURN(rig, sim::MakeProceduralFace(face_options));
  } else {
    sim::IctImportOptions ict;
    ict.dir = s.ict_dir;
    FACEDYN_ASSIGN_OR_RETURN(rig, sim::ImportIctFaceKit(ict));
  }
  if (s.markers > static_cast<int>(rig.markers.size())) {
    return facedyn::InvalidArgumentError("--markers " + std::to_string(s.markers) +
                                         ": the rig has " + std::to_string(rig.markers.size()) +
                                         " markers");
  }
  auto lips_it = rig.regions.find("lips");
  if (lips_it == rig.regions.end()) return facedyn::NotFoundError("the rig has no 'lips' region");

  // Key poses. Training: the range of motion; test: the speech visemes of sim/performance.cc.
  FACEDYN_ASSIGN_OR_RETURN(const std::vector<Eigen::VectorXd> rom, sim::RangeOfMotionPoses(rig));
  FACEDYN_ASSIGN_OR_RETURN(const std::vector<Eigen::VectorXd> visemes, sim::DialogueVisemes(rig));
  const auto rom_curve = sim::MakeSpeechSequence(rom, 3.0, seed);
  const auto speech_curve = sim::MakeSpeechSequence(visemes, 4.5, seed + 1000);

  detail::DetailTrainingSet set;
  set.subject = rig.name;
  set.neutral = rig.neutral;
  set.markers.assign(rig.markers.begin(), rig.markers.begin() + s.markers);
  set.frames_mm = Frames(rig, *rom_curve, s.train_frames, 30.0);
  const std::vector<Eigen::Matrix3Xd> truth = Frames(rig, *speech_curve, s.test_frames, 60.0);
  std::vector<Eigen::Matrix3Xd> test_markers;
  for (const auto& x : truth) test_markers.push_back(set.MarkersOn(x));
  // Validation (choosing the output compression, never the test): another speech draw.
  const auto validation_curve = sim::MakeSpeechSequence(visemes, 4.5, seed + 2000);
  const std::vector<Eigen::Matrix3Xd> validation_truth =
      Frames(rig, *validation_curve, s.test_frames, 60.0);
  std::vector<Eigen::Matrix3Xd> validation_markers;
  for (const auto& x : validation_truth) validation_markers.push_back(set.MarkersOn(x));

  Json run;
  run["seed"] = seed;
  run["vertices"] = rig.vertex_count();
  run["lips_vertices"] = lips_it->second.size();
  run["markers"] = s.markers;
  run["train_frames"] = s.train_frames;
  run["test_frames"] = s.test_frames;
  run["region_sigma_mm"] = s.sigma_mm;
  run["feature_sigma_mm"] = s.feature_sigma_mm;
  run["pose_cell_mm"] = s.pose_cell_mm;
  run["bickel_edge_sigma_mm"] = s.edge_sigma_mm;

  // Masquerade variants.
  struct Variant {
    const char* name;
    int global, per_region;
  };
  const Variant variants[] = {{"masquerade_all_frames", 0, 0},
                              {"masquerade_global_80", s.global_frames, 0},
                              {"masquerade_per_region_40", 0, 40},
                              {"masquerade_per_region_20", 0, 20}};
  Json methods = Json::object();
  bool large_done = false;
  for (const Variant& variant : variants) {
    detail::MasqueradeOptions options;
    options.region_sigma_mm = s.sigma_mm;
    options.feature_sigma_mm = s.feature_sigma_mm;
    options.pose_cell_mm = s.pose_cell_mm;
    options.global_frames = variant.global;
    options.per_region_frames = variant.per_region;
    detail::MasqueradeTrainingSummary summary;
    FACEDYN_ASSIGN_OR_RETURN(const detail::MasqueradeModel model,
                             detail::MasqueradeModel::Train(set, options, &summary));
    std::vector<Eigen::Matrix3Xd> result, large;
    FACEDYN_RETURN_IF_ERROR(model.ApplyFrames(test_markers, &result, &large));
    if (!large_done) {
      methods["large_scale_only"] = {{"errors", facedyn::eval::DetailErrorsJson(facedyn::eval::ScoreDetail(large, truth, lips_it->second))}};
      large_done = true;
    }
    FACEDYN_ASSIGN_OR_RETURN(const UpsampleSpeed speed, SpeedOf(model, test_markers));
    methods[variant.name] = {{"errors", facedyn::eval::DetailErrorsJson(facedyn::eval::ScoreDetail(
                                            result, truth, lips_it->second))},
                             {"memory_bytes", model.MemoryBytes()},
                             {"memory_parts", MemoryPartsJson(model)},
                             {"mean_frames_per_region", summary.mean_frames_per_region},
                             {"regions_with_linear_part", summary.linear_regions},
                             {"train_s", summary.train_s}};
    methods[variant.name].update(speed.ToJson());
    std::fprintf(stderr, "detail_bench: seed %llu %s done\n", static_cast<unsigned long long>(seed),
                 variant.name);
  }
  {
    // Output compression of the 80-global model's region RBFs (MasqueradeOptions::
    // output_energy), chosen on the validation speech: the smallest energy whose face mean
    // error there is within 5% of the uncompressed model's; then scored on the test.
    auto train_global = [&](double energy) {
      detail::MasqueradeOptions options;
      options.region_sigma_mm = s.sigma_mm;
      options.feature_sigma_mm = s.feature_sigma_mm;
      options.pose_cell_mm = s.pose_cell_mm;
      options.global_frames = s.global_frames;
      options.output_energy = energy;
      return detail::MasqueradeModel::Train(set, options);
    };
    Json candidates = Json::array();
    double uncompressed_validation = 0.0, chosen_energy = 1.0;
    for (double energy : {1.0, 0.9999, 0.999, 0.99, 0.9}) {
      FACEDYN_ASSIGN_OR_RETURN(const detail::MasqueradeModel model, train_global(energy));
      std::vector<Eigen::Matrix3Xd> result;
      FACEDYN_RETURN_IF_ERROR(model.ApplyFrames(validation_markers, &result));
      const double error =
          facedyn::eval::ScoreDetail(result, validation_truth, lips_it->second).face_mean_mm;
      if (energy == 1.0) uncompressed_validation = error;
      if (error <= 1.05 * uncompressed_validation) chosen_energy = energy;
      candidates.push_back({{"output_energy", energy},
                            {"validation_face_mean_mm", error},
                            {"memory_bytes", model.MemoryBytes()},
                            {"memory_parts", MemoryPartsJson(model)}});
    }
    FACEDYN_ASSIGN_OR_RETURN(const detail::MasqueradeModel model, train_global(chosen_energy));
    std::vector<Eigen::Matrix3Xd> result;
    FACEDYN_RETURN_IF_ERROR(model.ApplyFrames(test_markers, &result));
    FACEDYN_ASSIGN_OR_RETURN(const UpsampleSpeed speed, SpeedOf(model, test_markers));
    methods["masquerade_global_80_compressed"] = {
        {"errors", facedyn::eval::DetailErrorsJson(
                       facedyn::eval::ScoreDetail(result, truth, lips_it->second))},
        {"memory_bytes", model.MemoryBytes()},
        {"memory_parts", MemoryPartsJson(model)},
        {"output_energy", chosen_energy}};
    methods["masquerade_global_80_compressed"].update(speed.ToJson());
    // What `detail train --output-energy auto` chooses from the training takes alone (the
    // range-of-motion frames the global selection left out), scored on the test.
    {
      detail::MasqueradeOptions options;
      options.region_sigma_mm = s.sigma_mm;
      options.feature_sigma_mm = s.feature_sigma_mm;
      options.pose_cell_mm = s.pose_cell_mm;
      options.global_frames = s.global_frames;
      options.output_energy = detail::kChooseOutputEnergy;
      detail::MasqueradeTrainingSummary summary;
      FACEDYN_ASSIGN_OR_RETURN(const detail::MasqueradeModel automatic,
                               detail::MasqueradeModel::Train(set, options, &summary));
      std::vector<Eigen::Matrix3Xd> automatic_result;
      FACEDYN_RETURN_IF_ERROR(automatic.ApplyFrames(test_markers, &automatic_result));
      methods["masquerade_global_80_auto"] = {
          {"errors", facedyn::eval::DetailErrorsJson(
                         facedyn::eval::ScoreDetail(automatic_result, truth, lips_it->second))},
          {"memory_bytes", automatic.MemoryBytes()},
          {"output_energy", summary.output_energy},
          {"train_s", summary.train_s}};
    }
    run["output_compression_candidates"] = candidates;
    std::fprintf(stderr, "detail_bench: seed %llu compression chosen on validation: energy %g\n",
                 static_cast<unsigned long long>(seed), chosen_energy);
  }
  {
    detail::BickelOptions options;
    options.edge_sigma_mm = s.edge_sigma_mm;
    options.frames = s.global_frames;
    const auto start = Clock::now();
    FACEDYN_ASSIGN_OR_RETURN(const detail::BickelModel model,
                             detail::BickelModel::Train(set, options));
    const double train_s = Seconds(start);
    std::vector<Eigen::Matrix3Xd> result;
    FACEDYN_RETURN_IF_ERROR(model.ApplyFrames(test_markers, &result));
    FACEDYN_ASSIGN_OR_RETURN(const UpsampleSpeed speed, SpeedOf(model, test_markers));
    methods["bickel2008_80"] = {{"errors", facedyn::eval::DetailErrorsJson(facedyn::eval::ScoreDetail(result, truth, lips_it->second))},
                                {"memory_bytes", model.MemoryBytes()},
                                {"marker_graph_edges", model.edge_count()},
                                {"train_s", train_s}};
    methods["bickel2008_80"].update(speed.ToJson());
  }
  run["methods"] = methods;
  if (s.hmc) {
    FACEDYN_ASSIGN_OR_RETURN(run["hmc"], RunHmc(s, rig, set.frames_mm, truth, lips_it->second));
  }
  return run;
}

// Mean and sample sd over runs of every number at the same path.
void Summarise(const std::vector<Json>& runs, const Json& like, const Json::json_pointer& at,
               Json* out) {
  if (like.is_object()) {
    for (auto it = like.begin(); it != like.end(); ++it)
      Summarise(runs, it.value(), at / it.key(), out);
    return;
  }
  if (!like.is_number()) return;
  double sum = 0, sum2 = 0;
  for (const Json& r : runs) sum += r.at(at).get<double>();
  const double mean = sum / runs.size();
  for (const Json& r : runs) sum2 += std::pow(r.at(at).get<double>() - mean, 2);
  (*out)[at] = {{"mean", mean},
                {"sd", runs.size() > 1 ? std::sqrt(sum2 / (runs.size() - 1)) : 0.0}};
}

}  // namespace

int main(int argc, char** argv) {
  Settings s;
  std::vector<uint64_t> seeds;
  uint64_t seed = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "detail_bench: %s needs a value\n", arg.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (arg == "--vertices") {
      s.vertices = static_cast<int>(Integer(next(), arg));
    } else if (arg == "--markers") {
      s.markers = static_cast<int>(Integer(next(), arg));
    } else if (arg == "--train-frames") {
      s.train_frames = static_cast<int>(Integer(next(), arg));
    } else if (arg == "--test-frames") {
      s.test_frames = static_cast<int>(Integer(next(), arg));
    } else if (arg == "--global-frames") {
      s.global_frames = static_cast<int>(Integer(next(), arg));
    } else if (arg == "--sigma-mm") {
      s.sigma_mm = Number(next(), arg);
    } else if (arg == "--feature-sigma-mm") {
      s.feature_sigma_mm = Number(next(), arg);
    } else if (arg == "--pose-cell-mm") {
      s.pose_cell_mm = Number(next(), arg);
    } else if (arg == "--edge-sigma-mm") {
      s.edge_sigma_mm = Number(next(), arg);
    } else if (arg == "--seed") {
      seed = static_cast<uint64_t>(Integer(next(), arg));
    } else if (arg == "--seeds") {
      std::stringstream list(next());
      std::string item;
      while (std::getline(list, item, ','))
        seeds.push_back(static_cast<uint64_t>(Integer(item.c_str(), arg)));
    } else if (arg == "--ict") {
      s.ict_dir = next();
    } else if (arg == "--no-hmc") {
      s.hmc = false;
    } else if (arg == "--quick") {
      s.vertices = 4000;
      s.train_frames = 160;
      s.test_frames = 120;
    } else {
      std::fprintf(
          stderr,
          "usage: detail_bench [--vertices N] [--markers N] [--train-frames N] [--test-frames N] "
          "[--global-frames N] [--sigma-mm S] [--feature-sigma-mm S] [--pose-cell-mm S] "
          "[--edge-sigma-mm S] [--seed N] [--seeds 1,2,3] [--quick] [--no-hmc] [--ict DIR]\n");
      return 2;
    }
  }
  if (s.markers < 4 || s.train_frames < 2 || s.test_frames < 1 || !(s.sigma_mm > 0) ||
      !(s.feature_sigma_mm > 0) || !(s.edge_sigma_mm > 0) || !(s.pose_cell_mm >= 0)) {
    std::fprintf(
        stderr,
        "detail_bench: need --markers >= 4, --train-frames >= 2, --test-frames >= 1, sigmas > 0, "
        "--pose-cell-mm >= 0\n");
    return 2;
  }
  facedyn::InitLogging(facedyn::Verbosity::kQuiet);
  if (seeds.empty()) seeds.push_back(seed);
  std::vector<Json> runs;
  for (uint64_t sd : seeds) {
    facedyn::StatusOr<Json> run = Run(s, sd);
    if (!run.ok()) {
      std::fprintf(stderr, "detail_bench: %s\n", run.status().ToString().c_str());
      return 1;
    }
    runs.push_back(std::move(run).value());
  }
  Json out;
  out["runs"] = runs;
  if (runs.size() > 1) {
    Json summary = Json::object();
    Summarise(runs, runs.front()["methods"], Json::json_pointer("/methods"), &summary);
    if (runs.front().contains("hmc")) {
      Summarise(runs, runs.front()["hmc"], Json::json_pointer("/hmc"), &summary);
    }
    out["summary"] = summary;
    out["summary"]["seeds"] = seeds;
  }
  std::printf("%s\n", out.dump(2, ' ', false, facedyn::kJsonReplaceInvalidUtf8).c_str());
  return 0;
}
