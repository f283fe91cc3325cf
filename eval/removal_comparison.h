// One held-out take of a removal protocol on a reconstruction (the demo's): F against the
// baselines, the low-pass oracle, an optional reference F, the lower reference (Eq. 7 with the
// exact offsets in the estimated skull frame) and the skull-frame error of every method, over
// the take's jiggling vertices and scored frames, against the exact quasistatic of the
// simulation the take was reconstructed from. Prints a table and returns it as JSON.
#pragma once

#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"
#include "core/take.h"
#include "dynamics/removal_model.h"
#include "dynamics/training_frames.h"

namespace facedyn::eval {

// Another removal method's output on the reconstruction (e.g. the modal removal,
// dynamics/modal_synthesis.h), scored beside F under `name`.
struct NamedRemoval {
  std::string name;
  const Take* removed = nullptr;
};

// `reference` (may be null): another F (e.g. trained on simulated takes with exact targets).
// `others`: further methods' removals of `reconstructed`, each scored like F.
// `window_frames`: the metrics' window margin. *removed_out (may be null): F's removal. The
// simulated take must have the quasistatic and dynamic_offset channels and the reconstruction
// its frame and vertex counts (FailedPrecondition naming what is missing).
StatusOr<Json> CompareRemovalOnReconstruction(const dynamics::RemovalModel& f_model,
                                              const dynamics::RemovalModel* reference,
                                              const std::string& take_name, const Take& simulated,
                                              const Take& reconstructed, const FaceRig& face,
                                              int window_frames, Take* removed_out,
                                              const std::vector<NamedRemoval>& others = {});

// One line of the removal tables: what, method, error (mm), error relative to the offset.
void PrintMethodRow(const std::string& what, const std::string& method, double mm, double of);

// Mean |offset| (mm) over `vertices` and `frames`.
double MeanOffsetNorm(const PointCache& offsets, const std::vector<int>& vertices,
                      dynamics::FrameRange frames);

}  // namespace facedyn::eval
