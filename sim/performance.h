// SimulatePerformance: `facedyn sim perform` — a FaceRig, an expression curve and a skull
// motion in, a Take out whose positions are the dynamic skin and whose `quasistatic` channel
// is the exact quasistatic skin (same skull motion and expression, no inertia), with
// `dynamic_offset` = skull_from_world (dynamic - quasistatic), the paper's dx (Zoss et al.
// 2020, Eq. 6, here exact instead of a moving-average estimate).
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "core/face_rig.h"
#include "core/status.h"
#include "core/take.h"
#include "physics/soft_tissue.h"
#include "sim/skull_motion.h"

namespace facedyn::sim {

struct PerformanceOptions {
  // An expression name (sim/expressions.h, held), "speech" (sim/expressions.h DialogueVisemes at
  // 4.5 syllables/s) or "range_of_motion" (every RangeOfMotionPoses pose once per 10.3 s at 3
  // poses/s, MakeScriptedSequence: a performance for training Masquerade's upsampler, detail/).
  std::string expression = "neutral";
  MotionOptions motion;
  double seconds = 3.0;
  double fps = 128.0;
  uint64_t seed = 1;  // expression drift/speech timing; the motion has its own seed
  physics::TissueOptions tissue;
  // An explicit material in place of tissue's calibration (a fitted twin's, physics/twin.h
  // LoadTwin); tissue's other fields (layers, Poisson ratio, density, muscles, step) still apply.
  std::optional<physics::TissueMaterial> material;

  Status Check() const;
};

struct PerformanceSummary {
  physics::ReferenceSummary reference;
  double youngs_modulus_kpa = 0.0;
  int substeps_per_frame = 0;
  double simulate_s = 0.0;  // wall time
};

// Peak |dynamic_offset| (mm) over the take's frames and each region's vertices, for every
// region of the rig plus "face" (all vertices). Requires the take's dynamic_offset channel.
StatusOr<std::map<std::string, double>> PeakOffsetByRegionMm(const FaceRig& rig, const Take& take,
                                                             double skip_first_s = 0.5);

// When a held-expression take made with `options` is held, in s from its first frame: the
// expression's formation (0.3 s) and the motion's fade-in, whichever is longer, plus
// core/take.h kHeldExpressionSettleS; nullopt for speech and range_of_motion (a performance is
// never held).
// It follows from the performance's script alone (its ramps), never from the tissue, so a
// capture session that prompts the simulated actor may write it into its takes as a real
// session writes the time it prompted. SimulatePerformance writes it into take.info.
std::optional<double> HeldExpressionStartS(const PerformanceOptions& options);

// Deterministic for given options. Shows progress per frame.
StatusOr<Take> SimulatePerformance(const FaceRig& rig, const PerformanceOptions& options,
                                   PerformanceSummary* summary = nullptr);

}  // namespace facedyn::sim
