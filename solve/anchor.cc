#include "solve/anchor.h"

#include <fmt/format.h>

namespace facedyn::solve {

StatusOr<Eigen::VectorXd> AnchorOffsets(const Puppet& puppet, const Eigen::MatrixXd& markers,
                                        int anchor_frame, const Eigen::VectorXd& anchor_weights) {
  if (markers.rows() != 3 * puppet.marker_count()) {
    return InvalidArgumentError(fmt::format("anchor: {} marker rows for {} markers", markers.rows(),
                                            puppet.marker_count()));
  }
  if (anchor_frame < 0 || anchor_frame >= markers.cols()) {
    return InvalidArgumentError(
        fmt::format("anchor: frame {} is outside 0..{}", anchor_frame, markers.cols() - 1));
  }
  if (anchor_weights.size() != puppet.channel_count()) {
    return InvalidArgumentError(fmt::format("anchor: {} weights for {} channels",
                                            anchor_weights.size(), puppet.channel_count()));
  }
  return Eigen::VectorXd(markers.col(anchor_frame) - puppet.StackedMarkers(anchor_weights));
}

StatusOr<Eigen::MatrixXd> AlignToAnchor(const Eigen::MatrixXd& markers,
                                        const Eigen::VectorXd& offsets,
                                        const Eigen::VectorXd& alpha) {
  if (offsets.size() != markers.rows()) {
    return InvalidArgumentError(
        fmt::format("anchor: {} offsets for {} marker rows", offsets.size(), markers.rows()));
  }
  if (alpha.size() != 0 && alpha.size() != markers.cols()) {
    return InvalidArgumentError(
        fmt::format("anchor: {} alphas for {} frames", alpha.size(), markers.cols()));
  }
  Eigen::MatrixXd aligned = markers;
  for (Eigen::Index f = 0; f < markers.cols(); ++f) {
    aligned.col(f) -= (alpha.size() == 0 ? 1.0 : alpha[f]) * offsets;
  }
  return aligned;
}

}  // namespace facedyn::solve
