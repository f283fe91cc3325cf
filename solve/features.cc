#include "solve/features.h"

#include <sstream>

namespace facedyn::solve {

StatusOr<FeatureSet> FeatureSet::Parse(const std::string& text) {
  FeatureSet set{false, false, false};
  std::stringstream stream(text);
  std::string part;
  while (std::getline(stream, part, '+')) {
    if (part == "distance") {
      set.distance = true;
    } else if (part == "direction") {
      set.direction = true;
    } else if (part == "delta") {
      set.delta = true;
    } else {
      return InvalidArgumentError("features '" + text + "': '" + part +
                                  "' is not one of distance, direction, delta");
    }
  }
  if (!set.distance && !set.direction && !set.delta) {
    return InvalidArgumentError("features '" + text + "': names no feature");
  }
  return set;
}

std::string FeatureSet::ToString() const {
  std::string text;
  if (distance) text += "distance";
  if (direction) text += std::string(text.empty() ? "" : "+") + "direction";
  if (delta) text += std::string(text.empty() ? "" : "+") + "delta";
  return text;
}

int FeatureSize(int marker_count, const FeatureSet& set) {
  const int pairs = marker_count * (marker_count - 1) / 2;
  return (set.distance ? pairs : 0) + (set.direction ? 3 * pairs : 0) +
         (set.delta ? 3 * marker_count : 0);
}

void ComputeGraphFeatures(const Eigen::Ref<const Eigen::Matrix3Xd>& markers_in_skull,
                          const Eigen::Ref<const Eigen::Matrix3Xd>& neutral_in_skull,
                          const FeatureSet& set, float* out) {
  const int n = static_cast<int>(markers_in_skull.cols());
  const int pairs = n * (n - 1) / 2;
  float* distance = out;
  float* direction = out + (set.distance ? pairs : 0);
  float* delta = direction + (set.direction ? 3 * pairs : 0);
  if (set.distance || set.direction) {
    int k = 0;
    for (int i = 0; i < n; ++i) {
      for (int j = i + 1; j < n; ++j, ++k) {
        const Eigen::Vector3d d = markers_in_skull.col(j) - markers_in_skull.col(i);
        const double length = d.norm();
        if (set.distance) distance[k] = static_cast<float>(length);
        if (set.direction) {
          const Eigen::Vector3d u =
              length > 0.0 ? Eigen::Vector3d(d / length) : Eigen::Vector3d::Zero();
          direction[3 * k + 0] = static_cast<float>(u.x());
          direction[3 * k + 1] = static_cast<float>(u.y());
          direction[3 * k + 2] = static_cast<float>(u.z());
        }
      }
    }
  }
  if (set.delta) {
    for (int i = 0; i < n; ++i) {
      for (int a = 0; a < 3; ++a) {
        delta[3 * i + a] = static_cast<float>(markers_in_skull(a, i) - neutral_in_skull(a, i));
      }
    }
  }
}

}  // namespace facedyn::solve
