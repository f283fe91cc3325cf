// The rig-solving stage of `facedyn demo` (issue 21, FDLS): the reconstructed talking take, as
// filmed (with the platform's jiggle) and after dynamics removal, solved into the puppet's
// controls (the demo face's named blendshapes and jaw), and the solved weights driving a second
// character (subject B, another face with the same channel names). It wires solve/ (the method)
// to the dynamics stage's takes; the simulator's exact quasistatic skin is read only to score.
#pragma once

#include <cstdint>
#include <string>

#include "app/demo_dynamics.h"
#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::app {

struct SolveDemoOptions {
  bool quick = false;
  uint64_t seed = 1;
  int epochs = 20;  // per region network (FDLS tables' default: 60, ~3 min on one thread)
  static SolveDemoOptions ForDemo(bool quick, uint64_t seed);
};

// Trains an FDLS solver on `face`'s puppet (FDLS 4.1 tuples from the rig alone), solves
// `artifacts`' performance takes (performance_reconstructed and performance_removed, markers read
// off each frame's mesh) with the network and with fine-tuning, scores both against reference
// weights (the QP solve of the simulator's exact quasistatic skin: what the weights would be
// without secondary dynamics), writes the weights CSVs under <out_dir>/solve and the second
// character driven by the removed take's weights as a take (<out_dir>/takes/solve_driven_B), and
// returns the figures ("training", "from_reconstructed", "from_removed", "curves" for the report's
// plot, "driven"). Errors: no performance in the artifacts, a take that does not fit the face.
StatusOr<Json> RunSolveDemoStage(const FaceRig& face, const DemoDynamicsArtifacts& artifacts,
                                 const SolveDemoOptions& options, const std::string& out_dir);

}  // namespace facedyn::app
