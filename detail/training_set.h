// What both learned upsamplers (Masquerade, Bickel 2008) train from, and the analysis they
// share: high-resolution frames of one actor in fixed topology (the rig captures), the HMC
// marker layout attached to that mesh, and per frame the large-scale skin the markers alone
// give plus the fine detail left over, as local offsets in the large-scale surface's frames.
//
// Frames are in the skull frame (mm): HMC markers are triangulated in the helmet's frame, which
// moves with the skull, and the rig captures are stabilised to it.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/mesh.h"
#include "core/status.h"
#include "detail/large_scale.h"

namespace facedyn::detail {

struct DetailTrainingSet {
  std::string subject;                      // the rig's name, carried into the model file
  Mesh neutral;                             // neutral skin (skull frame, mm)
  std::vector<Marker> markers;              // HMC marker layout on `neutral`
  std::vector<Eigen::Matrix3Xd> frames_mm;  // high-resolution skin per frame (3 x V)

  // Counts agree, marker vertices in range, marker names unique and non-empty, frames finite.
  // Messages name the frame or marker.
  Status Validate() const;
  std::vector<SurfacePoint> MarkerPoints() const;
  // Marker positions (3 x M) on a high-resolution frame: the virtual HMC markers.
  Eigen::Matrix3Xd MarkersOn(const Eigen::Matrix3Xd& skin_mm) const;
};

// Per training frame: large-scale skin from the frame's own markers, tangent frames of it, and
// the local offsets of the true skin from it (the fine detail to learn).
struct LargeScaleFrames {
  std::vector<Eigen::Matrix3Xd> large_mm;
  std::vector<Eigen::Matrix3Xd> local_offsets_mm;
};
LargeScaleFrames AnalyseFrames(const DetailTrainingSet& set, const LaplacianDeformer& deformer,
                               const TangentFrames& tangent);

// Marker names, one per marker, for compatibility checks.
std::vector<std::string> MarkerNames(const std::vector<Marker>& markers);

}  // namespace facedyn::detail
