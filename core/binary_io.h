// Little helpers for facedyn's binary model files (detail/'s Masquerade model, dynamics/'s modal
// model): length-prefixed strings and arrays of plain values, in this machine's byte order
// (little-endian on every machine facedyn runs on). BinaryReader never reads past its buffer and
// bounds every count it reads, so a truncated or corrupted file is a DataLoss naming the path,
// the byte offset and what was being read, never a crash or a huge allocation.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "core/status.h"

namespace facedyn {

class BinaryWriter {
 public:
  template <typename T>
  void Pod(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    bytes_.append(reinterpret_cast<const char*>(&value), sizeof(T));
  }
  void Str(const std::string& s) {
    Pod<uint32_t>(static_cast<uint32_t>(s.size()));
    bytes_.append(s);
  }
  // A count (int64) then the values.
  template <typename T>
  void Array(const T* data, int64_t n) {
    static_assert(std::is_trivially_copyable_v<T>);
    Pod<int64_t>(n);
    bytes_.append(reinterpret_cast<const char*>(data), sizeof(T) * static_cast<size_t>(n));
  }
  void Doubles(const double* data, int64_t n) { Array(data, n); }
  void Ints(const int* data, int64_t n) { Array(data, n); }
  void Raw(const char* data, size_t n) { bytes_.append(data, n); }
  const std::string& bytes() const { return bytes_; }

 private:
  std::string bytes_;
};

class BinaryReader {
 public:
  // `max_count`: the largest array count accepted (a sanity bound against corrupted counts).
  BinaryReader(std::string bytes, std::string path, int64_t max_count = 50'000'000);

  Status Take(void* out, size_t n, const char* what);
  template <typename T>
  Status Pod(T* value, const char* what) {
    static_assert(std::is_trivially_copyable_v<T>);
    return Take(value, sizeof(T), what);
  }
  Status Str(std::string* s, const char* what);
  // A counted array of exactly `expected` entries (or any count up to max_count when
  // expected < 0).
  template <typename T>
  Status Array(std::vector<T>* out, int64_t expected, const char* what) {
    static_assert(std::is_trivially_copyable_v<T>);
    int64_t n = 0;
    FACEDYN_RETURN_IF_ERROR(Pod(&n, what));
    FACEDYN_RETURN_IF_ERROR(CheckCount(n, expected, what));
    out->resize(static_cast<size_t>(n));
    return Take(out->data(), sizeof(T) * static_cast<size_t>(n), what);
  }
  // A count in [0, max].
  Status Count(int64_t* n, int64_t max, const char* what);
  // The next bytes are exactly `expected` (a magic or a trailer).
  Status Expect(const char* expected, size_t n, const char* what);
  bool AtEnd() const { return pos_ == bytes_.size(); }
  size_t position() const { return pos_; }
  size_t remaining() const { return bytes_.size() - pos_; }
  const std::string& path() const { return path_; }

 private:
  Status CheckCount(int64_t n, int64_t expected, const char* what) const;

  std::string bytes_;
  std::string path_;
  int64_t max_count_;
  size_t pos_ = 0;
};

}  // namespace facedyn
