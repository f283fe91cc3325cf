// TetShell: the volumetric soft tissue between skin and skull as layered prisms split into
// tetrahedra.
//
// The FaceRig's skull surface shares the skin's topology (physics/face_anatomy.h): skull vertex i
// lies under skin vertex i. Node (layer l, vertex i) interpolates linearly between them, l = 0
// on the skull (attached) and l = layers on the skin. Each skin triangle and layer gives a
// prism, split into 3 tetrahedra by the rule "on the quad between vertices p < q the diagonal
// joins q below with p above", which depends only on global indices, so neighbouring prisms
// agree on their shared faces and the mesh is conforming. An extruded shell is what the
// anatomy is (a few mm to 2 cm of flesh over bone) and needs no tetrahedral mesher (TetGen is
// AGPL and not used).
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/mesh.h"

namespace facedyn::physics {

struct TetShell {
  int layers = 0;
  int surface_vertex_count = 0;
  Eigen::Matrix3Xd rest_positions_mm;  // 3 x N, node(l, i) at column l * V + i
  Eigen::Matrix4Xi tets;               // 4 x T, positively oriented at rest
  Eigen::VectorXi tet_surface_vertex;  // per tet: a skin vertex of its prism (for region lookup)

  int node_count() const { return static_cast<int>(rest_positions_mm.cols()); }
  int Node(int layer, int vertex) const { return layer * surface_vertex_count + vertex; }
  int SkinNode(int vertex) const { return Node(layers, vertex); }
};

// Builds the shell. Preconditions: skin and skull have the same vertex count; layers >= 1.
// Prisms whose tetrahedra would be degenerate (skull vertex on the skin) are skipped.
TetShell BuildTetShell(const Mesh& skin, const Eigen::Matrix3Xd& skull_positions_mm, int layers);

}  // namespace facedyn::physics
