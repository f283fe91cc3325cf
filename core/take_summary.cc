#include "core/take_summary.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace facedyn {

TakeSummary SummarizeTake(const Take& take) {
  TakeSummary s;
  s.frame_count = take.frame_count();
  s.fps = take.info.fps;
  s.vertex_count = take.vertex_count();
  s.face_count = take.topology.face_count();
  s.duration_s = take.duration_s();
  for (const auto& [name, cache] : take.channels) s.channels.push_back(name);
  s.has_jaw = !take.skull_from_jaw.empty();
  if (take.world_from_skull.empty()) return s;
  const Rigid3 skull0_from_world = take.world_from_skull.front().Inverse();
  const Eigen::Vector3d t0 = take.world_from_skull.front().translation();
  s.skull.translation_min_mm = s.skull.translation_max_mm = t0;
  for (const Rigid3& world_from_skull : take.world_from_skull) {
    const Eigen::Vector3d& t = world_from_skull.translation();
    s.skull.translation_min_mm = s.skull.translation_min_mm.cwiseMin(t);
    s.skull.translation_max_mm = s.skull.translation_max_mm.cwiseMax(t);
    s.skull.max_displacement_mm = std::max(s.skull.max_displacement_mm, (t - t0).norm());
    const double angle = (skull0_from_world * world_from_skull).AngleRad();
    s.skull.max_rotation_deg = std::max(s.skull.max_rotation_deg, angle * 180.0 / M_PI);
  }
  return s;
}

Json TakeSummaryToJson(const Take& take, const TakeSummary& s) {
  auto vec = [](const Eigen::Vector3d& v) { return Json::array({v.x(), v.y(), v.z()}); };
  Json json;
  json["frames"] = s.frame_count;
  json["fps"] = s.fps;
  json["vertices"] = s.vertex_count;
  json["faces"] = s.face_count;
  json["duration_s"] = s.duration_s;
  json["channels"] = s.channels;
  json["has_jaw"] = s.has_jaw;
  json["subject"] = take.info.subject;
  json["expression"] = take.info.expression;
  json["motion"] = take.info.motion;
  json["platform_hz"] = take.info.platform_hz ? Json(*take.info.platform_hz) : Json(nullptr);
  json["source"] = take.info.source;
  json["skull_motion"] = {
      {"translation_min_mm", vec(s.skull.translation_min_mm)},
      {"translation_max_mm", vec(s.skull.translation_max_mm)},
      {"translation_range_mm", vec(s.skull.translation_max_mm - s.skull.translation_min_mm)},
      {"max_displacement_mm", s.skull.max_displacement_mm},
      {"max_rotation_deg", s.skull.max_rotation_deg}};
  return json;
}

std::string TakeSummaryToText(const Take& take, const TakeSummary& s) {
  const Eigen::Vector3d range = s.skull.translation_max_mm - s.skull.translation_min_mm;
  std::string channels;
  for (const auto& c : s.channels) channels += (channels.empty() ? "" : ", ") + c;
  std::string text;
  text += fmt::format("frames        {} at {:g} fps ({:.3f} s)\n", s.frame_count, s.fps, s.duration_s);
  text += fmt::format("vertices      {} ({} faces)\n", s.vertex_count, s.face_count);
  text += fmt::format("channels      {}\n", channels.empty() ? "(none)" : channels);
  text += fmt::format("jaw           {}\n", s.has_jaw ? "yes" : "no");
  if (!take.info.subject.empty()) text += fmt::format("subject       {}\n", take.info.subject);
  if (!take.info.expression.empty()) text += fmt::format("expression    {}\n", take.info.expression);
  if (!take.info.motion.empty()) text += fmt::format("motion        {}\n", take.info.motion);
  if (take.info.platform_hz) text += fmt::format("platform      {:g} Hz\n", *take.info.platform_hz);
  if (!take.info.source.empty()) text += fmt::format("source        {}\n", take.info.source);
  text += fmt::format("skull motion  translation range x {:.3f} y {:.3f} z {:.3f} mm, max displacement {:.3f} mm\n",
                      range.x(), range.y(), range.z(), s.skull.max_displacement_mm);
  text += fmt::format("              max rotation {:.3f} deg (relative to frame 0)\n", s.skull.max_rotation_deg);
  return text;
}

}  // namespace facedyn
