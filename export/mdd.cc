#include "export/mdd.h"

#include <cmath>
#include <cstdint>
#include <cstring>

#include <fmt/format.h>

#include "core/file_util.h"

namespace facedyn {
namespace {

static_assert(sizeof(float) == 4 && sizeof(uint32_t) == 4, "MDD stores 32-bit fields");

uint32_t LoadBigEndian32(const char* p) {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  return (uint32_t(b[0]) << 24) | (uint32_t(b[1]) << 16) | (uint32_t(b[2]) << 8) | uint32_t(b[3]);
}
void StoreBigEndian32(uint32_t v, char* p) {
  p[0] = static_cast<char>(v >> 24);
  p[1] = static_cast<char>(v >> 16);
  p[2] = static_cast<char>(v >> 8);
  p[3] = static_cast<char>(v);
}
float LoadFloat(const char* p) {
  const uint32_t bits = LoadBigEndian32(p);
  float value;
  std::memcpy(&value, &bits, sizeof(value));
  return value;
}
void StoreFloat(float value, char* p) {
  uint32_t bits;
  std::memcpy(&bits, &value, sizeof(bits));
  StoreBigEndian32(bits, p);
}

}  // namespace

StatusOr<MddCache> ReadMdd(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(const std::string bytes, ReadFileToString(path));
  if (bytes.size() < static_cast<size_t>(kMddHeaderBytes)) {
    return DataLossError(fmt::format("{}: truncated MDD header ({} bytes, need {})", path,
                                     bytes.size(), kMddHeaderBytes));
  }
  const auto frame_count = static_cast<int32_t>(LoadBigEndian32(bytes.data()));
  const auto vertex_count = static_cast<int32_t>(LoadBigEndian32(bytes.data() + 4));
  if (frame_count < 0 || vertex_count < 0) {
    return DataLossError(fmt::format("{}: negative count in the MDD header ({} frames, {} points; "
                                     "is it little-endian, i.e. not an MDD?)",
                                     path, frame_count, vertex_count));
  }
  if (vertex_count == 0 && frame_count > 0) {
    return DataLossError(
        fmt::format("{}: header declares {} frames of 0 points", path, frame_count));
  }
  // Each frame costs 4 bytes of time plus 12 per point; compare by division before multiplying
  // so that a header of 2^31 - 1 frames and points cannot wrap.
  const uint64_t per_frame = 4 + uint64_t(vertex_count) * 12;  // < 2^35
  const uint64_t payload = bytes.size() - kMddHeaderBytes;
  if (uint64_t(frame_count) > payload / per_frame) {
    return DataLossError(fmt::format(
        "{}: truncated: header declares {} frames of {} points but the file has {} bytes", path,
        frame_count, vertex_count, bytes.size()));
  }
  const uint64_t expected = kMddHeaderBytes + per_frame * uint64_t(frame_count);
  if (bytes.size() != expected) {
    return DataLossError(fmt::format("{}: size mismatch: header declares {} frames of {} points "
                                     "({} bytes) but the file has {} bytes",
                                     path, frame_count, vertex_count, expected, bytes.size()));
  }
  MddCache cache;
  cache.points.vertex_count = vertex_count;
  cache.time_s.resize(frame_count);
  const char* times = bytes.data() + kMddHeaderBytes;
  for (int f = 0; f < frame_count; ++f) {
    cache.time_s[f] = LoadFloat(times + 4 * size_t(f));
    if (!std::isfinite(cache.time_s[f]) || (f > 0 && cache.time_s[f] < cache.time_s[f - 1])) {
      return DataLossError(fmt::format("{}: frame {} has time {} s (times must be finite and "
                                       "never decrease)",
                                       path, f, cache.time_s[f]));
    }
  }
  cache.points.positions.resize(3 * Eigen::Index(vertex_count), frame_count);
  const char* values = times + 4 * size_t(frame_count);
  for (int f = 0; f < frame_count; ++f) {
    float* column = cache.points.positions.col(f).data();
    for (Eigen::Index i = 0; i < 3 * Eigen::Index(vertex_count); ++i) {
      column[i] = LoadFloat(values);
      values += 4;
      if (!std::isfinite(column[i])) {
        return DataLossError(fmt::format("{}: frame {} point {} has a non-finite coordinate",
                                         path, f, i / 3));
      }
    }
  }
  return cache;
}

Status WriteMdd(const std::string& path, const PointCache& cache,
                const std::vector<double>& time_s) {
  const int frames = cache.frame_count();
  if (cache.positions.rows() != 3 * Eigen::Index(cache.vertex_count)) {
    return InvalidArgumentError(fmt::format("{}: the cache has {} rows for {} points", path,
                                            cache.positions.rows(), cache.vertex_count));
  }
  if (static_cast<int>(time_s.size()) != frames) {
    return InvalidArgumentError(
        fmt::format("{}: {} frame times for {} frames", path, time_s.size(), frames));
  }
  for (int f = 0; f < frames; ++f) {
    if (!std::isfinite(time_s[f]) || (f > 0 && time_s[f] < time_s[f - 1])) {
      return InvalidArgumentError(
          fmt::format("{}: frame {} time {} s is not finite and non-decreasing", path, f, time_s[f]));
    }
  }
  std::string bytes(kMddHeaderBytes + (4 + 12 * size_t(cache.vertex_count)) * size_t(frames), '\0');
  StoreBigEndian32(static_cast<uint32_t>(frames), bytes.data());
  StoreBigEndian32(static_cast<uint32_t>(cache.vertex_count), bytes.data() + 4);
  char* p = bytes.data() + kMddHeaderBytes;
  for (int f = 0; f < frames; ++f, p += 4) StoreFloat(static_cast<float>(time_s[f]), p);
  for (int f = 0; f < frames; ++f) {
    const float* column = cache.positions.col(f).data();
    for (Eigen::Index i = 0; i < cache.positions.rows(); ++i, p += 4) StoreFloat(column[i], p);
  }
  return WriteFileAtomic(path, bytes);
}

}  // namespace facedyn
