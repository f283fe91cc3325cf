// The procedural face: facedyn's embedded default FaceRig, needing no files.
//
// The skin is a single chart over a (u, y) parameter rectangle: u is arc length (mm) around a
// reference head ellipse, y the height (mm). Each grid point sits on a head-shaped generalized
// cylinder (half width a(y), depth c(y)) and is pushed along the surface normal by a sum of
// smooth bumps and dips: brow ridge, eye sockets, nose with alae, cheekbones, muzzle, lips,
// chin. The eye openings and the mouth slit are holes cut out of the grid (ellipses in (u, y),
// which never leaves a bow-tie vertex); their rims are then pulled onto the ellipse (eyes) or
// into a lens (mouth). UVs are the normalised (u, y), so the chart is one piece in [0,1]^2 and
// every triangle keeps its orientation in uv. Expressions are smooth, local displacement fields
// defined on the same coordinates, so they do not depend on the resolution.
//
// Frame: the skull frame at rest (mm): origin near the centre of the head, +Y up, the face
// looking toward +Z, +X the subject's left. The face is about 147 mm wide and 207 mm tall.
#pragma once

#include <Eigen/Core>
#include <string>

#include "core/face_rig.h"
#include "core/status.h"
#include "physics/face_anatomy.h"

namespace facedyn::sim {

// Blendshape names of the procedural face (deltas in mm), in this order.
inline constexpr const char* kProceduralExpressions[] = {
    "smile",      "jaw_open",   "pucker",        "brow_raise", "squeeze",
    "cheek_puff", "lip_funnel", "mouth_stretch", "sneer",      "lips_parted"};

// Mandible rotation of jaw_open at weight 1 (about +X through the jaw pivot; positive opens).
// With the chin ~116 mm from the pivot this drops the chin by ~20 mm.
inline constexpr double kProceduralJawOpenRad = 0.175;
// Temporomandibular joint (hinge) in the skull frame, just in front of the ears.
inline const Eigen::Vector3d kProceduralJawPivotMm{0.0, -18.0, 5.0};

struct ProceduralFaceOptions {
  // 4000..10000; the result is within +-10% (typically 2%). The default keeps a 3 s, 128 fps
  // simulated take under 10 s on a 2-core machine (bench/sim_bench).
  int target_vertex_count = 5000;
  std::string name = "procedural";
  physics::AnatomyOptions anatomy;  // skull, samples, markers
  Status Check() const;
};

// Builds the complete procedural FaceRig: neutral skin with UVs, the 10 expression
// blendshapes of kProceduralExpressions, regions (see physics::LabelFaceRegions), jaw (pivot
// kProceduralJawPivotMm, axis +X, region "jaw"), then physics::CompleteFaceAnatomy. Deterministic.
StatusOr<FaceRig> MakeProceduralFace(const ProceduralFaceOptions& options);

// Another subject from a rig: every position the rig stores in the skull frame (skin, skull,
// expression deltas, landmarks, jaw pivot) scaled per axis by `scale` (each > 0). Samples,
// markers and regions are defined on vertices, so they follow. Tissue thickness scales with the
// face, as it would between a smaller and a larger head. Errors name a bad scale or what the
// scaled rig fails to validate.
StatusOr<FaceRig> ScaledFaceRig(const FaceRig& rig, const Eigen::Vector3d& scale,
                                const std::string& name);

}  // namespace facedyn::sim
