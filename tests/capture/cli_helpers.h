// Helpers shared by the capture CLI tests.
#pragma once

#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/test_support.h"

namespace facedyn::capture {

using nlohmann::json;

inline const std::string kSource = FACEDYN_SOURCE_DIR;

// A 3-camera simulated capture config in `dir` (lead-in kept at its minimum for speed).
inline std::string Sim3Config(const std::string& dir, const std::string& extra_sim = "",
                              const std::string& top = "", double duration_s = 0.25,
                              int width = 320, int height = 256) {
  const std::string path = dir + "/capture.yaml";
  std::ofstream out(path);
  out << "name: test\nfps: 128\nduration_s: " << duration_s << "\nexposure_us: 2000\n"
      << "recorder: {queue_frames: 8, backpressure: block}\n"
      << "cameras:\n  backend: sim\n  ring: {count: 3, width_px: " << width
      << ", height_px: " << height << ", focal_px: " << 900.0 * width / 320
      << ", distance_mm: 800, span_deg: 90}\n"
      << top
      << "sim:\n  face: procedural\n  expression: neutral\n  platform_hz: 8\n  lead_in_s: 0.3\n"
      << extra_sim;
  return path;
}

inline json ReadJson(const std::string& path) { return json::parse(testing::ReadBytes(path)); }

inline std::string Facedyn() { return testing::FacedynExecutable(); }

}  // namespace facedyn::capture
