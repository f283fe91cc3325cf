// The procedural face and its puppet, built once per test binary (a few seconds of work).
#pragma once

#include "core/face_rig.h"
#include "sim/procedural_face.h"
#include "solve/puppet.h"

namespace facedyn::solve::testing {

inline const FaceRig& ProceduralRig() {
  static const FaceRig* rig =
      new FaceRig(sim::MakeProceduralFace(sim::ProceduralFaceOptions{}).value());
  return *rig;
}

inline const Puppet& ProceduralPuppet() {
  static const Puppet* puppet = new Puppet(MakePuppet(ProceduralRig()).value());
  return *puppet;
}

}  // namespace facedyn::solve::testing
