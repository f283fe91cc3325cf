// Shared fixtures of the reconstruction tests: the procedural face, an 8-camera ring around
// it, and marker observations made by projecting known 3D points through known cameras.
#pragma once

#include <Eigen/Core>
#include <random>
#include <vector>

#include "core/face_rig.h"
#include "reconstruct/camera.h"
#include "reconstruct/synthetic_views.h"
#include "reconstruct/triangulation.h"

namespace facedyn::reconstruct::testing {

// The procedural face (built once per test binary).
const FaceRig& ProceduralFace();

// Eight 1280x1024 cameras on a 120-degree arc 600 mm in front of the face (f = 2200 px, mild
// barrel distortion), looking at the middle of the face.
std::vector<Camera> FaceCameraRing(int camera_count = 8);

using reconstruct::MarkerNormals;
using reconstruct::MarkerPositions;
using reconstruct::MarkerViews;
using reconstruct::ProjectMarkers;

}  // namespace facedyn::reconstruct::testing
