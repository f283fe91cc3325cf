// glTF 2.0 binary (.glb) export through tinygltf: what Blender, Maya (with a plug-in), Unreal,
// three.js and every web glTF viewer load.
//
// What is written, and why:
//   - Units and frame: glTF is metres, +Y up, right-handed; facedyn's world is millimetres,
//     +Y up, right-handed, so positions are scaled by 1e-3 and nothing is rotated.
//   - One mesh, one primitive of triangles (polygons fan-triangulated as Mesh::Triangles does).
//     glTF has one uv per vertex, so a vertex that sits on a UV seam is split: glb vertex i
//     is facedyn vertex i for i < V, and the seam copies follow, their source vertices listed
//     in the mesh's extras ("facedyn_seam_source_vertices") so a reader can weld them back.
//   - Smooth vertex normals (core/mesh.h VertexNormals) for the base and, per morph target,
//     the normal change, so shading follows the deformation.
//   - Morph target names in mesh.extras.targetNames (the convention Blender's importer and
//     three.js's GLTFLoader read).
//
// A rig (WriteRigGlb): the neutral with one morph target per blendshape, in the rig's order
// and under its names, plus optionally an animation "weights" of the morph weights sampled at
// the track's times (LINEAR, as a solve's curves are meant). The rig's jaw is a hinge in the
// skull, not a blendshape: it is not exported (say so to anyone who expects it).
//
// A take (WriteTakeGlb): glTF can move vertices only through morph targets, so the take is its
// first frame plus one morph target per later frame ("frame_000001", ...) and an animation
// whose weights are one-hot at each frame's time from the take's start: exact at every frame,
// linear between neighbours, and at most two targets active at once (viewers that cap active
// morph targets show it correctly). It costs 24 bytes per vertex per frame (position and
// normal deltas, float32), about 87 MB for a 3 s, 128 fps, 9,409-vertex take: fine for review
// clips; for long takes use the point caches (PC2/MDD), which are 12 bytes per vertex per
// frame and which Blender's Mesh Cache modifier plays from disk.
#pragma once

#include <cstdint>
#include <string>

#include "core/blendshape_weights.h"
#include "core/face_rig.h"
#include "core/status.h"
#include "core/take.h"

namespace facedyn {

struct GlbSummary {
  int vertex_count = 0;        // glb vertices (facedyn vertices plus seam copies)
  int morph_target_count = 0;
  int animation_samples = 0;   // 0 without an animation
  uint64_t bytes = 0;          // size of the .glb
};

// Writes the rig (neutral + blendshapes) and, when `animation` is given, its weights over time.
// Every column of `animation` must name one of the rig's blendshapes (an error names the first
// that does not); the rig's shapes the track does not name stay at 0. Written atomically.
StatusOr<GlbSummary> WriteRigGlb(const FaceRig& rig, const BlendshapeWeightsTrack* animation,
                                 const std::string& path);

// Writes a take as described above; a 1-frame take is a static mesh without morph targets.
// A .glb is limited to 4 GiB by its 32-bit length fields; a take that would exceed it is an
// error naming its size (export it as PC2 or MDD instead). Written atomically.
StatusOr<GlbSummary> WriteTakeGlb(const Take& take, const std::string& path);

}  // namespace facedyn
