#include "capture/frame_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace facedyn::capture {
namespace {

constexpr char kMagic[4] = {'F', 'D', 'F', 'R'};

uint64_t Fnv1a64(const uint8_t* data, size_t bytes) {
  uint64_t hash = 1469598103934665603ull;
  for (size_t i = 0; i < bytes; ++i) {
    hash ^= data[i];
    hash *= 1099511628211ull;
  }
  return hash;
}

template <typename T>
void Put(uint8_t* header, int offset, T value) {
  std::memcpy(header + offset, &value, sizeof(T));  // the supported platforms are little-endian
}
template <typename T>
T Get(const uint8_t* header, int offset) {
  T value;
  std::memcpy(&value, header + offset, sizeof(T));
  return value;
}

void EncodeHeader(const Frame& frame, uint8_t* header) {
  std::memset(header, 0, kFrameHeaderBytes);
  std::memcpy(header, kMagic, 4);
  Put<uint32_t>(header, 4, kFrameHeaderBytes);
  Put<int64_t>(header, 8, frame.trigger_index);
  Put<int64_t>(header, 16, frame.timestamp_ns);
  Put<int32_t>(header, 24, frame.exposure_us);
  Put<uint32_t>(header, 28, static_cast<uint32_t>(frame.width_px));
  Put<uint32_t>(header, 32, static_cast<uint32_t>(frame.height_px));
  Put<uint32_t>(header, 36, static_cast<uint32_t>(frame.format));
  Put<uint64_t>(header, 40, frame.pixels.size());
  Put<uint32_t>(header, 48, static_cast<uint32_t>(frame.camera_index));
  Put<uint64_t>(header, 56, Fnv1a64(header, 56));
}

// Empty string when the header is valid. Sizes are checked one field at a time against
// capture/frame.h's caps before they are multiplied: width and height are uint32 on disk, and
// 0xFFFFFFFF x 0xFFFFFFFF x 1 wraps 64 bits to 1, which once matched a 1-byte payload and gave
// a "valid" frame of -1 x -1 pixels.
std::string DecodeHeader(const uint8_t* header, int64_t offset, FrameRecord* record) {
  if (std::memcmp(header, kMagic, 4) != 0) return "bad record magic";
  if (Get<uint32_t>(header, 4) != kFrameHeaderBytes) return "bad header size";
  if (Get<uint64_t>(header, 56) != Fnv1a64(header, 56)) return "header checksum mismatch";
  const uint32_t width = Get<uint32_t>(header, 28);
  const uint32_t height = Get<uint32_t>(header, 32);
  if (width < 1 || width > kMaxFrameSidePx || height < 1 || height > kMaxFrameSidePx) {
    return "frame size " + std::to_string(width) + "x" + std::to_string(height) +
           " px is outside 1.." + std::to_string(kMaxFrameSidePx) + " a side";
  }
  const uint32_t format = Get<uint32_t>(header, 36);
  if (format < 1 || format > 3) return "unknown pixel format " + std::to_string(format);
  record->offset = offset;
  record->trigger_index = Get<int64_t>(header, 8);
  record->timestamp_ns = Get<int64_t>(header, 16);
  record->exposure_us = Get<int32_t>(header, 24);
  record->width_px = static_cast<int>(width);
  record->height_px = static_cast<int>(height);
  record->format = static_cast<PixelFormat>(format);
  record->payload_bytes = Get<uint64_t>(header, 40);
  record->camera_index = static_cast<int>(Get<uint32_t>(header, 48));
  // At most 2^16 * 2^16 * 3 < 2^34: cannot wrap.
  const uint64_t expected = uint64_t{width} * height * BytesPerPixel(record->format);
  if (expected > kMaxFrameBytes) {
    return "frame of " + std::to_string(width) + "x" + std::to_string(height) + " " +
           PixelFormatName(record->format) + " needs " + std::to_string(expected) +
           " bytes, more than the " + std::to_string(kMaxFrameBytes) + "-byte limit";
  }
  if (record->payload_bytes != expected)
    return "payload size " + std::to_string(record->payload_bytes) + " disagrees with " +
           std::to_string(width) + "x" + std::to_string(height) + " " +
           PixelFormatName(record->format) + " (" + std::to_string(expected) + " bytes)";
  return "";
}

}  // namespace

StatusOr<std::unique_ptr<FrameFileWriter>> FrameFileWriter::Create(const std::string& path) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) {
    return UnavailableError(path + ": cannot create frame file: " + std::strerror(errno));
  }
  return std::unique_ptr<FrameFileWriter>(new FrameFileWriter(path, fd));
}

FrameFileWriter::~FrameFileWriter() { (void)Close(false); }

Status FrameFileWriter::Append(const Frame& frame) {
  if (failed_ || fd_ < 0) return FailedPreconditionError(path_ + ": writer already stopped");
  FACEDYN_CHECK(frame.pixels.size() == frame.ExpectedBytes(), "frame pixel buffer size mismatch");
  uint8_t header[kFrameHeaderBytes];
  EncodeHeader(frame, header);
  iovec parts[2] = {{header, kFrameHeaderBytes},
                    {const_cast<uint8_t*>(frame.pixels.data()), frame.pixels.size()}};
  size_t total = kFrameHeaderBytes + frame.pixels.size();
  size_t done = 0;
  while (done < total) {
    iovec pending[2];
    int count = 0;
    size_t skip = done;
    for (const iovec& part : parts) {
      if (skip >= part.iov_len) {
        skip -= part.iov_len;
        continue;
      }
      pending[count++] = {static_cast<uint8_t*>(part.iov_base) + skip, part.iov_len - skip};
      skip = 0;
    }
    const ssize_t n = ::writev(fd_, pending, count);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int error = n < 0 ? errno : ENOSPC;
      failed_ = true;
      // Drop the torn record so the file ends on a record boundary.
      if (::ftruncate(fd_, bytes_committed_) != 0 || ::lseek(fd_, bytes_committed_, SEEK_SET) < 0) {
        return UnavailableError(path_ + ": write of trigger " +
                                std::to_string(frame.trigger_index) + " failed (" +
                                std::strerror(error) +
                                ") and the partial record could not be "
                                "truncated (" +
                                std::strerror(errno) + "); readers will ignore it");
      }
      return UnavailableError(
          path_ + ": write of trigger " + std::to_string(frame.trigger_index) + " failed: " +
          (error == ENOSPC ? "no space left on device (disk full)" : std::strerror(error)));
    }
    done += static_cast<size_t>(n);
  }
  // Start writeback of this record now (asynchronously) instead of letting dirty pages pile up
  // until the kernel's thresholds or the final fdatasync: the disk then works while the take
  // runs, and a take ends with little left to flush.
  ::sync_file_range(fd_, bytes_committed_, static_cast<off64_t>(total), SYNC_FILE_RANGE_WRITE);
  bytes_committed_ += static_cast<int64_t>(total);
  ++frames_written_;
  return Status::Ok();
}

Status FrameFileWriter::Close(bool sync) {
  if (fd_ < 0) return Status::Ok();
  Status status;
  if (sync && ::fdatasync(fd_) != 0)
    status = UnavailableError(path_ + ": fdatasync failed: " + std::strerror(errno));
  if (::close(fd_) != 0 && status.ok())
    status = UnavailableError(path_ + ": close failed: " + std::strerror(errno));
  fd_ = -1;
  return status;
}

StatusOr<std::unique_ptr<FrameFileReader>> FrameFileReader::Open(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    if (errno == ENOENT) return NotFoundError(path + ": no such frame file");
    return UnavailableError(path + ": cannot open: " + std::strerror(errno));
  }
  std::unique_ptr<FrameFileReader> reader(new FrameFileReader(path, fd));
  struct stat info;
  if (::fstat(fd, &info) != 0)
    return UnavailableError(path + ": stat failed: " + std::strerror(errno));
  FrameFileScan& scan = reader->scan_;
  scan.file_bytes = info.st_size;
  int64_t offset = 0;
  while (offset < scan.file_bytes) {
    if (scan.file_bytes - offset < kFrameHeaderBytes) {
      scan.tail_problem = "truncated record header at byte " + std::to_string(offset);
      break;
    }
    uint8_t header[kFrameHeaderBytes];
    if (::pread(fd, header, kFrameHeaderBytes, offset) != kFrameHeaderBytes) {
      scan.tail_problem =
          "read error at byte " + std::to_string(offset) + ": " + std::strerror(errno);
      break;
    }
    FrameRecord record;
    const std::string problem = DecodeHeader(header, offset, &record);
    if (!problem.empty()) {
      scan.tail_problem = problem + " at byte " + std::to_string(offset) + " (record " +
                          std::to_string(scan.records.size()) + ")";
      break;
    }
    const int64_t end = offset + kFrameHeaderBytes + static_cast<int64_t>(record.payload_bytes);
    if (end > scan.file_bytes) {
      scan.tail_problem = "truncated pixels of trigger " + std::to_string(record.trigger_index) +
                          " at byte " + std::to_string(offset);
      break;
    }
    // Its framing is sound (checksum, sizes), so one record with an impossible trigger index
    // is left out and named, and the records after it are still read: skipping it loses only
    // that frame, where stopping would lose the rest of the take.
    if (record.trigger_index < 0 || record.trigger_index >= kMaxTriggersPerTake) {
      scan.record_problems.push_back(
          path + ": record " + std::to_string(scan.records.size() + scan.record_problems.size()) +
          " at byte " + std::to_string(offset) + " has trigger_index " +
          std::to_string(record.trigger_index) + ", outside 0.." +
          std::to_string(kMaxTriggersPerTake - 1) + " (no take is longer); left out");
    } else {
      scan.records.push_back(record);
    }
    offset = end;
  }
  scan.valid_bytes =
      offset < scan.file_bytes && !scan.tail_problem.empty() ? offset : scan.file_bytes;
  return reader;
}

FrameFileReader::~FrameFileReader() {
  if (fd_ >= 0) ::close(fd_);
}

int FrameFileReader::FindTrigger(int64_t trigger_index) const {
  for (size_t i = 0; i < scan_.records.size(); ++i) {
    if (scan_.records[i].trigger_index == trigger_index) return static_cast<int>(i);
  }
  return -1;
}

Status FrameFileReader::Read(int index, Frame* frame) const {
  FACEDYN_CHECK(index >= 0 && index < frame_count(), "FrameFileReader::Read: index out of range");
  const FrameRecord& record = scan_.records[index];
  frame->camera_index = record.camera_index;
  frame->trigger_index = record.trigger_index;
  frame->timestamp_ns = record.timestamp_ns;
  frame->exposure_us = record.exposure_us;
  frame->width_px = record.width_px;
  frame->height_px = record.height_px;
  frame->format = record.format;
  frame->pixels.resize(record.payload_bytes);
  size_t done = 0;
  while (done < record.payload_bytes) {
    const ssize_t n = ::pread(fd_, frame->pixels.data() + done, record.payload_bytes - done,
                              record.offset + kFrameHeaderBytes + static_cast<int64_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      return DataLossError(path_ + ": cannot read pixels of record " + std::to_string(index) +
                           ": " + (n < 0 ? std::strerror(errno) : "unexpected end of file"));
    }
    done += static_cast<size_t>(n);
  }
  return Status::Ok();
}

}  // namespace facedyn::capture
