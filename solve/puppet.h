// The FDLS puppet (Weta's FDLS, section 4.1 and supplementary section 7): a FaceRig's named
// blendshapes, jaw included, seen only through its painted markers.
//
// A FaceRig models the jaw as a blendshape channel ("jaw_open" on the procedural face, the ARKit
// jaw shapes on ICT-FaceKit) whose delta is the mandible's rotation at weight 1, so the puppet is
// one linear map from weights to markers (Eq. 1 of FDLS restricted to the marker points):
//
//   x(w) = x_0 + B w,   x stacked as [x_1 y_1 z_1 x_2 ...] (3M), B = 3M x C, in mm, skull frame.
//
// Why markers only: solving and training never need the dense mesh; evaluating B w for M = 150
// markers and C <= 60 channels is ~30k multiply-adds a frame, which keeps training-data
// generation and the fine-tuning residual cheap. Which channels form the jaw is a region table
// matter (solve/solve_config.h), not the puppet's.
#pragma once

#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "core/face_rig.h"
#include "core/status.h"

namespace facedyn::solve {

struct Puppet {
  std::string rig_name;
  std::vector<std::string> channel_names;     // the rig's blendshape names, in its order
  std::vector<std::string> marker_names;      // the rig's painted markers, in its order
  std::vector<int> marker_vertices;           // the rig vertex each marker is closest to
  Eigen::Matrix3Xd neutral_markers_in_skull;  // 3 x M, mm (FDLS's "neutral markers")
  Eigen::MatrixXd marker_basis_mm;            // 3M x C: column c = marker deltas of channel c
  Eigen::VectorXd lower_bounds;               // C, weight bounds (0 for a rig's shapes)
  Eigen::VectorXd upper_bounds;               // C (1)
  // Left/right channel pairs found by name (suffixes _L/_R, Left/Right; not ARKit's sideways
  // jawLeft/jawRight and mouthLeft/mouthRight), for the symmetric and asymmetric training poses
  // (FDLS 4.1). Empty for the procedural face (no split channels).
  std::vector<std::pair<int, int>> symmetric_pairs;

  int channel_count() const { return static_cast<int>(channel_names.size()); }
  int marker_count() const { return static_cast<int>(marker_names.size()); }
  int ChannelIndex(const std::string& name) const;  // -1 when unknown
  int MarkerIndex(const std::string& name) const;   // -1 when unknown

  // x_0 + B w as a stacked 3M vector (mm, skull frame). Precondition: weights.size() == C.
  Eigen::VectorXd StackedMarkers(const Eigen::VectorXd& weights) const;
  // The same as 3 x M.
  Eigen::Matrix3Xd Markers(const Eigen::VectorXd& weights) const;
  // Stacked neutral markers (3M).
  Eigen::VectorXd StackedNeutral() const;
};

// The puppet of a rig: neutral markers at the markers' surface points, B from the blendshape
// deltas at the same points. Errors: the rig does not validate, has no markers or no
// blendshapes.
StatusOr<Puppet> MakePuppet(const FaceRig& rig);

}  // namespace facedyn::solve
