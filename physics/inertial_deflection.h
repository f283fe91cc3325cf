// The skin's static deflection under the skull's inertial loads, at the rig's markers: what the
// face model predicts a marker does when the head accelerates slowly enough for the flesh to
// follow without ringing. reconstruct/skull_pose.h uses it as the shape of the stable markers'
// jiggle, so that the skull pose does not absorb it.
//
// Why the model and not a formula: the deflection of a soft layer on bone under a body force
// grows with its thickness squared (the rule the skull pose used before), but it also slides the
// skin along the bone in directions set by the layer's shape, its boundary and the load's
// direction, and an angular acceleration loads each point in proportion to its lever arm. The
// tissue FEM (physics/soft_tissue.h) has all of it. Only shapes are used: the deflection per
// unit load scales as 1/E, so the basis is normalised and no material parameter of the subject
// is needed (nor read: the model runs with a unit Young's modulus and uniform stiffness).
#pragma once

#include <Eigen/Core>

#include "core/face_rig.h"
#include "core/status.h"
#include "physics/soft_tissue.h"

namespace facedyn::physics {

struct InertialDeflectionOptions {
  // Columns 0-2: uniform acceleration of the flesh along the skull's x, y, z (gravity's change
  // and the origin's acceleration); with `angular`, columns 3-5: angular acceleration about
  // the skull's x, y, z axes through its origin.
  bool angular = true;
  // Load-dependent Ritz blocks (Wilson, Yuan & Dickens 1982): 1 is the static deflection
  // K^-1 F; each further block multiplies the last by K^-1 M, which adds what inertia does to
  // the shape as the load's frequency rises (the dynamic response at frequency w is
  // sum_j (w^2 K^-1 M)^j K^-1 F below the first resonance). The shapes do not depend on a
  // uniform stiffness scale (K^-1 M K^-1 F scales as 1/E^2 and is normalised). With more than
  // one block the columns are orthonormalised over the markers (same span).
  int krylov_blocks = 1;
  TissueOptions tissue;  // mesh layers and Poisson ratio; the calibration targets are unused
};

// (3 x markers) x (3 or 6) * krylov_blocks matrix, row 3m + axis for rig.markers[m], in the skull
// frame; every column scaled to unit RMS over the markers (mm per unit load of arbitrary scale).
// Requires a rig whose skull shares the skin's topology (physics/face_anatomy.h rigs). Takes about
// as long as one factorisation of the tissue's stiffness (seconds for the procedural face).
StatusOr<Eigen::MatrixXd> MarkerInertialDeflectionBasis(const FaceRig& rig,
                                                        const InertialDeflectionOptions& options);

}  // namespace facedyn::physics
