#include "core/binary_io.h"

#include <fmt/format.h>

#include <utility>

namespace facedyn {

BinaryReader::BinaryReader(std::string bytes, std::string path, int64_t max_count)
    : bytes_(std::move(bytes)), path_(std::move(path)), max_count_(max_count) {}

Status BinaryReader::Take(void* out, size_t n, const char* what) {
  if (bytes_.size() - pos_ < n) {
    return DataLossError(
        fmt::format("{}: truncated at byte {} while reading {}", path_, pos_, what));
  }
  if (n > 0) std::memcpy(out, bytes_.data() + pos_, n);
  pos_ += n;
  return Status::Ok();
}

Status BinaryReader::Str(std::string* s, const char* what) {
  uint32_t n = 0;
  FACEDYN_RETURN_IF_ERROR(Pod(&n, what));
  if (n > bytes_.size() - pos_) {
    return DataLossError(fmt::format("{}: truncated at byte {} in {}", path_, pos_, what));
  }
  s->assign(bytes_.data() + pos_, n);
  pos_ += n;
  return Status::Ok();
}

Status BinaryReader::CheckCount(int64_t n, int64_t expected, const char* what) const {
  if (n < 0 || n > max_count_ || (expected >= 0 && n != expected)) {
    return DataLossError(
        fmt::format("{}: {} has {} entries, expected {}", path_, what, n,
                    expected >= 0 ? std::to_string(expected) : std::string("a sane count")));
  }
  return Status::Ok();
}

Status BinaryReader::Count(int64_t* n, int64_t max, const char* what) {
  FACEDYN_RETURN_IF_ERROR(Pod(n, what));
  if (*n < 0 || *n > max) {
    return DataLossError(fmt::format("{}: {} is {}, out of range", path_, what, *n));
  }
  return Status::Ok();
}

Status BinaryReader::Expect(const char* expected, size_t n, const char* what) {
  if (bytes_.size() - pos_ < n || std::memcmp(bytes_.data() + pos_, expected, n) != 0) {
    return DataLossError(fmt::format("{}: {} not found at byte {}", path_, what, pos_));
  }
  pos_ += n;
  return Status::Ok();
}

}  // namespace facedyn
