#include "eval/removal_comparison.h"

#include <cmath>
#include <cstdio>
#include <vector>

#include <fmt/format.h>

#include "dynamics/baselines.h"
#include "dynamics/training_frames.h"
#include "eval/metrics.h"
#include "eval/skull_frame.h"

namespace facedyn::eval {
namespace {



}  // namespace

void PrintMethodRow(const std::string& what, const std::string& method, double mm, double of) {
  std::printf("  %-28s %-30s %8.3f mm %7.1f%%\n", what.c_str(), method.c_str(), mm, 100 * of);
}

double MeanOffsetNorm(const PointCache& offsets, const std::vector<int>& vertices,
                      dynamics::FrameRange frames) {
  PointCache zero = offsets;
  zero.positions.setZero();
  return MeanDistanceOverVertices(offsets, zero, vertices, frames);
}

StatusOr<Json> CompareRemovalOnReconstruction(const dynamics::RemovalModel& f_model,
                              const dynamics::RemovalModel* reference, const std::string& take_name,
                              const Take& simulated, const Take& reconstructed, const FaceRig& face,
                              int window_frames, Take* removed_out,
                              const std::vector<NamedRemoval>& others) {
  for (const char* channel : {"quasistatic", "dynamic_offset"}) {
    if (simulated.channels.count(channel) == 0) {
      return FailedPreconditionError(
          fmt::format("{}: the simulated take has no \"{}\" channel", take_name, channel));
    }
  }
  if (reconstructed.frame_count() != simulated.frame_count() ||
      reconstructed.vertex_count() != simulated.vertex_count()) {
    return FailedPreconditionError(fmt::format(
        "{}: the reconstruction ({} frames, {} vertices) does not match its simulation ({} "
        "frames, {} vertices)",
        take_name, reconstructed.frame_count(), reconstructed.vertex_count(),
        simulated.frame_count(), simulated.vertex_count()));
  }
  const int skip = window_frames;
  const dynamics::FrameRange scored = dynamics::ScoredFrames(simulated, skip);
  const PointCache& truth = simulated.channels.at("quasistatic");
  const std::vector<int> jiggle =
      JigglingVertices(simulated.channels.at("dynamic_offset"), scored);
  const double offset_mm = MeanOffsetNorm(simulated.channels.at("dynamic_offset"), jiggle, scored);
  FACEDYN_ASSIGN_OR_RETURN(Take removed, dynamics::RemoveDynamics(f_model, reconstructed, face));
  EvaluateOptions evaluate;  // scored frames: ScoredFrames(simulated, window), as above
  FACEDYN_ASSIGN_OR_RETURN(const Evaluation evaluation,
                           Evaluate(removed, simulated, &reconstructed, &face, evaluate));
  Json methods = Json::object();
  auto add_method = [&](const std::string& name, const PointCache& predicted,
                        const ErrorStats& face_stats) {
    const double error_mm = MeanDistanceOverVertices(predicted, truth, jiggle, scored);
    // The stabilised expression in the skull frame (eval/skull_frame.h): the method's in the
    // reconstruction's estimated skull frame against the exact one in the simulator's.
    const double skull_mm = SkullFrameMeanDistance(
        predicted, reconstructed.world_from_skull, truth, simulated.world_from_skull, jiggle, scored);
    methods[name] = {{"mean_mm", Round4(face_stats.mean_mm)},
                     {"skull_frame_jiggle_mean_mm", Round4(skull_mm)},
                     {"p95_mm", Round4(face_stats.p95_mm)},
                     {"max_mm", Round4(face_stats.max_mm)},
                     {"jiggle_mean_mm", Round4(error_mm)},
                     {"relative_to_offset", Round4(offset_mm > 0 ? error_mm / offset_mm : 0.0)}};
  };
  add_method("F", removed.positions, evaluation.reports.front().face);
  if (reference != nullptr) {
    FACEDYN_ASSIGN_OR_RETURN(const Take by_reference,
                             dynamics::RemoveDynamics(*reference, reconstructed, face));
    FACEDYN_ASSIGN_OR_RETURN(const Evaluation reference_evaluation,
                             Evaluate(by_reference, simulated, nullptr, &face, evaluate));
    add_method("F_exact_targets_simulated", by_reference.positions,
               reference_evaluation.reports.front().face);
  }
  for (const NamedRemoval& other : others) {
    if (other.removed == nullptr || other.removed->frame_count() != reconstructed.frame_count() ||
        other.removed->vertex_count() != reconstructed.vertex_count()) {
      return InvalidArgumentError(fmt::format(
          "{}: the \"{}\" removal is missing or does not match the reconstruction", take_name,
          other.name));
    }
    FACEDYN_ASSIGN_OR_RETURN(const Evaluation other_evaluation,
                             Evaluate(*other.removed, simulated, nullptr, &face, evaluate));
    add_method(other.name, other.removed->positions, other_evaluation.reports.front().face);
  }
  for (size_t r = 1; r < evaluation.reports.size(); ++r) {
    const std::string& name = evaluation.reports[r].name;
    FACEDYN_ASSIGN_OR_RETURN(
        const PointCache baseline,
        BaselinePositions(reconstructed, evaluation, name, evaluate.baselines));
    add_method(name, baseline, evaluation.reports[r].face);
    if (name == "lowpass") methods[name]["cutoff_hz"] = Round4(evaluation.rule_cutoff_hz);
    if (name == "lowpass_oracle") {
      methods[name]["cutoff_hz"] = evaluation.oracle_cutoff_hz;
      methods[name]["oracle"] = true;
    }
  }
  // What the reconstruction itself gets wrong (its positions vs the simulated ones, dynamics
  // included): a floor for any removal that only subtracts dynamics, which a temporal filter
  // like the low-pass can go below by smoothing the reconstruction's frame-to-frame noise.
  const double reconstruction_error_mm = MeanDistanceOverVertices(
      reconstructed.positions, simulated.positions, jiggle, scored);
  // The lower reference (eval/skull_frame.h): Eq. 7 with the exact offsets in the estimated
  // skull frame, the error a perfect F would leave on this reconstruction.
  const PointCache exact_offsets_removed =
      RemoveExactOffsets(reconstructed, simulated.channels.at("dynamic_offset"));
  const double exact_offsets_removed_mm =
      MeanDistanceOverVertices(exact_offsets_removed, truth, jiggle, scored);
  const double f_mm = methods["F"]["jiggle_mean_mm"].get<double>();
  const double lowpass_mm = methods["lowpass"]["jiggle_mean_mm"].get<double>();
  std::printf(
      "\nRemoval on the reconstructed %s take (never trained on), error vs the exact "
      "quasistatic over the jiggling vertices (mean true offset %.3f mm):\n",
      take_name.c_str(), offset_mm);
  for (const auto& [method, figures] : methods.items()) {
    PrintMethodRow(take_name + " reconstructed", method, figures["jiggle_mean_mm"].get<double>(),
             figures["relative_to_offset"].get<double>());
  }
  std::printf(
      "  (the reconstruction itself is %.3f mm from the simulated positions there; Eq. 7 with the "
      "exact offsets in its estimated skull frame is %.3f mm from the exact quasistatic; "
      "low-pass cutoff by rule %.2f Hz, the oracle's %.1f Hz)\n",
      reconstruction_error_mm, exact_offsets_removed_mm, evaluation.rule_cutoff_hz,
      evaluation.oracle_cutoff_hz);
  if (removed_out != nullptr) *removed_out = std::move(removed);
  return Json{{"take", take_name + " reconstructed"},
              {"truth", "exact quasistatic of the simulation that was reconstructed"},
              {"scored_frames", {scored.begin, scored.end}},
              {"jiggle_vertices", jiggle.size()},
              {"mean_dynamic_offset_mm", Round4(offset_mm)},
              {"reconstruction_error_mm", Round4(reconstruction_error_mm)},
              {"exact_offsets_removed_mm", Round4(exact_offsets_removed_mm)},
              {"methods", methods},
              {"lowpass_over_F", Round4(f_mm > 0 ? lowpass_mm / f_mm : 0.0)}};
}


}  // namespace facedyn::eval
