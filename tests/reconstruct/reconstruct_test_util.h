// Shared fixtures of the reconstruction tests: the procedural face, an 8-camera ring around
// it, and marker observations made by projecting known 3D points through known cameras.
#pragma once

#include <random>
#include <vector>

#include <Eigen/Core>

#include "core/face_rig.h"
#include "reconstruct/camera.h"
#include "reconstruct/triangulation.h"

namespace facedyn::reconstruct::testing {

// The procedural face (built once per test binary).
const FaceRig& ProceduralFace();

// Eight 1280x1024 cameras on a 120-degree arc 600 mm in front of the face (f = 2200 px, mild
// barrel distortion), looking at the middle of the face.
std::vector<Camera> FaceCameraRing(int camera_count = 8);

// Marker positions (3 x M) and unit normals on the skin `skin_in_world` (3 x V).
Eigen::Matrix3Xd MarkerPositions(const FaceRig& rig, const Eigen::Matrix3Xd& skin_in_world);
Eigen::Matrix3Xd MarkerNormals(const FaceRig& rig, const Eigen::Matrix3Xd& skin_in_world);

struct MarkerViews {
  std::vector<std::vector<ImageObservation>> detections;  // per camera
  std::vector<std::vector<int>> truth;                    // marker index of each detection
};
// Projects every marker that faces a camera (normal towards it by more than `min_cos`) and
// lies in its image, adding Gaussian noise of `sigma_px` per axis; detection order shuffled.
MarkerViews ProjectMarkers(const std::vector<Camera>& cameras, const Eigen::Matrix3Xd& markers,
                           const Eigen::Matrix3Xd& normals, double sigma_px, std::mt19937* rng,
                           double min_cos = 0.2);

}  // namespace facedyn::reconstruct::testing
