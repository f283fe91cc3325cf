// ICT-FaceKit importer: the upstream folder, as users download it, into a FaceRig in mm.
//
// Upstream facts (ICT-FaceKit README.md): generic_neutral_mesh.obj is the full head (26719
// vertices, quads, centimetres, +Y up, face toward +Z); the face region is vertices 0..9408
// with polygons 0..9229; each expression is a full OBJ in the same topology named after its
// ARKit-style shape (browDown_L.obj, jawOpen.obj, ...; 53 in the README, 55 files in the
// shipped folder); identity000.obj.. are linear identity modes in the same topology.
//
// What the importer does: keeps the face region (faces touching other vertices are dropped;
// vertex numbering is unchanged), converts cm to mm, adds sum_k w_k (identity_k - neutral) to
// the neutral (expression deltas are unchanged by identity, so they hold for every identity),
// and stores each expression OBJ as a blendshape delta named by its file stem. It then finds
// the face's frame geometrically (eye and mouth openings from the boundary loops, nose tip,
// head extent from the full head mesh), moves the head so the skull-frame origin is the centre
// of the cranium (+Y up, face toward +Z), labels regions (physics::LabelFaceRegions; the jaw region
// is where jawOpen moves the skin by more than a third of its peak), puts the jaw hinge (axis +X)
// just in front of and below the ears, and completes the anatomy (physics::CompleteFaceAnatomy).
//
// Expression OBJs are read by a dedicated vertex-only reader (they share the neutral's
// topology): every file's vertex count is checked and a wrong one is reported with its path.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "core/face_rig.h"
#include "core/status.h"
#include "physics/face_anatomy.h"

namespace facedyn::sim {

inline constexpr int kIctFaceVertexCount = 9409;  // vertices 0..9408 (upstream README)
inline constexpr double kIctMmPerUnit = 10.0;     // ICT-FaceKit is in centimetres

struct IctImportOptions {
  std::string dir;  // the ICT-FaceKit folder (generic_neutral_mesh.obj, expression OBJs)
  std::vector<std::pair<std::string, double>> identity_weights;  // e.g. {{"identity000", 1.5}}
  std::string name;                 // rig name; "" gives "ict" plus the identity spec
  physics::AnatomyOptions anatomy;  // skull, samples, markers
  Status Check() const;
};

// Parses "identity000:1.5,identity002:-0.5" (whitespace around items allowed). Names must be
// identity000..identity003, the identity modes the facedyn ICT folder ships (upstream has 100
// PCA modes; raise kIctIdentityModes in ict_import.cc to accept more), weights finite numbers
// in [-10, 10], each name at most once. "" gives an empty list.
StatusOr<std::vector<std::pair<std::string, double>>> ParseIdentitySpec(const std::string& spec);

// Imports the folder (see above). Errors name the folder or the file that is missing, short or
// corrupt.
StatusOr<FaceRig> ImportIctFaceKit(const IctImportOptions& options);

}  // namespace facedyn::sim
