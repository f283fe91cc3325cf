// ReadMesh (core/mesh.h) on an arbitrary .ply file: a Take's topology, imported face meshes.
#include <cstddef>
#include <cstdint>

#include "core/mesh.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = facedyn::fuzz::WriteScratchFile("input.ply", data, size);
  const auto mesh = facedyn::ReadMesh(path);
  if (!mesh.ok()) return 0;
  // An accepted mesh is valid, so what its users do first must work: triangulate, read uvs.
  if (!mesh->Validate(path).ok()) __builtin_trap();
  const Eigen::Matrix3Xi triangles = mesh->Triangles();
  if (mesh->has_uvs()) (void)mesh->VertexUvs();
  (void)triangles;
  return 0;
}
