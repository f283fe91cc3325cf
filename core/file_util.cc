#include "core/file_util.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace facedyn {

StatusOr<std::string> ReadFileToString(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return NotFoundError(path + ": no such file");
  if (std::filesystem::is_directory(path, ec)) {
    return InvalidArgumentError(path + ": is a directory, expected a file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return NotFoundError(path + ": cannot open: " + std::strerror(errno));
  std::ostringstream buffer;
  buffer << in.rdbuf();
  if (in.bad()) return DataLossError(path + ": read error: " + std::strerror(errno));
  return buffer.str();
}

Status WriteFileAtomic(const std::string& path, const std::string& contents) {
  const std::string tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return UnavailableError(tmp + ": cannot create: " + std::strerror(errno));
  size_t written = 0;
  while (written < contents.size()) {
    const ssize_t n = ::write(fd, contents.data() + written, contents.size() - written);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string reason = std::strerror(errno);
      ::close(fd);
      ::unlink(tmp.c_str());
      return UnavailableError(path + ": write failed: " + reason);
    }
    written += static_cast<size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    const std::string reason = std::strerror(errno);
    ::unlink(tmp.c_str());
    return UnavailableError(path + ": flush failed: " + reason);
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string reason = std::strerror(errno);
    ::unlink(tmp.c_str());
    return UnavailableError(path + ": rename failed: " + reason);
  }
  // The rename lives in the directory: without this a power cut can bring back the old file.
  return SyncParentDirectory(path);
}

Status SyncParentDirectory(const std::string& path) {
  std::string dir = std::filesystem::path(path).parent_path().string();
  if (dir.empty()) dir = ".";
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return UnavailableError(dir + ": cannot open directory to sync: " + std::strerror(errno));
  const int rc = ::fsync(fd);
  const int error = errno;
  ::close(fd);
  // Some file systems (e.g. certain FUSE mounts) refuse fsync on a directory: nothing to do.
  if (rc != 0 && error != EINVAL && error != EROFS)
    return UnavailableError(dir + ": directory fsync failed: " + std::strerror(error));
  return Status::Ok();
}

StatusOr<int> OpenAppendLog(const std::string& path, size_t* torn_bytes) {
  if (torn_bytes) *torn_bytes = 0;
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) return UnavailableError(path + ": cannot open: " + std::strerror(errno));
  const off_t size = ::lseek(fd, 0, SEEK_END);
  if (size > 0) {
    // Find the last '\n' by reading backwards in blocks.
    off_t keep = 0;  // bytes up to and including the last newline
    char block[4096];
    off_t end = size;
    bool last_byte_newline = false;
    bool found = false;
    while (end > 0 && !found) {
      const off_t begin = std::max<off_t>(0, end - static_cast<off_t>(sizeof(block)));
      const ssize_t n = ::pread(fd, block, static_cast<size_t>(end - begin), begin);
      if (n != end - begin) {
        const std::string reason = n < 0 ? std::strerror(errno) : "short read";
        ::close(fd);
        return UnavailableError(path + ": cannot read its tail: " + reason);
      }
      if (end == size) last_byte_newline = block[n - 1] == '\n';
      if (last_byte_newline) {
        keep = size;
        found = true;
        break;
      }
      for (ssize_t i = n - 1; i >= 0; --i) {
        if (block[i] == '\n') {
          keep = begin + i + 1;
          found = true;
          break;
        }
      }
      end = begin;
    }
    if (keep < size) {
      std::string fragment(static_cast<size_t>(size - keep), '\0');
      if (::pread(fd, fragment.data(), fragment.size(), keep) !=
          static_cast<ssize_t>(fragment.size())) {
        ::close(fd);
        return UnavailableError(path + ": cannot read its torn tail");
      }
      const std::string torn_path = path + ".torn";
      const int torn = ::open(torn_path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
      fragment += '\n';
      if (torn < 0 ||
          ::write(torn, fragment.data(), fragment.size()) != static_cast<ssize_t>(fragment.size()) ||
          ::fsync(torn) != 0) {
        const std::string reason = std::strerror(errno);
        if (torn >= 0) ::close(torn);
        ::close(fd);
        return UnavailableError(path + ": a torn last line could not be preserved in " +
                                torn_path + ": " + reason + "; nothing was changed");
      }
      ::close(torn);
      if (::ftruncate(fd, keep) != 0 || ::fsync(fd) != 0) {
        const std::string reason = std::strerror(errno);
        ::close(fd);
        return UnavailableError(path + ": cannot cut its torn last line (kept in " + torn_path +
                                "): " + reason);
      }
      if (torn_bytes) *torn_bytes = fragment.size() - 1;
    }
  }
  return fd;
}

Status AppendLogLine(int fd, const std::string& line, const std::string& path_for_errors) {
  const off_t before = ::lseek(fd, 0, SEEK_END);
  size_t done = 0;
  while (done < line.size()) {
    const ssize_t n = ::write(fd, line.data() + done, line.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string reason = n < 0 ? std::strerror(errno) : "wrote nothing";
      // Roll back a partial record so the log never holds a fragment.
      if (done > 0 && before >= 0) (void)!::ftruncate(fd, before);
      return UnavailableError(path_for_errors + ": cannot append: " + reason);
    }
    done += static_cast<size_t>(n);
  }
  return Status::Ok();
}

Status MakeDirectories(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return UnavailableError(dir + ": cannot create directory: " + ec.message());
  if (!std::filesystem::is_directory(dir, ec)) {
    return InvalidArgumentError(dir + ": exists and is not a directory");
  }
  return Status::Ok();
}

std::string JoinPath(const std::string& a, const std::string& b) {
  if (a.empty()) return b;
  if (a.back() == '/') return a + b;
  return a + "/" + b;
}

std::string LowercaseExtension(const std::string& path) {
  std::string extension = std::filesystem::path(path).extension().string();
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return extension;
}

}  // namespace facedyn
