// A small synthetic training set for the detail tests: a patch of an ellipsoid (a face-sized
// curved surface, core/mesh_primitives.h), a few markers spread over it, and frames that are a
// smooth two-parameter deformation plus fine ripples (wavelength below the marker spacing, so
// the markers alone can not give them) whose amplitude follows the deformation.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/mesh.h"
#include "core/mesh_primitives.h"
#include "detail/training_set.h"

namespace facedyn::detail::testing {

inline Mesh TestPatch() { return MakeEllipsoidPatch(80.0, 100.0, 60.0, 0.9, 0.8, 24, 24); }

// Markers at a regular sub-grid of the patch's vertices (rows x cols markers).
inline std::vector<Marker> TestMarkers(const Mesh& mesh, int per_side = 4) {
  // The patch's grid has 25 x 25 vertices, row-major.
  const int side = 25;
  std::vector<Marker> markers;
  for (int i = 0; i < per_side; ++i) {
    for (int j = 0; j < per_side; ++j) {
      const int r = 2 + i * (side - 5) / (per_side - 1), c = 2 + j * (side - 5) / (per_side - 1);
      Marker m;
      m.name = "m" + std::to_string(i) + "_" + std::to_string(j);
      m.point = SurfacePoint::AtVertex(r * side + c);
      markers.push_back(m);
    }
  }
  (void)mesh;
  return markers;
}

// Frame for pose (a, b): a smooth bulge and a sideways stretch (large scale) plus ripples of
// amplitude 0.6 a mm along z with a 12 mm wavelength (fine scale).
inline Eigen::Matrix3Xd TestFrame(const Mesh& mesh, double a, double b) {
  Eigen::Matrix3Xd x = mesh.positions_mm;
  for (int v = 0; v < x.cols(); ++v) {
    const double px = mesh.positions_mm(0, v), py = mesh.positions_mm(1, v);
    x(2, v) += 8.0 * a * std::exp(-(px * px + py * py) / (2 * 40.0 * 40.0));
    x(0, v) += 4.0 * b * px / 100.0;
    x(2, v) += 0.6 * a * std::sin(2 * M_PI * px / 12.0) * std::cos(2 * M_PI * py / 12.0) +
               0.3 * b * std::sin(2 * M_PI * py / 10.0);
  }
  return x;
}

inline DetailTrainingSet TestTrainingSet(int per_axis = 5) {
  DetailTrainingSet set;
  set.subject = "patch";
  set.neutral = TestPatch();
  set.markers = TestMarkers(set.neutral);
  for (int i = 0; i < per_axis; ++i) {
    for (int j = 0; j < per_axis; ++j) {
      set.frames_mm.push_back(
          TestFrame(set.neutral, -1.0 + 2.0 * i / (per_axis - 1), -1.0 + 2.0 * j / (per_axis - 1)));
    }
  }
  return set;
}

}  // namespace facedyn::detail::testing
