#include "fuzz/fuzz_util.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <set>

namespace facedyn::fuzz {
namespace {

class Scratch {
 public:
  Scratch() {
    spdlog::set_level(spdlog::level::off);
    const char* tmp = std::getenv("TMPDIR");
    std::string pattern = std::string(tmp && *tmp ? tmp : "/tmp") + "/facedyn-fuzz-XXXXXX";
    if (::mkdtemp(pattern.data()) == nullptr) {
      std::perror("facedyn fuzz: mkdtemp");
      std::abort();
    }
    dir_ = pattern;
  }
  ~Scratch() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  const std::string& dir() const { return dir_; }

 private:
  std::string dir_;
};

Scratch& TheScratch() {
  static Scratch scratch;
  return scratch;
}

}  // namespace

const std::string& ScratchDir() { return TheScratch().dir(); }

std::string WriteScratchFile(const std::string& relative, const uint8_t* data, size_t size) {
  const std::filesystem::path path = std::filesystem::path(ScratchDir()) / relative;
  std::error_code ec;
  std::filesystem::create_directories(path.parent_path(), ec);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) {
    std::fprintf(stderr, "facedyn fuzz: cannot write %s\n", path.c_str());
    std::abort();
  }
  return path.string();
}

std::string WriteScratchFile(const std::string& relative, const std::string& text) {
  return WriteScratchFile(relative, reinterpret_cast<const uint8_t*>(text.data()), text.size());
}

void CopyConfigFolder(const std::string& sub) {
  static std::mutex mutex;
  static std::set<std::string> copied;
  std::lock_guard<std::mutex> lock(mutex);
  if (!copied.insert(sub).second) return;
  const std::filesystem::path to = std::filesystem::path(ScratchDir()) / sub;
  std::error_code ec;
  std::filesystem::create_directories(to, ec);
  std::filesystem::copy(SourcePath("config/" + sub), to,
                        std::filesystem::copy_options::recursive |
                            std::filesystem::copy_options::overwrite_existing,
                        ec);
  if (ec) {
    std::fprintf(stderr, "facedyn fuzz: cannot copy config/%s: %s\n", sub.c_str(),
                 ec.message().c_str());
    std::abort();
  }
}

std::string SourcePath(const std::string& relative) {
  return std::string(FACEDYN_SOURCE_DIR) + "/" + relative;
}

}  // namespace facedyn::fuzz
