// SHA-256 of files and folders, for deciding whether a job's inputs changed (OpenSSL's libcrypto:
// a well-kept, fast implementation — not hand-written).
//
// Hashing a session's raw frames (gigabytes per take) on every run would cost minutes, so a
// FileHashCache remembers each file's digest with its size and modification time; a file whose
// size and mtime are unchanged is not read again. The cache travels in the job's state file.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::process {

struct FileDigest {
  int64_t size = 0;
  int64_t mtime_ns = 0;
  std::string sha256;  // lowercase hex
};

class FileHashCache {
 public:
  // The digest of a regular file, read only when its size or mtime differ from the cached entry.
  StatusOr<std::string> FileSha256(const std::string& path);
  const std::map<std::string, FileDigest>& entries() const { return entries_; }
  // The entries used since construction (entries of files no longer hashed drop out).
  Json ToJson() const;
  static FileHashCache FromJson(const Json& json);  // tolerant: bad entries are ignored
  int64_t bytes_read() const { return bytes_read_; }

 private:
  std::map<std::string, FileDigest> entries_;  // previous digests
  std::map<std::string, FileDigest> used_;     // digests used in this run
  int64_t bytes_read_ = 0;
};

// Streams SHA-256 over named parts: each Add is framed by its length, so ("ab","c") and
// ("a","bc") differ.
class Sha256Builder {
 public:
  Sha256Builder();
  ~Sha256Builder();
  Sha256Builder(const Sha256Builder&) = delete;
  Sha256Builder& operator=(const Sha256Builder&) = delete;
  void Add(const std::string& bytes);
  std::string HexDigest();  // finishes the hash

 private:
  void* context_;  // EVP_MD_CTX
};

// The hash of a set of inputs: every file under every path (folders recursively, in sorted
// order; the path of each file relative to its input root is hashed with its content), plus
// `extra` strings (the command lines, the tool version). An input that does not exist is an
// error naming it.
StatusOr<std::string> HashInputs(const std::vector<std::string>& inputs,
                                 const std::vector<std::string>& extra, FileHashCache* cache);

// SHA-256 of a byte string, hex.
std::string Sha256Hex(const std::string& bytes);

}  // namespace facedyn::process
