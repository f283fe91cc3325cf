#include "core/pc2.h"

#include <cmath>
#include <cstdint>
#include <cstring>

#include <fmt/format.h>

#include "core/file_util.h"

namespace facedyn {
namespace {

static_assert(sizeof(float) == 4, "PC2 stores float32");
// facedyn targets little-endian hosts (x86-64, aarch64), where PC2's byte order is native.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "PC2 I/O assumes a little-endian host");

template <typename T>
T ReadScalar(const std::string& bytes, size_t offset) {
  T value;
  std::memcpy(&value, bytes.data() + offset, sizeof(T));
  return value;
}

template <typename T>
void AppendScalar(std::string* bytes, T value) {
  bytes->append(reinterpret_cast<const char*>(&value), sizeof(T));
}

}  // namespace

StatusOr<PointCache> ReadPc2(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(const std::string bytes, ReadFileToString(path));
  if (bytes.size() < static_cast<size_t>(kPc2HeaderBytes)) {
    return DataLossError(fmt::format("{}: truncated PC2 header ({} bytes, need {})", path,
                                     bytes.size(), kPc2HeaderBytes));
  }
  if (std::memcmp(bytes.data(), kPc2Magic, sizeof(kPc2Magic)) != 0) {
    return DataLossError(path + ": not a PC2 file (missing \"POINTCACHE2\" signature)");
  }
  const int32_t version = ReadScalar<int32_t>(bytes, 12);
  const int32_t vertex_count = ReadScalar<int32_t>(bytes, 16);
  const float start_frame = ReadScalar<float>(bytes, 20);
  const float sampling = ReadScalar<float>(bytes, 24);
  const int32_t frame_count = ReadScalar<int32_t>(bytes, 28);
  if (version != 1) return DataLossError(fmt::format("{}: unsupported PC2 version {} (expected 1)", path, version));
  if (vertex_count < 0) return DataLossError(fmt::format("{}: negative vertex count {}", path, vertex_count));
  if (frame_count < 0) return DataLossError(fmt::format("{}: negative frame count {}", path, frame_count));
  if (!std::isfinite(start_frame) || !std::isfinite(sampling) || sampling <= 0) {
    return DataLossError(fmt::format("{}: bad start frame {} or sampling {}", path, start_frame, sampling));
  }
  // Zero points make every frame zero bytes long, so a 32-byte file could claim 2^31 - 1 frames
  // and pass the size check: a cache of two billion empty frames that every reader then loops
  // over (a fuzz/pc2 run hung on it for minutes).
  if (vertex_count == 0 && frame_count > 0) {
    return DataLossError(fmt::format("{}: header declares {} frames of 0 vertices", path,
                                     frame_count));
  }
  const uint64_t frame_bytes = uint64_t(vertex_count) * 3 * sizeof(float);  // < 2^35
  // frame_bytes * frame_count can pass 2^64 for a hostile header (and wrap to the file's size):
  // compare by division against the bytes that are there before multiplying.
  const uint64_t payload = bytes.size() - kPc2HeaderBytes;
  if (frame_bytes > 0 && uint64_t(frame_count) > payload / frame_bytes) {
    return DataLossError(fmt::format(
        "{}: truncated: header declares {} frames of {} vertices but the file has {} bytes; "
        "frame {} is incomplete",
        path, frame_count, vertex_count, bytes.size(), payload / frame_bytes));
  }
  const uint64_t expected = kPc2HeaderBytes + frame_bytes * uint64_t(frame_count);
  if (bytes.size() != expected) {
    if (bytes.size() < expected && frame_bytes > 0) {
      const uint64_t complete = (bytes.size() - kPc2HeaderBytes) / frame_bytes;
      return DataLossError(fmt::format(
          "{}: truncated: header declares {} frames of {} vertices ({} bytes) but the file has {} "
          "bytes; frame {} is incomplete",
          path, frame_count, vertex_count, expected, bytes.size(), complete));
    }
    return DataLossError(fmt::format("{}: size mismatch: header declares {} frames of {} vertices "
                                     "({} bytes) but the file has {} bytes",
                                     path, frame_count, vertex_count, expected, bytes.size()));
  }
  PointCache cache;
  cache.vertex_count = vertex_count;
  cache.start_frame = start_frame;
  cache.sampling = sampling;
  cache.positions.resize(3 * Eigen::Index(vertex_count), frame_count);
  if (expected > uint64_t(kPc2HeaderBytes)) {
    std::memcpy(cache.positions.data(), bytes.data() + kPc2HeaderBytes, expected - kPc2HeaderBytes);
  }
  for (int f = 0; f < frame_count; ++f) {
    if (cache.positions.col(f).allFinite()) continue;
    for (int v = 0; v < vertex_count; ++v) {
      if (!cache.Frame(f).col(v).allFinite()) {
        return DataLossError(fmt::format("{}: frame {} vertex {} has a non-finite coordinate", path, f, v));
      }
    }
  }
  return cache;
}

Status WritePc2(const std::string& path, const PointCache& cache) {
  FACEDYN_CHECK(cache.positions.rows() == 3 * Eigen::Index(cache.vertex_count),
                "PointCache rows must be 3 * vertex_count");
  std::string bytes;
  bytes.reserve(kPc2HeaderBytes + cache.positions.size() * sizeof(float));
  bytes.append(kPc2Magic, sizeof(kPc2Magic));
  AppendScalar<int32_t>(&bytes, 1);
  AppendScalar<int32_t>(&bytes, cache.vertex_count);
  AppendScalar<float>(&bytes, cache.start_frame);
  AppendScalar<float>(&bytes, cache.sampling);
  AppendScalar<int32_t>(&bytes, cache.frame_count());
  bytes.append(reinterpret_cast<const char*>(cache.positions.data()),
               cache.positions.size() * sizeof(float));
  return WriteFileAtomic(path, bytes);
}

}  // namespace facedyn
