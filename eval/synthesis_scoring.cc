#include "eval/synthesis_scoring.h"

#include <cmath>

#include <fmt/format.h>

#include "dynamics/training_frames.h"
#include "eval/metrics.h"
#include "eval/removal_comparison.h"

namespace facedyn::eval {
namespace {

Status HasOffsets(const Take& take, const std::string& what) {
  if (take.channels.count("dynamic_offset") == 0) {
    return FailedPreconditionError(
        fmt::format("{} has no \"dynamic_offset\" channel", what));
  }
  return Status::Ok();
}

Status SameShape(const Take& a, const std::string& a_name, const Take& b,
                 const std::string& b_name) {
  if (a.frame_count() != b.frame_count() || a.vertex_count() != b.vertex_count()) {
    return FailedPreconditionError(fmt::format(
        "{} ({} frames, {} vertices) does not match {} ({} frames, {} vertices)", a_name,
        a.frame_count(), a.vertex_count(), b_name, b.frame_count(), b.vertex_count()));
  }
  return Status::Ok();
}

double Relative(double mm, double of_mm) { return of_mm > 0 ? mm / of_mm : 0.0; }

// The frames a protocol scores on `truth`; FailedPrecondition when there are none (a take too
// short for its hold start and the window margins).
StatusOr<dynamics::FrameRange> Scored(const Take& truth, int window_frames,
                                      const std::string& what) {
  const dynamics::FrameRange scored = dynamics::ScoredFrames(truth, window_frames);
  if (scored.empty()) {
    return FailedPreconditionError(fmt::format(
        "{}: no frame to score ({} frames; the hold start and {} frames of window margin at "
        "each end leave none)",
        what, truth.frame_count(), window_frames));
  }
  return scored;
}

}  // namespace

StatusOr<Json> SynthesisErrors(const Take& synthesised, const Take& truth,
                               const std::vector<int>& vertices, int window_frames) {
  FACEDYN_RETURN_IF_ERROR(HasOffsets(truth, "the truth"));
  FACEDYN_RETURN_IF_ERROR(HasOffsets(synthesised, "the synthesised take"));
  FACEDYN_RETURN_IF_ERROR(SameShape(synthesised, "the synthesised take", truth, "the truth"));
  FACEDYN_ASSIGN_OR_RETURN(const dynamics::FrameRange scored,
                           Scored(truth, window_frames, "synthesis errors"));
  return Json{{"position_mean_mm", Round4(MeanDistanceOverVertices(
                                       synthesised.positions, truth.positions, vertices, scored))},
              {"offset_mean_mm", Round4(MeanDistanceOverVertices(
                                     synthesised.channels.at("dynamic_offset"),
                                     truth.channels.at("dynamic_offset"), vertices, scored))}};
}

StatusOr<Json> NoDynamicsErrors(const Take& quasistatic, const Take& truth,
                                const std::vector<int>& vertices, int window_frames) {
  FACEDYN_RETURN_IF_ERROR(HasOffsets(truth, "the truth"));
  FACEDYN_RETURN_IF_ERROR(SameShape(quasistatic, "the quasistatic take", truth, "the truth"));
  FACEDYN_ASSIGN_OR_RETURN(const dynamics::FrameRange scored,
                           Scored(truth, window_frames, "no-dynamics errors"));
  return Json{{"position_mean_mm", Round4(MeanDistanceOverVertices(
                                       quasistatic.positions, truth.positions, vertices, scored))},
              {"offset_mean_mm",
               Round4(MeanOffsetNorm(truth.channels.at("dynamic_offset"), vertices, scored))}};
}

StatusOr<Json> ResynthesisFigures(const std::string& take_name, const Take& simulated,
                                  const Take& original, const Take& removed,
                                  const Take& resynthesised, int window_frames) {
  FACEDYN_RETURN_IF_ERROR(HasOffsets(simulated, take_name + ": the simulated take"));
  FACEDYN_RETURN_IF_ERROR(SameShape(original, take_name, simulated, "its simulation"));
  FACEDYN_RETURN_IF_ERROR(SameShape(removed, take_name + "'s removal", simulated, "its simulation"));
  FACEDYN_RETURN_IF_ERROR(
      SameShape(resynthesised, take_name + "'s resynthesis", simulated, "its simulation"));
  FACEDYN_ASSIGN_OR_RETURN(const dynamics::FrameRange scored,
                           Scored(simulated, window_frames, take_name));
  const PointCache& offsets = simulated.channels.at("dynamic_offset");
  const std::vector<int> jiggle = JigglingVertices(offsets, scored);
  const double offset_mm = MeanOffsetNorm(offsets, jiggle, scored);
  const double residual_mm =
      MeanDistanceOverVertices(resynthesised.positions, original.positions, jiggle, scored);
  // Without synthesis, the residual of the removed take is the dynamics themselves.
  const double removed_only_mm =
      MeanDistanceOverVertices(removed.positions, original.positions, jiggle, scored);
  Json figures = {{"take", take_name},
                  {"mean_dynamic_offset_mm", Round4(offset_mm)},
                  {"resynthesis_residual_mm", Round4(residual_mm)},
                  {"relative_to_offset", Round4(Relative(residual_mm, offset_mm))},
                  {"removed_without_synthesis_mm", Round4(removed_only_mm)}};
  if (&original != &simulated) {
    figures["resynthesised_vs_simulated_dynamic_mm"] = Round4(
        MeanDistanceOverVertices(resynthesised.positions, simulated.positions, jiggle, scored));
  }
  return figures;
}

StatusOr<RetargetingResult> ScoreRetargeting(const dynamics::SynthesisModel& target_synthesis,
                                             const Take& source_truth, const FaceRig& source_rig,
                                             const Take& target_truth, const FaceRig& target_rig,
                                             const Take& target_quasistatic, int window_frames,
                                             const dynamics::ModalSynthesisModel* target_modal) {
  FACEDYN_RETURN_IF_ERROR(HasOffsets(source_truth, "retargeting: the source's truth"));
  FACEDYN_RETURN_IF_ERROR(HasOffsets(target_truth, "retargeting: the target's truth"));
  if (source_truth.frame_count() != target_truth.frame_count() ||
      static_cast<int>(source_truth.world_from_skull.size()) != source_truth.frame_count() ||
      static_cast<int>(target_truth.world_from_skull.size()) != target_truth.frame_count()) {
    return InvalidArgumentError(fmt::format(
        "retargeting: the source ({} frames) and the target ({} frames) were not simulated "
        "under one head motion",
        source_truth.frame_count(), target_truth.frame_count()));
  }
  for (int t = 0; t < target_truth.frame_count(); ++t) {
    const Rigid3 d = source_truth.world_from_skull[t].Inverse() * target_truth.world_from_skull[t];
    if (d.translation().norm() > 1e-6 || d.AngleRad() > 1e-9) {
      return InvalidArgumentError(fmt::format(
          "retargeting: the target's head motion differs from the source's at frame {}", t));
    }
  }
  FACEDYN_ASSIGN_OR_RETURN(const dynamics::FrameRange scored,
                           Scored(target_truth, window_frames, "retargeting"));
  RetargetingResult result;
  FACEDYN_ASSIGN_OR_RETURN(
      result.retargeted,
      dynamics::SynthesizeDynamics(target_synthesis, target_quasistatic,
                                   source_truth.world_from_skull, source_truth.info.motion,
                                   target_rig));
  // Naive (Fig. 10b): the source's true offsets copied sample by sample onto the target. It is
  // given the exact source dynamics, the most it could have.
  FACEDYN_ASSIGN_OR_RETURN(result.naive, dynamics::NaiveDeltaTransfer(source_truth, source_rig,
                                                                      target_quasistatic,
                                                                      target_rig));
  const std::vector<int> jiggle =
      JigglingVertices(target_truth.channels.at("dynamic_offset"), scored);
  const double offset_mm =
      MeanOffsetNorm(target_truth.channels.at("dynamic_offset"), jiggle, scored);
  Json methods;
  FACEDYN_ASSIGN_OR_RETURN(methods["H_B_retarget"],
                           SynthesisErrors(result.retargeted, target_truth, jiggle, window_frames));
  FACEDYN_ASSIGN_OR_RETURN(methods["naive_delta_transfer"],
                           SynthesisErrors(result.naive, target_truth, jiggle, window_frames));
  if (target_modal != nullptr) {
    FACEDYN_ASSIGN_OR_RETURN(result.modal,
                             target_modal->Synthesize(target_quasistatic,
                                                      source_truth.world_from_skull,
                                                      source_truth.info.motion, target_rig));
    FACEDYN_ASSIGN_OR_RETURN(methods["modal_B_retarget"],
                             SynthesisErrors(result.modal, target_truth, jiggle, window_frames));
  }
  FACEDYN_ASSIGN_OR_RETURN(
      methods["no_dynamics"],
      NoDynamicsErrors(target_quasistatic, target_truth, jiggle, window_frames));
  result.figures = {{"jiggle_vertices", jiggle.size()},
                    {"mean_dynamic_offset_mm", Round4(offset_mm)},
                    {"methods", methods}};
  return result;
}

}  // namespace facedyn::eval
