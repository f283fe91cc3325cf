// solve_bench: the rig-solving figures of issue 21 (FDLS), printed as JSON.
//
//   solve_bench [--quick] [--seed N] [--seeds 1,2,3] [--epochs N] [--seconds S] [--fps N]
//               [--noise-mm S] [--salient T[,T...]] [--smoothness L] [--threads N]
//               [--active-channels K] [--filmed-seconds S] [--ict DIR [--config REGIONS.yaml]]
//
// Subject: the procedural face (sim/, the embedded default rig; the solve library itself never
// links sim/), or with --ict DIR the ICT-FaceKit face (sim/ict_import.h: its 55 ARKit-named
// shapes and painted markers) with config/solve/ict.yaml's region tables (--config: others).
// Its puppet generates the training tuples (FDLS 4.1: one-hot sweeps, ROM clips, random sparse
// combinations, noisy and mask-shifted copies). Test: a held-out speech-like performance with
// known weights, drawn from another seed and never used in training: smooth key-to-key curves
// (smoothstep between keys every 0.12-0.3 s for the jaw and the channels of regions over the
// rig's lips, 0.4-1.0 s elsewhere; a key is away from zero with probability
// min(1/2, K / channels), so that about K = `--active-channels` (default 5) channels move at a
// time), `--seconds` at `--fps`. Markers are the puppet's own, clean and with `--noise-mm`
// Gaussian noise per coordinate, and filmed: the first `--filmed-seconds` (default 2; 0 skips
// it) rendered, detected and reconstructed on the simulated stage (see FilmedStudy).
//
// Methods, each on both marker sets: the network (FDLS 4.4, jaw first), the QP baseline (Eq. 2
// per frame from zero, every channel free, Ceres bounded trust region) and the network followed
// by fine-tuning (4.5: Eq. 2 from the network's solve, every channel free). Figures: weight
// RMSE (over frames and channels), jaw weight RMSE, the jaw's rotation error (degrees RMS: the
// jaw-opening weight's error times that shape's hinge angle), marker RMSE (mm, distance between
// the puppet's markers at the solved weights and the observed markers). Speed: frames/s of each
// method on the whole performance, LibTorch on `--threads` (default 2) threads, median of 3.
//
// --seed N: training data, network initialisation and test performance from seed N (the test
// performance from 1000 + N). --seeds 1,2,3: one study per seed; "replicates" holds each figure's
// mean and sample standard deviation over seeds. --salient T[,T...]: candidate thresholds of
// salient selection (Eq. 3, scale 1 mm); a network per candidate on the kept tuples, and every
// tuple as one more candidate; the choice made on a validation performance (seed 3000 + N, never
// the test) twice, on clean markers and with --noise-mm noise, then the chosen networks and the
// all-tuples one scored on the test performance.
// "anchor_alignment": the shot from a face 3% larger with its mask 2 mm off, solved by the
// network before and after alignment on one neutral-ish frame (4.4.2), and the fraction of the
// error the change added that alignment removed.
// --smoothness L: also "network_finetuned_smooth", the fine-tuning with temporal smoothness
// lambda = L (mm^2 per unit weight^2 per frame step; one problem over the whole performance).
// --quick: fewer epochs and tuples (a smoke run, not the figures).

#include <ATen/Parallel.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "bench/bench_flags.h"
#include "core/json_io.h"
#include "eval/simulated_stage.h"
#include "reconstruct/pipeline.h"
#include "sim/expressions.h"
#include "sim/ict_import.h"
#include "sim/procedural_face.h"
#include "solve/anchor.h"
#include "solve/fdls_solver.h"
#include "solve/marker_fit.h"
#include "solve/solve_config.h"
#include "solve/solve_io.h"
#include "solve/training_data.h"

namespace {

using facedyn::Json;
using namespace facedyn::solve;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}

template <typename T>
T Check(facedyn::StatusOr<T> value, const char* what) {
  if (!value.ok()) {
    std::fprintf(stderr, "solve_bench: %s: %s\n", what, value.status().ToString().c_str());
    std::exit(1);
  }
  return std::move(value).value();
}

std::vector<std::string> Split(const std::string& list) {
  std::vector<std::string> items;
  size_t start = 0;
  while (start <= list.size()) {
    const size_t comma = list.find(',', start);
    items.push_back(
        list.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return items;
}

// Speech-like weights (C x N): per channel, keys at random intervals, smoothstep between them.
// A key is away from zero with probability min(1/2, active_channels / C): about
// `active_channels` channels are moving at any time, as in a face talking (on the procedural
// puppet's 10 channels that is every other key, the generator's original rule, draw for draw).
Eigen::MatrixXd SpeechLikeWeights(const Puppet& puppet, const std::vector<int>& fast_channels,
                                  int frames, double fps, double active_channels, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double zero_key = 1.0 - std::min(0.5, active_channels / puppet.channel_count());
  Eigen::MatrixXd w(puppet.channel_count(), frames);
  for (int c = 0; c < puppet.channel_count(); ++c) {
    const bool fast = std::count(fast_channels.begin(), fast_channels.end(), c) > 0;
    const double min_gap = fast ? 0.12 : 0.4, max_gap = fast ? 0.3 : 1.0;
    const double peak = fast ? 0.9 : 0.6;
    auto key_value = [&]() { return unit(rng) < zero_key ? 0.0 : peak * unit(rng); };
    double t0 = 0.0, v0 = 0.0;
    double t1 = min_gap + (max_gap - min_gap) * unit(rng), v1 = key_value();
    for (int f = 0; f < frames; ++f) {
      const double t = f / fps;
      while (t > t1) {
        t0 = t1;
        v0 = v1;
        t1 += min_gap + (max_gap - min_gap) * unit(rng);
        v1 = key_value();
      }
      const double s = (t - t0) / (t1 - t0);
      w(c, f) = v0 + (v1 - v0) * s * s * (3.0 - 2.0 * s);
    }
  }
  return w;
}

struct Figures {
  double weight_rmse = 0.0;
  double jaw_rmse = 0.0;
  double jaw_deg_rms = 0.0;  // mandible rotation error, degrees RMS
  double marker_rmse_mm = 0.0;
};

// The rig's jaw hinge: the jaw-opening channel and the mandible rotation of that shape at
// weight 1 (sim::JawOpenAngleRad: the rig's own hinge fitted to the shape for an ICT rig). A
// jaw weight error times the angle is the jaw's rotation error; the sideways and forward jaw
// shapes are not rotations about the hinge and count only in the jaw weight RMSE.
struct JawHinge {
  int channel = -1;
  double rad_per_weight = 0.0;
};

JawHinge FindJawHinge(const facedyn::FaceRig& rig, const Puppet& puppet) {
  JawHinge hinge;
  for (const char* name : {"jaw_open", "jawOpen"}) {
    if (puppet.ChannelIndex(name) >= 0) hinge.channel = puppet.ChannelIndex(name);
  }
  hinge.rad_per_weight = facedyn::sim::JawOpenAngleRad(rig);
  return hinge;
}

Figures Score(const Puppet& puppet, const std::vector<int>& jaw, const JawHinge& hinge,
              const Eigen::MatrixXd& solved, const Eigen::MatrixXd& truth,
              const Eigen::MatrixXd& markers, const MarkerPresence* present = nullptr) {
  Figures f;
  f.weight_rmse = std::sqrt((solved - truth).squaredNorm() / static_cast<double>(truth.size()));
  double jaw_sum = 0.0;
  for (int c : jaw) jaw_sum += (solved.row(c) - truth.row(c)).squaredNorm();
  f.jaw_rmse = std::sqrt(jaw_sum / static_cast<double>(jaw.size() * truth.cols()));
  if (hinge.channel >= 0) {
    f.jaw_deg_rms = std::sqrt((solved.row(hinge.channel) - truth.row(hinge.channel)).squaredNorm() /
                              static_cast<double>(truth.cols())) *
                    std::abs(hinge.rad_per_weight) * 180.0 / M_PI;
  }
  f.marker_rmse_mm = MarkerRmseMm(puppet, solved, markers, present);
  return f;
}

Json ToJson(const Figures& f, double frames_per_s) {
  return Json{{"weight_rmse", f.weight_rmse},
              {"jaw_weight_rmse", f.jaw_rmse},
              {"jaw_deg_rms", f.jaw_deg_rms},
              {"marker_rmse_mm", f.marker_rmse_mm},
              {"frames_per_s", frames_per_s}};
}

// Median of three timings of `run` (frames / seconds).
template <typename Run>
double FramesPerSecond(int frames, Run run) {
  std::vector<double> rates;
  for (int k = 0; k < 3; ++k) {
    const auto start = Clock::now();
    run();
    rates.push_back(frames / Seconds(start));
  }
  std::sort(rates.begin(), rates.end());
  return rates[1];
}

struct Settings {
  bool quick = false;
  int epochs = 60;
  double seconds = 20.0;
  double fps = 60.0;
  double noise_mm = 0.1;
  std::vector<double> salient;  // candidate thresholds (empty: no salient study)
  double smoothness = 0.0;
  int threads = 2;
  double filmed_seconds = 2.0;   // 0: no filmed study
  double active_channels = 5.0;  // channels away from zero at a time in the performances
};

// The first `--filmed-seconds` of the test performance filmed by the simulated stage's 8-camera
// rig (calibrated from 60 views of a simulated ChArUco board, as the default demo's; every frame
// rendered with blur, noise, distortion and self-occlusion, the dots detected, triangulated,
// tracked and labelled, the skull pose estimated: eval::FilmSimulatedTake, as `facedyn demo`
// films), the head still. The solves read the labelled marker tracks in the estimated skull frame
// (solve::MarkersFromTracks); a marker the tracker lost is missing (the network refills it from its
// neighbours, the fits leave it out). Figures as for the clean and noisy markers (marker RMSE
// against the filmed markers present: the fit's residual), plus "true_marker_rmse_mm": the puppet's
// markers at the solved weights against the markers' true positions on the performance, and the
// filmed markers' own error against those true positions.
Json FilmedStudy(const facedyn::FaceRig& rig, const Puppet& puppet, const ResolvedConfig& config,
                 const JawHinge& hinge, const FdlsSolver& solver, const Eigen::MatrixXd& truth,
                 const Settings& settings, uint64_t seed) {
  namespace eval = facedyn::eval;
  const int frames = static_cast<int>(
      std::min<Eigen::Index>(truth.cols(), std::lround(settings.filmed_seconds * settings.fps)));
  const Eigen::MatrixXd weights = truth.leftCols(frames);
  facedyn::BlendshapeWeightsTrack track;
  track.names = puppet.channel_names;
  for (int f = 0; f < frames; ++f) track.time_s.push_back(f / settings.fps);
  track.weights = weights.transpose();
  const facedyn::Take performance =
      Check(DriveRig(rig, track, "the test performance"), "driving the rig");
  const auto start = Clock::now();
  const eval::SimulatedCameraRig cameras =
      Check(eval::CalibrateSimulatedCameraRig(60, 2020 + seed), "calibrating the camera rig");
  eval::FilmTimings timings;
  eval::FilmOptions film;
  film.timings = &timings;
  film.progress = true;
  const facedyn::reconstruct::Reconstruction reconstruction =
      Check(eval::FilmSimulatedTake(rig, cameras, performance, 5000 + seed, film), "filming");
  const double film_s = Seconds(start);
  const facedyn::MarkerTracks tracks = facedyn::reconstruct::MarkerTracksOf(rig, reconstruction);
  const MarkerFrames filmed = Check(
      MarkersFromTracks(puppet, tracks, reconstruction.take.world_from_skull), "filmed markers");
  const Eigen::MatrixXd true_markers =
      (puppet.marker_basis_mm * weights).colwise() + puppet.StackedNeutral();
  // The filmed markers against the truth (present ones), and the mean of that error: the part
  // every marker shares (the estimated skull pose's and the calibration's).
  double sq = 0.0;
  int present = 0;
  Eigen::Vector3d bias_mm = Eigen::Vector3d::Zero();
  for (int f = 0; f < frames; ++f) {
    for (int m = 0; m < puppet.marker_count(); ++m) {
      if (!filmed.present(m, f)) continue;
      const Eigen::Vector3d error =
          filmed.markers_in_skull.block<3, 1>(3 * m, f) - true_markers.block<3, 1>(3 * m, f);
      sq += error.squaredNorm();
      bias_mm += error;
      ++present;
    }
  }
  if (present > 0) bias_mm /= present;
  Json out = {{"frames", frames},
              {"fps", settings.fps},
              {"cameras", cameras.truth.size()},
              {"present_fraction", static_cast<double>(present) / (frames * puppet.marker_count())},
              {"filmed_marker_rms_mm", present > 0 ? std::sqrt(sq / present) : 0.0},
              {"filmed_marker_mean_error_mm", bias_mm.norm()},
              {"calibration_worst_centre_error_mm", cameras.worst_centre_error_mm},
              {"film_s", film_s},
              {"render_s", timings.render_s},
              {"detect_s", timings.detect_s},
              {"reconstruct_s", timings.reconstruct_s}};
  const Eigen::MatrixXd network =
      Check(solver.Solve(filmed.markers_in_skull, filmed.present), "network solve (filmed)");
  MarkerFitSummary qp_summary, tune_summary;
  const Eigen::MatrixXd qp = Check(
      SolveMarkersQp(puppet, filmed.markers_in_skull, &filmed.present, &qp_summary), "qp (filmed)");
  const Eigen::MatrixXd tuned =
      Check(FitWeightsToMarkers(puppet, filmed.markers_in_skull, network, &filmed.present,
                                MarkerFitOptions{}, &tune_summary),
            "finetune (filmed)");
  for (const auto& [name, solved] :
       {std::pair<const char*, const Eigen::MatrixXd*>{"network", &network},
        {"qp_baseline", &qp},
        {"network_finetuned", &tuned}}) {
    Json figures = ToJson(Score(puppet, config.jaw.channels, hinge, *solved, weights,
                                filmed.markers_in_skull, &filmed.present),
                          0.0);
    figures.erase("frames_per_s");
    figures["true_marker_rmse_mm"] = MarkerRmseMm(puppet, *solved, true_markers);
    out[name] = figures;
  }
  return out;
}

Json Study(const facedyn::FaceRig& rig, const Puppet& puppet, const ResolvedConfig& base,
           const Settings& settings, uint64_t seed) {
  ResolvedConfig config = base;
  config.network.epochs = settings.epochs;
  const JawHinge hinge = FindJawHinge(rig, puppet);
  TrainingDataOptions data_options;
  data_options.seed = seed;
  data_options.jaw_channels = config.jaw.channels;
  if (settings.quick) {
    data_options.random_combos = 600;
    data_options.rom_clips = 20;
    data_options.augment_copies = 1;
  }
  const Eigen::MatrixXd train_weights =
      Check(MakeTrainingWeights(puppet, data_options), "training weights");
  const TrainingSet data =
      Check(MakeTrainingSet(puppet, train_weights, data_options), "training set");
  FdlsTrainOptions train_options;
  train_options.seed = seed;
  train_options.num_threads =
      1;  // training on one thread: deterministic and no spin-waits on a shared machine
  std::vector<RegionTrainSummary> summaries;
  auto start = Clock::now();
  const FdlsSolver solver =
      Check(FdlsSolver::Train(puppet, config, data, train_options, &summaries), "training");
  const double train_s = Seconds(start);
  Json training = {{"tuples", data.sample_count()},
                   {"poses", train_weights.cols()},
                   {"epochs", config.network.epochs},
                   {"hidden_units", config.network.hidden_units},
                   {"residual_blocks", config.network.residual_blocks},
                   {"train_s", train_s},
                   {"regions", Json::array()}};
  for (const RegionTrainSummary& s : summaries) {
    training["regions"].push_back({{"region", s.region},
                                   {"markers", s.markers},
                                   {"inputs", s.inputs},
                                   {"channels", s.outputs},
                                   {"validation_weight_rmse", s.validation_rmse}});
  }

  // The held-out performance: jaw and mouth channels (those of regions over the rig's lips) fast,
  // the rest slow.
  std::vector<int> fast = config.jaw.channels;
  for (const ResolvedRegion& region : config.regions) {
    const std::vector<std::string>& over = region.spec.rig_regions;
    if (std::find(over.begin(), over.end(), "lips") != over.end())
      fast.insert(fast.end(), region.channels.begin(), region.channels.end());
  }
  const int frames = static_cast<int>(std::lround(settings.seconds * settings.fps));
  const Eigen::MatrixXd truth =
      SpeechLikeWeights(puppet, fast, frames, settings.fps, settings.active_channels, 1000 + seed);
  const Eigen::MatrixXd clean =
      (puppet.marker_basis_mm * truth).colwise() + puppet.StackedNeutral();
  Eigen::MatrixXd noisy = clean;
  std::mt19937_64 rng(2000 + seed);
  std::normal_distribution<double> normal(0.0, settings.noise_mm);
  for (Eigen::Index i = 0; i < noisy.size(); ++i) noisy.data()[i] += normal(rng);

  at::set_num_threads(settings.threads);
  Json test = {{"frames", frames},
               {"fps", settings.fps},
               {"seed", 1000 + seed},
               {"noise_mm", settings.noise_mm}};
  for (const auto& [name, markers] :
       {std::pair<const char*, const Eigen::MatrixXd*>{"clean", &clean}, {"noisy", &noisy}}) {
    Eigen::MatrixXd network;
    const double network_fps =
        FramesPerSecond(frames, [&] { network = Check(solver.Solve(*markers), "solve"); });
    Eigen::MatrixXd qp;
    MarkerFitSummary qp_summary;
    const double qp_fps = FramesPerSecond(
        frames, [&] { qp = Check(SolveMarkersQp(puppet, *markers, nullptr, &qp_summary), "qp"); });
    Eigen::MatrixXd tuned;
    MarkerFitSummary tune_summary;
    const double tune_fps = FramesPerSecond(frames, [&] {
      tuned = Check(FitWeightsToMarkers(puppet, *markers, network, nullptr, MarkerFitOptions{},
                                        &tune_summary),
                    "finetune");
    });
    Json entry = {
        {"network",
         ToJson(Score(puppet, config.jaw.channels, hinge, network, truth, *markers), network_fps)},
        {"qp_baseline",
         ToJson(Score(puppet, config.jaw.channels, hinge, qp, truth, *markers), qp_fps)},
        {"network_finetuned",
         ToJson(Score(puppet, config.jaw.channels, hinge, tuned, truth, *markers), tune_fps)}};
    entry["qp_baseline"]["iterations_per_frame"] =
        static_cast<double>(qp_summary.iterations) / frames;
    entry["network_finetuned"]["iterations_per_frame"] =
        static_cast<double>(tune_summary.iterations) / frames;
    entry["network_finetuned"]["converged"] = tune_summary.converged;
    if (settings.smoothness > 0.0) {
      Eigen::MatrixXd smooth;
      MarkerFitSummary smooth_summary;
      MarkerFitOptions smooth_options;
      smooth_options.smoothness = settings.smoothness;
      const double smooth_fps = FramesPerSecond(frames, [&] {
        smooth = Check(FitWeightsToMarkers(puppet, *markers, network, nullptr, smooth_options,
                                           &smooth_summary),
                       "smooth finetune");
      });
      entry["network_finetuned_smooth"] =
          ToJson(Score(puppet, config.jaw.channels, hinge, smooth, truth, *markers), smooth_fps);
      entry["network_finetuned_smooth"]["smoothness_mm2"] = settings.smoothness;
      entry["network_finetuned_smooth"]["converged"] = smooth_summary.converged;
    }
    test[name] = entry;
  }
  if (settings.filmed_seconds > 0.0)
    test["filmed"] = FilmedStudy(rig, puppet, config, hinge, solver, truth, settings, seed);
  if (!settings.salient.empty()) {
    // Salient selection (Eq. 3) with its threshold chosen on a validation performance (another
    // seed) that the test never shares: one network per candidate threshold on the kept tuples
    // (same epochs); every tuple (no selection) is a candidate too. The choice is made twice, on
    // the validation performance's clean markers and on them with the test's noise level (its own
    // draw), and only then are the chosen networks scored on the test performance.
    const Eigen::MatrixXd validation_truth = SpeechLikeWeights(
        puppet, fast, frames, settings.fps, settings.active_channels, 3000 + seed);
    const Eigen::MatrixXd validation_clean =
        (puppet.marker_basis_mm * validation_truth).colwise() + puppet.StackedNeutral();
    Eigen::MatrixXd validation_noisy = validation_clean;
    std::mt19937_64 validation_rng(4000 + seed);
    std::normal_distribution<double> validation_normal(0.0, settings.noise_mm);
    for (Eigen::Index i = 0; i < validation_noisy.size(); ++i)
      validation_noisy.data()[i] += validation_normal(validation_rng);
    auto validation_rmse = [&](const FdlsSolver& s, const Eigen::MatrixXd& markers) {
      return Score(puppet, config.jaw.channels, hinge, Check(s.Solve(markers), "validation solve"),
                   validation_truth, markers)
          .weight_rmse;
    };
    // Candidates: every tuple first, then each threshold.
    std::vector<FdlsSolver> owned;
    owned.reserve(settings.salient.size());
    std::vector<const FdlsSolver*> networks = {&solver};
    Json candidates = Json::array();
    candidates.push_back({{"threshold", "none (every tuple)"},
                          {"tuples_kept", data.sample_count()},
                          {"train_s", train_s}});
    for (double threshold : settings.salient) {
      const std::vector<int> kept = SelectSalientSamples(data.markers, threshold, 1.0);
      TrainingSet subset;
      subset.weights.resize(data.weights.rows(), static_cast<Eigen::Index>(kept.size()));
      subset.markers.resize(data.markers.rows(), static_cast<Eigen::Index>(kept.size()));
      for (size_t i = 0; i < kept.size(); ++i) {
        subset.weights.col(static_cast<Eigen::Index>(i)) = data.weights.col(kept[i]);
        subset.markers.col(static_cast<Eigen::Index>(i)) = data.markers.col(kept[i]);
      }
      const auto train_start = Clock::now();
      owned.push_back(Check(FdlsSolver::Train(puppet, config, subset, train_options, nullptr),
                            "salient training"));
      networks.push_back(&owned.back());
      candidates.push_back({{"threshold", threshold},
                            {"tuples_kept", kept.size()},
                            {"train_s", Seconds(train_start)}});
    }
    Json chosen;
    Json scored;
    for (const auto& [kind, validation] :
         {std::pair<const char*, const Eigen::MatrixXd*>{"clean", &validation_clean},
          {"noisy", &validation_noisy}}) {
      size_t best = 0;
      std::vector<double> rmse;
      for (size_t k = 0; k < networks.size(); ++k) {
        rmse.push_back(validation_rmse(*networks[k], *validation));
        candidates[k][std::string("validation_weight_rmse_") + kind] = rmse.back();
        if (rmse[k] < rmse[best]) best = k;
      }
      chosen[std::string(kind) + "_validation"] = candidates[best]["threshold"];
      for (const auto& [name, markers] :
           {std::pair<const char*, const Eigen::MatrixXd*>{"clean", &clean}, {"noisy", &noisy}}) {
        Json figures =
            ToJson(Score(puppet, config.jaw.channels, hinge,
                         Check(networks[best]->Solve(*markers), "solve"), truth, *markers),
                   0.0);
        figures.erase("frames_per_s");
        scored[name][std::string("chosen_on_") + kind + "_validation"] = figures;
      }
    }
    for (const auto& [name, markers] :
         {std::pair<const char*, const Eigen::MatrixXd*>{"clean", &clean}, {"noisy", &noisy}}) {
      Json figures = ToJson(Score(puppet, config.jaw.channels, hinge,
                                  Check(solver.Solve(*markers), "solve"), truth, *markers),
                            0.0);
      figures.erase("frames_per_s");
      scored[name]["all_tuples"] = figures;
    }
    test["salient"] = {{"scale_mm", 1.0},
                       {"validation_seed", 3000 + seed},
                       {"validation_noise_mm", settings.noise_mm},
                       {"candidates", candidates},
                       {"chosen", chosen},
                       {"test", scored}};
  }
  // Anchor alignment (4.4.2): the shot's face 3% larger (sim::ScaledFaceRig about the skull
  // origin) and its mask 2 mm off; the anchor is the frame whose network solve has the least
  // total weight (no truth is read to pick it), its weights taken as the neutral's (0).
  {
    const facedyn::FaceRig bigger = Check(
        facedyn::sim::ScaledFaceRig(rig, Eigen::Vector3d::Constant(1.03), rig.name + "_x1.03"),
        "scaled rig");
    const Puppet shot = Check(MakePuppet(bigger), "scaled puppet");
    const Eigen::Vector3d shift_mm = Eigen::Vector3d(1.0, 1.0, 0.5).normalized() * 2.0;
    Eigen::MatrixXd shifted = (shot.marker_basis_mm * truth).colwise() + shot.StackedNeutral();
    for (int m = 0; m < puppet.marker_count(); ++m)
      shifted.middleRows<3>(3 * m).colwise() += shift_mm;
    const Eigen::MatrixXd before = Check(solver.Solve(shifted), "solve shifted");
    // Frames after the first second only: the curves start at exactly neutral, which a shot
    // does not, and the anchor is meant to be neutral-ish.
    const Eigen::Index skip =
        std::min<Eigen::Index>(static_cast<Eigen::Index>(settings.fps), frames - 1);
    Eigen::Index anchor = 0;
    before.rightCols(frames - skip).colwise().sum().minCoeff(&anchor);
    anchor += skip;
    const Eigen::VectorXd offsets =
        Check(AnchorOffsets(puppet, shifted, static_cast<int>(anchor),
                            Eigen::VectorXd::Zero(puppet.channel_count())),
              "anchor");
    const Eigen::MatrixXd aligned = Check(AlignToAnchor(shifted, offsets), "align");
    const Eigen::MatrixXd after = Check(solver.Solve(aligned), "solve aligned");
    const Eigen::MatrixXd clean_solve = Check(solver.Solve(clean), "solve clean");
    const Figures f_clean = Score(puppet, config.jaw.channels, hinge, clean_solve, truth, clean);
    const Figures f_before = Score(puppet, config.jaw.channels, hinge, before, truth, shifted);
    const Figures f_after = Score(puppet, config.jaw.channels, hinge, after, truth, aligned);
    const double added = f_before.weight_rmse - f_clean.weight_rmse;
    test["anchor_alignment"] = {
        {"scale", 1.03},
        {"mask_shift_mm", 2.0},
        {"anchor_frame", anchor},
        {"anchor_true_weight_sum", truth.col(anchor).sum()},
        {"network_weight_rmse_unshifted", f_clean.weight_rmse},
        {"network_weight_rmse_shifted", f_before.weight_rmse},
        {"network_weight_rmse_aligned", f_after.weight_rmse},
        {"fraction_of_added_error_removed",
         added > 0 ? (f_before.weight_rmse - f_after.weight_rmse) / added : 0.0}};
  }
  test["network_multiply_adds_per_frame"] = solver.ForwardMultiplyAdds();
  test["threads"] = settings.threads;
  return Json{{"seed", seed}, {"training", training}, {"test", test}};
}

Json MeanSd(const std::vector<double>& values) {
  double mean = 0.0;
  for (double v : values) mean += v / static_cast<double>(values.size());
  double var = 0.0;
  for (double v : values)
    var += (v - mean) * (v - mean) / static_cast<double>(std::max<size_t>(1, values.size() - 1));
  return Json{{"mean", mean}, {"sd", std::sqrt(var)}, {"n", values.size()}};
}

// Mean and sample sd of every number under test.<set>.<method>.<figure> over the studies.
Json Replicates(const std::vector<Json>& studies) {
  Json out;
  for (const char* set : {"clean", "noisy"}) {
    for (const char* method : {"network", "qp_baseline", "network_finetuned"}) {
      for (const char* figure :
           {"weight_rmse", "jaw_weight_rmse", "jaw_deg_rms", "marker_rmse_mm", "frames_per_s"}) {
        std::vector<double> values;
        for (const Json& s : studies)
          values.push_back(s["test"][set][method][figure].get<double>());
        out[set][method][figure] = MeanSd(values);
      }
    }
  }
  if (studies.front()["test"].contains("filmed")) {
    for (const char* method : {"network", "qp_baseline", "network_finetuned"}) {
      for (const char* figure : {"weight_rmse", "jaw_weight_rmse", "jaw_deg_rms", "marker_rmse_mm",
                                 "true_marker_rmse_mm"}) {
        std::vector<double> values;
        for (const Json& s : studies)
          values.push_back(s["test"]["filmed"][method][figure].get<double>());
        out["filmed"][method][figure] = MeanSd(values);
      }
    }
    for (const char* figure :
         {"present_fraction", "filmed_marker_rms_mm", "filmed_marker_mean_error_mm"}) {
      std::vector<double> values;
      for (const Json& s : studies) values.push_back(s["test"]["filmed"][figure].get<double>());
      out["filmed"][figure] = MeanSd(values);
    }
  }
  for (const char* figure : {"network_weight_rmse_shifted", "network_weight_rmse_aligned",
                             "fraction_of_added_error_removed"}) {
    std::vector<double> values;
    for (const Json& s : studies)
      values.push_back(s["test"]["anchor_alignment"][figure].get<double>());
    out["anchor_alignment"][figure] = MeanSd(values);
  }
  if (studies.front()["test"].contains("salient")) {
    for (const char* set : {"clean", "noisy"}) {
      for (const char* method :
           {"chosen_on_clean_validation", "chosen_on_noisy_validation", "all_tuples"}) {
        for (const char* figure : {"weight_rmse", "marker_rmse_mm"}) {
          std::vector<double> values;
          for (const Json& s : studies)
            values.push_back(s["test"]["salient"]["test"][set][method][figure].get<double>());
          out["salient"][set][method][figure] = MeanSd(values);
        }
      }
    }
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  Settings settings;
  std::vector<uint64_t> seeds{1};
  bool epochs_given = false;
  std::string ict_dir;      // --ict: the ICT-FaceKit face instead of the procedural one
  std::string config_path;  // --config: region tables (default: the rig's own)
  for (int k = 1; k < argc; ++k) {
    const std::string arg = argv[k];
    auto next = [&]() -> const char* {
      if (k + 1 >= argc) {
        std::fprintf(stderr, "solve_bench: %s needs a value\n", arg.c_str());
        std::exit(2);
      }
      return argv[++k];
    };
    if (arg == "--quick") {
      settings.quick = true;
    } else if (arg == "--seed") {
      seeds = {static_cast<uint64_t>(facedyn::bench::FlagInteger("solve_bench", arg, next()))};
    } else if (arg == "--seeds") {
      seeds.clear();
      for (const std::string& item : Split(next())) {
        seeds.push_back(
            static_cast<uint64_t>(facedyn::bench::FlagInteger("solve_bench", arg, item.c_str())));
      }
    } else if (arg == "--epochs") {
      settings.epochs = static_cast<int>(facedyn::bench::FlagInteger("solve_bench", arg, next()));
      epochs_given = true;
    } else if (arg == "--seconds") {
      settings.seconds = facedyn::bench::FlagNumber("solve_bench", arg, next());
    } else if (arg == "--fps") {
      settings.fps = facedyn::bench::FlagNumber("solve_bench", arg, next());
    } else if (arg == "--noise-mm") {
      settings.noise_mm = facedyn::bench::FlagNumber("solve_bench", arg, next());
    } else if (arg == "--smoothness") {
      settings.smoothness = facedyn::bench::FlagNumber("solve_bench", arg, next());
    } else if (arg == "--salient") {
      settings.salient.clear();
      for (const std::string& item : Split(next())) {
        settings.salient.push_back(facedyn::bench::FlagNumber("solve_bench", arg, item.c_str()));
      }
    } else if (arg == "--threads") {
      settings.threads = static_cast<int>(facedyn::bench::FlagInteger("solve_bench", arg, next()));
    } else if (arg == "--active-channels") {
      settings.active_channels = facedyn::bench::FlagNumber("solve_bench", arg, next());
    } else if (arg == "--filmed-seconds") {
      settings.filmed_seconds = facedyn::bench::FlagNumber("solve_bench", arg, next());
    } else if (arg == "--ict") {
      ict_dir = next();
    } else if (arg == "--config") {
      config_path = next();
    } else if (arg == "--help" || arg == "-h") {
      std::printf(
          "solve_bench [--quick] [--seed N] [--seeds 1,2,3] [--epochs N] [--seconds S] [--fps N]\n"
          "            [--noise-mm S] [--salient T[,T...]] [--smoothness L] [--threads N]\n"
          "            [--active-channels K] [--filmed-seconds S] [--ict DIR [--config "
          "REGIONS.yaml]]\n");
      return 0;
    } else {
      std::fprintf(stderr, "solve_bench: unknown flag '%s' (--help lists them)\n", arg.c_str());
      return 2;
    }
  }
  if (settings.quick && !epochs_given) settings.epochs = 10;
  if (settings.epochs < 1 || settings.threads < 1 || !(settings.seconds > 0) ||
      !(settings.fps > 0) || settings.noise_mm < 0 || !(settings.filmed_seconds >= 0) ||
      !(settings.active_channels > 0) ||
      std::any_of(settings.salient.begin(), settings.salient.end(),
                  [](double t) { return !(t > 0.0 && t <= 1.0); }) ||
      seeds.empty()) {
    std::fprintf(
        stderr,
        "solve_bench: --epochs and --threads >= 1, --seconds and --fps > 0, --noise-mm and "
        "--filmed-seconds >= 0, --active-channels > 0, "
        "--salient thresholds in (0, 1], at least one seed\n");
    return 2;
  }
  if (settings.seconds * settings.fps < 2) {
    std::fprintf(stderr, "solve_bench: --seconds x --fps gives fewer than 2 frames\n");
    return 2;
  }
  if (!config_path.empty() && ict_dir.empty()) {
    std::fprintf(stderr,
                 "solve_bench: --config goes with --ict (the procedural face's tables "
                 "are embedded)\n");
    return 2;
  }
  facedyn::FaceRig rig;
  if (ict_dir.empty()) {
    rig = Check(facedyn::sim::MakeProceduralFace(facedyn::sim::ProceduralFaceOptions{}),
                "procedural face");
  } else {
    facedyn::sim::IctImportOptions ict;
    ict.dir = ict_dir;
    rig = Check(facedyn::sim::ImportIctFaceKit(ict), "ICT-FaceKit face");
    if (config_path.empty())
      config_path = std::string(FACEDYN_SOURCE_DIR) + "/config/solve/ict.yaml";
  }
  const Puppet puppet = Check(MakePuppet(rig), "puppet");
  const SolveConfig config = config_path.empty()
                                 ? Check(ProceduralSolveConfig(), "solve config")
                                 : Check(ReadSolveConfig(config_path), "solve config");
  const ResolvedConfig resolved = Check(ResolveSolveConfig(config, rig, puppet), "solve config");
  std::vector<Json> studies;
  for (uint64_t seed : seeds) studies.push_back(Study(rig, puppet, resolved, settings, seed));
  Json out = {{"bench", "solve"},
              {"rig", rig.name},
              {"channels", puppet.channel_count()},
              {"markers", puppet.marker_count()},
              {"quick", settings.quick},
              {"study", studies.front()}};
  if (studies.size() > 1) {
    out["seeds"] = seeds;
    out["replicates"] = Replicates(studies);
    out["studies"] = studies;
  }
  std::printf("%s\n", out.dump(2).c_str());
  return 0;
}
