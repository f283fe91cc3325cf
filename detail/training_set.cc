#include "detail/training_set.h"

#include <fmt/format.h>

#include <set>

namespace facedyn::detail {

Status DetailTrainingSet::Validate() const {
  FACEDYN_RETURN_IF_ERROR(neutral.Validate("detail training neutral"));
  const int v_count = neutral.vertex_count();
  if (markers.empty()) return InvalidArgumentError("detail training set: no markers");
  std::set<std::string> names;
  for (size_t m = 0; m < markers.size(); ++m) {
    const Marker& marker = markers[m];
    if (marker.name.empty())
      return InvalidArgumentError(fmt::format("detail training set: marker {} has no name", m));
    if (!names.insert(marker.name).second) {
      return InvalidArgumentError(
          fmt::format("detail training set: marker name '{}' appears twice", marker.name));
    }
    for (int k = 0; k < 3; ++k) {
      if (marker.point.vertices[k] < 0 || marker.point.vertices[k] >= v_count) {
        return InvalidArgumentError(
            fmt::format("detail training set: marker '{}' refers to vertex {}, the mesh has {}",
                        marker.name, marker.point.vertices[k], v_count));
      }
    }
  }
  if (frames_mm.empty()) return InvalidArgumentError("detail training set: no frames");
  for (size_t f = 0; f < frames_mm.size(); ++f) {
    if (frames_mm[f].cols() != v_count) {
      return FailedPreconditionError(
          fmt::format("detail training set: frame {} has {} vertices, the neutral has {}", f,
                      frames_mm[f].cols(), v_count));
    }
    if (!frames_mm[f].allFinite()) {
      return InvalidArgumentError(
          fmt::format("detail training set: frame {} has a non-finite position", f));
    }
  }
  return Status::Ok();
}

std::vector<SurfacePoint> DetailTrainingSet::MarkerPoints() const {
  std::vector<SurfacePoint> points;
  for (const Marker& m : markers) points.push_back(m.point);
  return points;
}

Eigen::Matrix3Xd DetailTrainingSet::MarkersOn(const Eigen::Matrix3Xd& skin_mm) const {
  Eigen::Matrix3Xd p(3, static_cast<int>(markers.size()));
  for (size_t m = 0; m < markers.size(); ++m)
    p.col(static_cast<int>(m)) = markers[m].point.Evaluate(skin_mm);
  return p;
}

LargeScaleFrames AnalyseFrames(const DetailTrainingSet& set, const LaplacianDeformer& deformer,
                               const TangentFrames& tangent) {
  LargeScaleFrames out;
  Eigen::Matrix<double, 9, Eigen::Dynamic> frames;
  for (const Eigen::Matrix3Xd& skin : set.frames_mm) {
    Eigen::Matrix3Xd large, local;
    deformer.Deform(set.MarkersOn(skin), &large);
    tangent.Compute(large, &frames);
    TangentFrames::ToLocal(frames, large, skin, &local);
    out.large_mm.push_back(std::move(large));
    out.local_offsets_mm.push_back(std::move(local));
  }
  return out;
}

std::vector<std::string> MarkerNames(const std::vector<Marker>& markers) {
  std::vector<std::string> names;
  for (const Marker& m : markers) names.push_back(m.name);
  return names;
}

}  // namespace facedyn::detail
