#include "process/content_hash.h"

#include <fcntl.h>
#include <openssl/evp.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>

namespace facedyn::process {
namespace fs = std::filesystem;
namespace {

std::string Hex(const unsigned char* bytes, unsigned size) {
  static const char* digits = "0123456789abcdef";
  std::string out;
  out.reserve(size * 2);
  for (unsigned i = 0; i < size; ++i) {
    out += digits[bytes[i] >> 4];
    out += digits[bytes[i] & 15];
  }
  return out;
}

}  // namespace

Sha256Builder::Sha256Builder() : context_(EVP_MD_CTX_new()) {
  EVP_DigestInit_ex(static_cast<EVP_MD_CTX*>(context_), EVP_sha256(), nullptr);
}
Sha256Builder::~Sha256Builder() { EVP_MD_CTX_free(static_cast<EVP_MD_CTX*>(context_)); }

void Sha256Builder::Add(const std::string& bytes) {
  const uint64_t size = bytes.size();
  EVP_DigestUpdate(static_cast<EVP_MD_CTX*>(context_), &size, sizeof(size));
  EVP_DigestUpdate(static_cast<EVP_MD_CTX*>(context_), bytes.data(), bytes.size());
}

std::string Sha256Builder::HexDigest() {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned size = 0;
  EVP_DigestFinal_ex(static_cast<EVP_MD_CTX*>(context_), digest, &size);
  return Hex(digest, size);
}

std::string Sha256Hex(const std::string& bytes) {
  Sha256Builder b;
  b.Add(bytes);
  return b.HexDigest();
}

StatusOr<std::string> FileHashCache::FileSha256(const std::string& path) {
  struct stat st {};
  if (stat(path.c_str(), &st) != 0) {
    return NotFoundError("cannot read input " + path + ": " + std::strerror(errno));
  }
  const int64_t mtime_ns =
      static_cast<int64_t>(st.st_mtim.tv_sec) * 1000000000LL + st.st_mtim.tv_nsec;
  const auto it = entries_.find(path);
  if (it != entries_.end() && it->second.size == st.st_size && it->second.mtime_ns == mtime_ns) {
    used_[path] = it->second;
    return it->second.sha256;
  }
  const int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return NotFoundError("cannot open input " + path + ": " + std::strerror(errno));
  EVP_MD_CTX* ctx = EVP_MD_CTX_new();
  EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr);
  std::vector<char> buffer(1 << 20);
  int64_t total = 0;
  while (true) {
    const ssize_t n = read(fd, buffer.data(), buffer.size());
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int error = errno;
      close(fd);
      EVP_MD_CTX_free(ctx);
      return DataLossError("cannot read input " + path + ": " + std::strerror(error));
    }
    if (n == 0) break;
    EVP_DigestUpdate(ctx, buffer.data(), static_cast<size_t>(n));
    total += n;
  }
  close(fd);
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned size = 0;
  EVP_DigestFinal_ex(ctx, digest, &size);
  EVP_MD_CTX_free(ctx);
  bytes_read_ += total;
  FileDigest d{static_cast<int64_t>(st.st_size), mtime_ns, Hex(digest, size)};
  if (total != st.st_size) d.mtime_ns = -1;  // changed while read: never trust this entry again
  entries_[path] = d;
  used_[path] = d;
  return d.sha256;
}

Json FileHashCache::ToJson() const {
  Json out = Json::array();
  for (const auto& [path, d] : used_) {
    out.push_back(
        {{"path", path}, {"size", d.size}, {"mtime_ns", d.mtime_ns}, {"sha256", d.sha256}});
  }
  return out;
}

FileHashCache FileHashCache::FromJson(const Json& json) {
  FileHashCache cache;
  if (!json.is_array()) return cache;
  for (const auto& e : json) {
    if (!e.is_object()) continue;
    const auto path = e.find("path");
    const auto size = e.find("size");
    const auto mtime = e.find("mtime_ns");
    const auto sha = e.find("sha256");
    if (path == e.end() || size == e.end() || mtime == e.end() || sha == e.end()) continue;
    if (!path->is_string() || !size->is_number_integer() || !mtime->is_number_integer() ||
        !sha->is_string()) {
      continue;
    }
    cache.entries_[path->get<std::string>()] =
        FileDigest{size->get<int64_t>(), mtime->get<int64_t>(), sha->get<std::string>()};
  }
  return cache;
}

StatusOr<std::string> HashInputs(const std::vector<std::string>& inputs,
                                 const std::vector<std::string>& extra, FileHashCache* cache) {
  Sha256Builder hash;
  for (const std::string& e : extra) hash.Add(e);
  for (const std::string& input : inputs) {
    std::error_code ec;
    const fs::file_status status = fs::status(input, ec);
    if (ec || !fs::exists(status)) return NotFoundError("input " + input + " does not exist");
    hash.Add("input:" + input);
    if (fs::is_regular_file(status)) {
      FACEDYN_ASSIGN_OR_RETURN(const std::string sha, cache->FileSha256(input));
      hash.Add(sha);
      continue;
    }
    if (!fs::is_directory(status))
      return InvalidArgumentError("input " + input + " is not a file or folder");
    std::vector<std::string> files;
    for (auto it = fs::recursive_directory_iterator(input, ec); !ec && it != fs::end(it);
         it.increment(ec)) {
      if (it->is_regular_file()) files.push_back(it->path().string());
    }
    if (ec) return DataLossError("cannot list input folder " + input + ": " + ec.message());
    std::sort(files.begin(), files.end());
    for (const std::string& file : files) {
      FACEDYN_ASSIGN_OR_RETURN(const std::string sha, cache->FileSha256(file));
      hash.Add(fs::path(file).lexically_relative(input).string());
      hash.Add(sha);
    }
  }
  return hash.HexDigest();
}

}  // namespace facedyn::process
