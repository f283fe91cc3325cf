// Scoring of synthesis protocols (Zoss et al. 2020): remove-then-resynthesise (Fig. 7), a new
// head motion synthesised on a held shape (Figs. 8-9), and retargeting between subjects
// (Figs. 9-10) with the naive delta transfer (Fig. 10b) and no dynamics beside it. The truth is
// a simulated take with the exact "dynamic_offset" channel; the methods never see it.
//
// Shared by bench/dynamics_bench (eval/dynamics_study) and `facedyn demo`
// (app/demo_dynamics.cc), so both print the same protocol's figures.
#pragma once

#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"
#include "core/take.h"
#include "dynamics/modal_synthesis.h"
#include "dynamics/synthesis_model.h"

namespace facedyn::eval {

// Errors of a synthesised take against a simulated truth of the same head motion, over
// `vertices` and the truth's scored frames (window margin `window_frames`):
// "position_mean_mm" (world frame) and "offset_mean_mm" (the synthesised "dynamic_offset"
// channel against the true one, skull frame) — the second isolates the dynamics from the
// quasistatic estimate's own error. FailedPrecondition when a channel or a count is missing.
StatusOr<Json> SynthesisErrors(const Take& synthesised, const Take& truth,
                               const std::vector<int>& vertices, int window_frames);

// The same figures for a take without dynamics: its positions are the quasistatic itself and
// its offset error is the true offset's size.
StatusOr<Json> NoDynamicsErrors(const Take& quasistatic, const Take& truth,
                                const std::vector<int>& vertices, int window_frames);

// Fig. 7 on one take: `original` (the take the method removed from: the simulation itself, or
// a reconstruction of it), `removed` (the method's quasistatic estimate) and `resynthesised`
// (its dynamics synthesised back under the original head motion), scored over the jiggling
// vertices of `simulated` (which has the exact channels): the residual against the original,
// the residual without synthesis (the dynamics themselves) and, when `original` is not
// `simulated`, the resynthesis against the simulated dynamic skin.
StatusOr<Json> ResynthesisFigures(const std::string& take_name, const Take& simulated,
                                  const Take& original, const Take& removed,
                                  const Take& resynthesised, int window_frames);

// Retargeting (Figs. 9-10): a source subject's head motion played on a target subject whose
// quasistatic take (`target_quasistatic`, posed by the source's motion) and synthesis network
// H_B are the target's own. `source_truth` and `target_truth` are the two subjects simulated
// under the same head motion (checked frame by frame: InvalidArgument otherwise). Scores H_B,
// the naive delta transfer of the source's exact offsets (given the most it could have) and no
// dynamics against the target's truth. *retargeted and *naive (may be null) receive the takes.
// With `target_modal` (may be null), the target's modal synthesis (dynamics/modal_synthesis.h)
// is scored too, as "modal_B_retarget", and its take returned in `modal`.
struct RetargetingResult {
  Json figures;  // "jiggle_vertices", "mean_dynamic_offset_mm", "methods"
  Take retargeted;
  Take naive;
  Take modal;  // empty without a modal model
};
StatusOr<RetargetingResult> ScoreRetargeting(const dynamics::SynthesisModel& target_synthesis,
                                             const Take& source_truth, const FaceRig& source_rig,
                                             const Take& target_truth, const FaceRig& target_rig,
                                             const Take& target_quasistatic, int window_frames,
                                             const dynamics::ModalSynthesisModel* target_modal =
                                                 nullptr);

}  // namespace facedyn::eval
