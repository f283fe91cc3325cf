// Frame: one image from one camera, stamped with the trigger that exposed it.
//
// Every frame carries its trigger index (the count of trigger pulses since the take armed,
// from 0), its timestamp in nanoseconds on the session clock (the start of exposure), and its
// exposure. Pixels are row-major and tightly packed. Buffers are recycled through a
// BufferPool so acquisition does not allocate per frame once the pool is warm.
#pragma once

#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

#include "core/status.h"

namespace facedyn::capture {

enum class PixelFormat : uint32_t { kMono8 = 1, kMono16 = 2, kBgr8 = 3 };

// Limits a frame read from outside (a frame file, a camera) must respect; anything beyond is
// corrupt or hostile, never a real frame. The largest machine-vision sensors are about
// 14,000 x 10,600 px (151 MP, 453 MB in bgr8), so 65,536 px a side and 1 GiB a frame leave
// room while keeping width x height x bytes far from wrapping 64 bits and every allocation
// one a workstation can make.
inline constexpr int64_t kMaxFrameSidePx = 65536;
inline constexpr uint64_t kMaxFrameBytes = uint64_t{1} << 30;
// Trigger indices count pulses from 0 and a take is at most 3600 s at 1000 fps
// (CaptureConfig::Check), so no index of a real take reaches this. Readers that size arrays by
// the largest index seen (reconstruct/session_input.cc) rely on it.
inline constexpr int64_t kMaxTriggersPerTake = int64_t{1000} * 3600;

int BytesPerPixel(PixelFormat format);
const char* PixelFormatName(PixelFormat format);  // "mono8", "mono16", "bgr8"
StatusOr<PixelFormat> ParsePixelFormat(const std::string& name);

struct Frame {
  int camera_index = 0;
  int64_t trigger_index = -1;
  int64_t timestamp_ns = 0;  // session clock, start of exposure
  int32_t exposure_us = 0;
  int width_px = 0;
  int height_px = 0;
  PixelFormat format = PixelFormat::kMono8;
  std::vector<uint8_t> pixels;

  size_t ExpectedBytes() const {
    return static_cast<size_t>(width_px) * height_px * BytesPerPixel(format);
  }
};

// A free list of pixel buffers. Acquire() returns a buffer of exactly `bytes` (reusing a
// released one when possible); Release() gives it back. Thread-safe.
class BufferPool {
 public:
  explicit BufferPool(size_t max_free = 64) : max_free_(max_free) {}
  std::vector<uint8_t> Acquire(size_t bytes);
  void Release(std::vector<uint8_t>&& buffer);

 private:
  std::mutex mutex_;
  std::vector<std::vector<uint8_t>> free_;
  size_t max_free_;
};

}  // namespace facedyn::capture
