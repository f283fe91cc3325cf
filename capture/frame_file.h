// Frame files: the lossless on-disk form of one camera's frames in one take
// (takes/<take>/cam<k>/frames.fdr).
//
// Why raw with a small header and not PNG: the simulated 8-camera rig produces
// 8 x 1280 x 1024 x 128 fps = 1.34 GB/s of mono8 pixels. zlib's deflate (PNG) runs at roughly
// 30-80 MB/s per core even at its fastest level, so PNG would need 20+ cores to keep up,
// while a raw record is one writev() of a 64-byte header and the pixels: the disk, not the
// CPU, is the limit, and that is what bench/capture_bench measures. Captured footage is
// compressed offline if at all (reconstruction reads raw frames faster anyway). One file per
// camera per take, appended sequentially, is the access pattern disks are fastest at and
// costs one open file per camera instead of one per frame.
//
// A file is a sequence of records, each a 64-byte little-endian header then the pixels:
//   0  char[4] magic "FDFR"          4  uint32 header_bytes (64)
//   8  int64 trigger_index          16  int64 timestamp_ns (session clock)
//  24  int32 exposure_us            28  uint32 width_px
//  32  uint32 height_px             36  uint32 pixel format (capture/frame.h PixelFormat)
//  40  uint64 payload_bytes         48  uint32 camera_index
//  52  uint32 reserved (0)          56  uint64 FNV-1a-64 checksum of bytes 0..55
// Records are in arrival order (normally trigger order). A record is only counted once its
// last byte is on disk; a torn tail (kill -9, disk full) is detected by length and ignored by
// readers, who report it. The header checksum detects a corrupted header; payloads carry no
// checksum (a CRC would cost as much CPU as the copy at these rates). Readers also refuse what
// no camera produces (capture/frame.h): a side outside 1..65,536 px or a payload over 1 GiB
// ends the scan like a corrupt header; a trigger index outside 0..kMaxTriggersPerTake-1 drops
// that one record, named, and the scan goes on.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "capture/frame.h"
#include "core/status.h"

namespace facedyn::capture {

inline constexpr int kFrameHeaderBytes = 64;
inline constexpr char kFrameFileName[] = "frames.fdr";

// Appends frames to one file. Not thread-safe: one writer thread per file.
class FrameFileWriter {
 public:
  // Creates `path` (which must not exist: a take never overwrites frames).
  static StatusOr<std::unique_ptr<FrameFileWriter>> Create(const std::string& path);
  ~FrameFileWriter();
  FrameFileWriter(const FrameFileWriter&) = delete;
  FrameFileWriter& operator=(const FrameFileWriter&) = delete;

  // Appends one record. On a write error (ENOSPC, EIO, ...) the file is truncated back to the
  // end of the last complete record and an Unavailable status names the file, the trigger
  // index and the reason; the writer then refuses further appends.
  Status Append(const Frame& frame);
  // fdatasync (when `sync`) and close. Idempotent.
  Status Close(bool sync = true);

  int64_t frames_written() const { return frames_written_; }
  int64_t bytes_committed() const { return bytes_committed_; }
  const std::string& path() const { return path_; }

 private:
  FrameFileWriter(std::string path, int fd) : path_(std::move(path)), fd_(fd) {}
  std::string path_;
  int fd_ = -1;
  bool failed_ = false;
  int64_t frames_written_ = 0;
  int64_t bytes_committed_ = 0;
};

struct FrameRecord {
  int64_t offset = 0;  // of the header
  int64_t trigger_index = 0;
  int64_t timestamp_ns = 0;
  int32_t exposure_us = 0;
  int width_px = 0;
  int height_px = 0;
  PixelFormat format = PixelFormat::kMono8;
  uint64_t payload_bytes = 0;
  int camera_index = 0;
};

struct FrameFileScan {
  std::vector<FrameRecord> records;  // complete records, file order
  int64_t file_bytes = 0;
  int64_t valid_bytes = 0;   // end of the last complete record
  std::string tail_problem;  // "" when the file ends cleanly after a record
  // Records whose framing is sound but whose content is impossible (a trigger index no take
  // can reach), each named with the file, its record number, byte offset and value. They are
  // not in `records`; the scan goes on after them.
  std::vector<std::string> record_problems;
};

// Reads a frame file for random access. The scan reads only headers (seeking over pixels).
class FrameFileReader {
 public:
  // NotFound when missing; a file whose first header is corrupt scans as zero records with a
  // tail_problem (the caller decides whether that is fatal).
  static StatusOr<std::unique_ptr<FrameFileReader>> Open(const std::string& path);
  ~FrameFileReader();
  FrameFileReader(const FrameFileReader&) = delete;
  FrameFileReader& operator=(const FrameFileReader&) = delete;

  const FrameFileScan& scan() const { return scan_; }
  int frame_count() const { return static_cast<int>(scan_.records.size()); }
  // Record index of the first frame with this trigger index, or -1.
  int FindTrigger(int64_t trigger_index) const;
  // Reads record `index` (0 <= index < frame_count()) into *frame (pixels resized).
  Status Read(int index, Frame* frame) const;

 private:
  FrameFileReader(std::string path, int fd) : path_(std::move(path)), fd_(fd) {}
  std::string path_;
  int fd_ = -1;
  FrameFileScan scan_;
};

}  // namespace facedyn::capture
