// FaceRig: what the simulator and the solvers know about one subject.
//
// Everything is in the skull frame at rest, in millimetres (the skull frame's origin is the
// head's rest pose, so the rest skin and the skull share coordinates). A rig holds:
//   - the neutral skin mesh with UVs, and named expression blendshapes as per-vertex deltas;
//   - the skull surface and its landmarks (Zoss et al. 2020, Fig. 4a: b1..b5, usually 5);
//   - skin samples, points on the skin where dynamics are learned (Fig. 4b: 344);
//   - the painted-marker layout used by reconstruction;
//   - named vertex regions, some of them stable (forehead, nose bridge, temples) for
//     stabilisation, and the jaw: its pivot and hinge axis and the region it drives.
// Points on the skin are SurfacePoints (three vertices + barycentric weights) so they stay
// attached to the skin whatever the mesh resolution.
//
// Folder format (SaveFaceRig / LoadFaceRig):
//   face_rig.json      name, units, blendshape names, landmarks, jaw, regions, stable_regions
//   neutral.obj        neutral skin with UVs
//   blendshapes.pc2    frame k = deltas of blendshape k (absent when there are none)
//   skull.obj          skull surface
//   skin_samples.csv   v0,v1,v2,w0,w1,w2
//   markers.csv        name,v0,v1,v2,w0,w1,w2,diameter_mm
#pragma once

#include <array>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/mesh.h"
#include "core/status.h"

namespace facedyn {

inline constexpr int kFaceRigFormatVersion = 1;

struct SurfacePoint {
  std::array<int, 3> vertices{0, 0, 0};
  Eigen::Vector3d weights{1.0, 0.0, 0.0};  // barycentric, sum to 1

  static SurfacePoint AtVertex(int v) { return SurfacePoint{{v, v, v}, {1.0, 0.0, 0.0}}; }
  // The point on a surface with the given vertex positions (3 x V).
  template <typename Derived>
  Eigen::Vector3d Evaluate(const Eigen::MatrixBase<Derived>& positions) const {
    return weights[0] * positions.col(vertices[0]).template cast<double>() +
           weights[1] * positions.col(vertices[1]).template cast<double>() +
           weights[2] * positions.col(vertices[2]).template cast<double>();
  }
};

struct SkullLandmark {
  std::string name;
  Eigen::Vector3d position_in_skull;
};

struct Marker {
  std::string name;
  SurfacePoint point;
  double diameter_mm = 2.0;
};

struct JawModel {
  Eigen::Vector3d pivot_in_skull = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis_in_skull = Eigen::Vector3d::UnitX();  // hinge axis, unit
  std::string region;  // name of the region the jaw drives ("" when the rig has no jaw)
};

struct FaceRig {
  std::string name;
  Mesh neutral;
  std::vector<std::string> blendshape_names;
  std::vector<Eigen::Matrix3Xd> blendshape_deltas_mm;  // one 3 x V per name
  Mesh skull;
  std::vector<SkullLandmark> skull_landmarks;
  std::vector<SurfacePoint> skin_samples;
  std::vector<Marker> markers;
  std::map<std::string, std::vector<int>> regions;  // vertex indices into neutral
  std::vector<std::string> stable_regions;
  JawModel jaw;

  int vertex_count() const { return neutral.vertex_count(); }
  // Index of a blendshape, or -1.
  int BlendshapeIndex(const std::string& name) const;
  // neutral + sum_k weights[k] * delta_k (3 x V). Precondition: weights.size() == #blendshapes.
  Eigen::Matrix3Xd Evaluate(const Eigen::VectorXd& weights) const;
  // Positions of the skin samples on a skin surface (3 x #samples).
  Eigen::Matrix3Xd SamplePositions(const Eigen::Matrix3Xd& skin_positions) const;

  // Indices in range, weights barycentric, counts consistent, names unique, regions known.
  Status Validate() const;
};

StatusOr<FaceRig> LoadFaceRig(const std::string& dir);
Status SaveFaceRig(const FaceRig& rig, const std::string& dir);

// A sparse marker layout on a rig (a head-mounted camera's markers, Masquerade's virtual
// markers): `spec` is a count N (the rig's first N markers; the procedural rig orders them by
// farthest-point sampling, so any prefix is spread over the face) or a file of marker names,
// one per line ('#' comments), or a FaceRig's markers.csv (the layout of a face it was saved
// with, e.g. a simulated head-mounted capture's ground_truth/face/markers.csv). `what` names the spec in errors (e.g. "--markers").
StatusOr<std::vector<Marker>> SelectMarkerLayout(const FaceRig& rig, const std::string& spec,
                                                 const std::string& what);

}  // namespace facedyn
