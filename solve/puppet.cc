#include "solve/puppet.h"

#include <fmt/format.h>

#include "core/check.h"

namespace facedyn::solve {
namespace {

// The partner of a split channel name ("mouthSmile_L" <-> "mouthSmile_R", "eyeBlinkLeft" <->
// "eyeBlinkRight"), or "" when the name carries no side.
std::string MirrorName(const std::string& name) {
  const std::pair<const char*, const char*> kSides[] = {
      {"_L", "_R"}, {"_R", "_L"}, {"Left", "Right"}, {"Right", "Left"}};
  for (const auto& [side, other] : kSides) {
    const std::string suffix(side);
    if (name.size() > suffix.size() &&
        name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0) {
      const std::string stem = name.substr(0, name.size() - suffix.size());
      // ARKit's jawLeft/jawRight and mouthLeft/mouthRight move the whole jaw or mouth sideways:
      // opposite directions of one motion, not one shape split in halves, so never posed together.
      if (stem == "jaw" || stem == "mouth") return "";
      return stem + other;
    }
  }
  return "";
}

}  // namespace

int Puppet::ChannelIndex(const std::string& name) const {
  for (size_t i = 0; i < channel_names.size(); ++i) {
    if (channel_names[i] == name) return static_cast<int>(i);
  }
  return -1;
}

int Puppet::MarkerIndex(const std::string& name) const {
  for (size_t i = 0; i < marker_names.size(); ++i) {
    if (marker_names[i] == name) return static_cast<int>(i);
  }
  return -1;
}

Eigen::VectorXd Puppet::StackedNeutral() const {
  return Eigen::Map<const Eigen::VectorXd>(neutral_markers_in_skull.data(),
                                           neutral_markers_in_skull.size());
}

Eigen::VectorXd Puppet::StackedMarkers(const Eigen::VectorXd& weights) const {
  FACEDYN_CHECK(weights.size() == channel_count(),
                "Puppet::StackedMarkers: one weight per channel");
  return StackedNeutral() + marker_basis_mm * weights;
}

Eigen::Matrix3Xd Puppet::Markers(const Eigen::VectorXd& weights) const {
  const Eigen::VectorXd stacked = StackedMarkers(weights);
  return Eigen::Map<const Eigen::Matrix3Xd>(stacked.data(), 3, marker_count());
}

StatusOr<Puppet> MakePuppet(const FaceRig& rig) {
  FACEDYN_RETURN_IF_ERROR(rig.Validate().WithContext("puppet of face rig '" + rig.name + "'"));
  if (rig.markers.empty()) {
    return FailedPreconditionError("puppet: face rig '" + rig.name + "' has no painted markers");
  }
  if (rig.blendshape_names.empty()) {
    return FailedPreconditionError("puppet: face rig '" + rig.name + "' has no blendshapes");
  }
  Puppet puppet;
  puppet.rig_name = rig.name;
  puppet.channel_names = rig.blendshape_names;
  const int m_count = static_cast<int>(rig.markers.size());
  const int c_count = static_cast<int>(rig.blendshape_names.size());
  puppet.neutral_markers_in_skull.resize(3, m_count);
  puppet.marker_basis_mm.resize(3 * m_count, c_count);
  for (int m = 0; m < m_count; ++m) {
    const Marker& marker = rig.markers[m];
    puppet.marker_names.push_back(marker.name);
    int heaviest = 0;
    marker.point.weights.maxCoeff(&heaviest);
    puppet.marker_vertices.push_back(marker.point.vertices[heaviest]);
    puppet.neutral_markers_in_skull.col(m) = marker.point.Evaluate(rig.neutral.positions_mm);
    for (int c = 0; c < c_count; ++c) {
      puppet.marker_basis_mm.block<3, 1>(3 * m, c) =
          marker.point.Evaluate(rig.blendshape_deltas_mm[c]);
    }
  }
  puppet.lower_bounds = Eigen::VectorXd::Zero(c_count);
  puppet.upper_bounds = Eigen::VectorXd::Ones(c_count);
  for (int c = 0; c < c_count; ++c) {
    const std::string mirror = MirrorName(puppet.channel_names[c]);
    const int other = mirror.empty() ? -1 : puppet.ChannelIndex(mirror);
    if (other > c) puppet.symmetric_pairs.emplace_back(c, other);
  }
  return puppet;
}

}  // namespace facedyn::solve
