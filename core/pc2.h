// PC2 point caches (Blender's Mesh Cache modifier format), the per-frame vertex store of a Take.
//
// Layout (little-endian): char[12] "POINTCACHE2\0", int32 version = 1, int32 point count,
// float32 start frame, float32 sampling (frames per sample), int32 sample count, then
// float32 x y z for every point of every sample, sample-major. In memory a cache is one
// contiguous 3V x F float matrix whose column f is frame f's xyz, i.e. exactly the file's
// payload, so reading and writing are single block copies and a frame is an Eigen::Map.
#pragma once

#include <string>

#include <Eigen/Core>

#include "core/status.h"

namespace facedyn {

inline constexpr char kPc2Magic[12] = {'P', 'O', 'I', 'N', 'T', 'C', 'A', 'C', 'H', 'E', '2', '\0'};
inline constexpr int kPc2HeaderBytes = 32;

struct PointCache {
  int vertex_count = 0;
  float start_frame = 0.0f;
  float sampling = 1.0f;
  Eigen::MatrixXf positions;  // 3 * vertex_count x frame_count

  int frame_count() const { return static_cast<int>(positions.cols()); }
  Eigen::Map<const Eigen::Matrix3Xf> Frame(int f) const {
    return Eigen::Map<const Eigen::Matrix3Xf>(positions.col(f).data(), 3, vertex_count);
  }
  Eigen::Map<Eigen::Matrix3Xf> Frame(int f) {
    return Eigen::Map<Eigen::Matrix3Xf>(positions.col(f).data(), 3, vertex_count);
  }
};

// Reads and validates a PC2: magic, version, sizes against the file length, finite values.
// Errors name the file and, for bad values, the frame and vertex.
StatusOr<PointCache> ReadPc2(const std::string& path);

// Writes atomically (temporary file + rename). Precondition: positions has 3*vertex_count rows.
Status WritePc2(const std::string& path, const PointCache& cache);

}  // namespace facedyn
