// What `facedyn take info` reports about a Take: counts, duration and the range of the
// skull's rigid motion.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/json_io.h"
#include "core/take.h"

namespace facedyn {

struct SkullMotionRange {
  Eigen::Vector3d translation_min_mm = Eigen::Vector3d::Zero();  // world frame, per axis
  Eigen::Vector3d translation_max_mm = Eigen::Vector3d::Zero();
  double max_displacement_mm = 0.0;  // largest |t(f) - t(0)|
  double max_rotation_deg = 0.0;     // largest rotation angle of skull(0)^-1 * skull(f)
};

struct TakeSummary {
  int frame_count = 0;
  double fps = 0.0;
  int vertex_count = 0;
  int face_count = 0;
  double duration_s = 0.0;
  std::vector<std::string> channels;
  bool has_jaw = false;
  SkullMotionRange skull;
};

// Ranges are taken relative to the first frame, so a take that starts at any pose reports
// how far the head moved during the take. An empty take has zero ranges.
TakeSummary SummarizeTake(const Take& take);
Json TakeSummaryToJson(const Take& take, const TakeSummary& summary);
std::string TakeSummaryToText(const Take& take, const TakeSummary& summary);

}  // namespace facedyn
