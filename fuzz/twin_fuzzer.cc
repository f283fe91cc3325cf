// physics::LoadTwin (physics/twin.h): the twin file `facedyn twin fit` writes and `twin perform`
// reads, which a user may edit, copy between machines or truncate. Read against the procedural
// face (the rig the seeds were fitted to; built once).
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "physics/twin.h"
#include "sim/procedural_face.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const facedyn::FaceRig* rig = new facedyn::FaceRig(
      facedyn::sim::MakeProceduralFace(facedyn::sim::ProceduralFaceOptions()).value());
  const std::string path = facedyn::fuzz::WriteScratchFile("twin.json", data, size);
  const auto twin = facedyn::physics::LoadTwin(path, *rig);
  // A twin the loader accepts must be simulable: valid tissue options, a positive modulus, one
  // positive stiffness scale per tetrahedron, non-negative damping, and a sane body if any.
  if (twin.ok()) {
    if (!twin->tissue.Check().ok()) __builtin_trap();
    const auto& material = twin->material;
    if (!(material.youngs_modulus_kpa > 0) || !(material.rayleigh_mass >= 0) ||
        !(material.rayleigh_stiffness >= 0) || material.tet_stiffness_scale.size() == 0) {
      __builtin_trap();
    }
    for (Eigen::Index e = 0; e < material.tet_stiffness_scale.size(); ++e) {
      if (!(material.tet_stiffness_scale[e] > 0)) __builtin_trap();
    }
    if (twin->body && (!(twin->body->resonance_hz > 0) || !(twin->body->damping_ratio > 0) ||
                       !std::isfinite(twin->body->pitch_rad_per_g))) {
      __builtin_trap();
    }
  }
  return 0;
}
