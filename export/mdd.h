// MDD point caches (LightWave's Motion Designer format; Blender's Mesh Cache modifier and 3ds
// Max's Point Cache read it beside PC2).
//
// Layout, every field big-endian (the format comes from LightWave on 68k/PowerPC Macs; Blender's
// reader byte-swaps on little-endian hosts, MOD_meshcache_mdd):
//   int32   frame count F
//   int32   point count V
//   float32 time of each frame in seconds, F values
//   float32 x y z for every point of every frame, frame-major (F * V * 3 values)
// so a file is 8 + 4F + 12VF bytes. Unlike PC2 there is no signature and no version, and each
// frame carries its own time: facedyn writes each frame's time from the take's first frame.
// Coordinates are written as the take holds them (mm, world frame), as for PC2.
#pragma once

#include <string>
#include <vector>

#include "core/pc2.h"
#include "core/status.h"

namespace facedyn {

inline constexpr int kMddHeaderBytes = 8;

struct MddCache {
  PointCache points;           // start_frame 0, sampling 1: MDD says time per frame instead
  std::vector<float> time_s;   // one per frame
};

// Reads and validates an MDD: sizes against the file length computed without overflow (a
// hostile header cannot make it allocate more than the file holds), finite values and times
// that never go backwards. Errors name the file and, for bad values, the frame and point.
StatusOr<MddCache> ReadMdd(const std::string& path);

// Writes atomically. Preconditions: cache.positions has 3*vertex_count rows; time_s has one
// finite value per frame, non-decreasing.
Status WriteMdd(const std::string& path, const PointCache& cache, const std::vector<double>& time_s);

}  // namespace facedyn
