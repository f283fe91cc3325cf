#include "capture/frame.h"

namespace facedyn::capture {

int BytesPerPixel(PixelFormat format) {
  switch (format) {
    case PixelFormat::kMono8:
      return 1;
    case PixelFormat::kMono16:
      return 2;
    case PixelFormat::kBgr8:
      return 3;
  }
  return 0;
}

const char* PixelFormatName(PixelFormat format) {
  switch (format) {
    case PixelFormat::kMono8:
      return "mono8";
    case PixelFormat::kMono16:
      return "mono16";
    case PixelFormat::kBgr8:
      return "bgr8";
  }
  return "unknown";
}

StatusOr<PixelFormat> ParsePixelFormat(const std::string& name) {
  if (name == "mono8") return PixelFormat::kMono8;
  if (name == "mono16") return PixelFormat::kMono16;
  if (name == "bgr8") return PixelFormat::kBgr8;
  return InvalidArgumentError("pixel format '" + name + "' is not one of mono8, mono16, bgr8");
}

std::vector<uint8_t> BufferPool::Acquire(size_t bytes) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!free_.empty()) {
      std::vector<uint8_t> buffer = std::move(free_.back());
      free_.pop_back();
      buffer.resize(bytes);  // no reallocation when the capacity suffices
      return buffer;
    }
  }
  return std::vector<uint8_t>(bytes);
}

void BufferPool::Release(std::vector<uint8_t>&& buffer) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (free_.size() < max_free_ && buffer.capacity() > 0) free_.push_back(std::move(buffer));
}

}  // namespace facedyn::capture
