// Mesh: a polygon surface in fixed topology, the vertex order every Take and FaceRig shares.
//
// Faces are stored compactly (CSR: face_offsets indexes corner arrays) because captured and
// scanned heads mix quads and triangles (ICT-FaceKit is quads, MediaPipe triangles) and the
// topology must round-trip unchanged. UVs are per corner (corner_uvs indexes `uvs`) so seams
// survive; `VertexUvs()` gives one uv per vertex where a single chart is enough (surface
// stretch features). Positions are millimetres in whatever frame the owner documents.
//
// File I/O goes through OpenMesh (OBJ and PLY). Fixed topology is checked on read: OpenMesh
// repairs non-manifold input by duplicating vertices, which would silently renumber the mesh,
// so a read that changes the vertex count is an error rather than a new topology.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/status.h"

namespace facedyn {

struct Mesh {
  Eigen::Matrix3Xd positions_mm;  // 3 x V
  std::vector<int> face_offsets{0};  // F + 1 entries; face f has corners [offsets[f], offsets[f+1])
  std::vector<int> corner_vertices;  // vertex index per corner
  std::vector<int> corner_uvs;       // uv index per corner, or empty when the mesh has no UVs
  Eigen::Matrix2Xd uvs;              // 2 x T texture coordinates

  int vertex_count() const { return static_cast<int>(positions_mm.cols()); }
  int face_count() const { return static_cast<int>(face_offsets.size()) - 1; }
  int FaceSize(int face) const { return face_offsets[face + 1] - face_offsets[face]; }
  bool has_uvs() const { return !corner_uvs.empty(); }

  // Appends a face given by vertex indices (and optional per-corner uv indices).
  void AddFace(const std::vector<int>& vertices, const std::vector<int>& uv_indices = {});

  // Fan triangulation of every face, 3 x (sum of (size - 2)), in face order.
  Eigen::Matrix3Xi Triangles() const;

  // One uv per vertex (the first corner's uv that touches the vertex); vertices without a
  // uv get NaN. Requires has_uvs().
  Eigen::Matrix2Xd VertexUvs() const;

  // Checks indices are in range, faces have >= 3 corners, coordinates are finite.
  // `what` names the mesh in the message (a file path, "FaceRig neutral", ...).
  Status Validate(const std::string& what) const;
};

// Unit vertex normals of `positions_mm` (3 x V) in `mesh`'s topology: the sum of the adjacent
// fan triangles' normals weighted by their area; +Z for a vertex no triangle with area touches.
Eigen::Matrix3Xd VertexNormals(const Mesh& mesh, const Eigen::Matrix3Xd& positions_mm);

// Same topology (faces and UV layout); positions may differ.
bool SameTopology(const Mesh& a, const Mesh& b);

// Reads an OBJ or PLY (chosen by extension) with UVs when the file has them.
StatusOr<Mesh> ReadMesh(const std::string& path);

// Writes `mesh` as OBJ or PLY (by extension). With `positions_mm` (3 x V), those positions
// are written instead of mesh.positions_mm: one frame of a take in the take's topology.
// PLY stores one uv per vertex (the format has no per-corner uvs).
Status WriteMesh(const Mesh& mesh, const std::string& path);
Status WriteMesh(const Mesh& mesh, const Eigen::Matrix3Xd& positions_mm, const std::string& path);

}  // namespace facedyn
