// Graph features of a marker region (FDLS section 4.3), the input of every region network.
//
// For the markers x_1..x_n of one region (skull frame, mm) and their neutral positions n_1..n_n:
//   pairwise distance  d_ij = |x_j - x_i|                         for i < j   (n(n-1)/2 values)
//   pairwise direction u_ij = (x_j - x_i) / |x_j - x_i|           for i < j   (3 per pair)
//   delta pose         p_i  = x_i - n_i                                       (3 per marker)
// concatenated in that order (distances, then directions, then deltas), pairs in the order
// (0,1), (0,2), ..., (0,n-1), (1,2), ... and xyz within a pair or marker. The paper's formula for
// the direction is lost in our copy of the text; the unit vector is used because, with the
// distance beside it, the pair's full difference is still recoverable while each feature stays
// in a bounded range. Distances and directions ignore a translation of the whole mask (a slipped
// head camera); the delta pose does not, which is why anchor alignment (section 4.4.2) exists.
#pragma once

#include <Eigen/Core>
#include <string>

#include "core/status.h"

namespace facedyn::solve {

struct FeatureSet {
  bool distance = true;
  bool direction = true;
  bool delta = true;
  // "distance", "direction", "delta" joined by '+' (the YAML spelling, e.g. "distance+delta").
  static StatusOr<FeatureSet> Parse(const std::string& text);
  std::string ToString() const;
};

// Number of features of `marker_count` markers.
int FeatureSize(int marker_count, const FeatureSet& set);

// Writes FeatureSize(n, set) floats to `out`. markers_in_skull and neutral_in_skull are 3 x n.
// Two coincident markers (distance 0) get direction 0 rather than NaN.
void ComputeGraphFeatures(const Eigen::Ref<const Eigen::Matrix3Xd>& markers_in_skull,
                          const Eigen::Ref<const Eigen::Matrix3Xd>& neutral_in_skull,
                          const FeatureSet& set, float* out);

}  // namespace facedyn::solve
