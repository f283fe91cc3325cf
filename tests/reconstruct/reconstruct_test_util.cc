#include "tests/reconstruct/reconstruct_test_util.h"

#include <algorithm>
#include <numeric>

#include "sim/procedural_face.h"

namespace facedyn::reconstruct::testing {

const FaceRig& ProceduralFace() {
  static const FaceRig* rig =
      new FaceRig(sim::MakeProceduralFace(sim::ProceduralFaceOptions()).value());
  return *rig;
}

std::vector<Camera> FaceCameraRing(int camera_count) { return MakeFaceCameraRing(camera_count); }

}  // namespace facedyn::reconstruct::testing
