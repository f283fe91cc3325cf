#include "tests/support/test_support.h"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#ifndef FACEDYN_SOURCE_DIR
#error "FACEDYN_SOURCE_DIR must be defined by the build"
#endif

namespace facedyn::testing {

TempDir::TempDir() {
  std::random_device rd;
  const auto base = std::filesystem::temp_directory_path();
  for (int attempt = 0; attempt < 100; ++attempt) {
    auto candidate = base / ("facedyn_test_" + std::to_string(rd()));
    if (std::filesystem::create_directory(candidate)) {
      path_ = candidate.string();
      return;
    }
  }
  ADD_FAILURE() << "cannot create a temporary directory";
}

TempDir::~TempDir() {
  std::error_code ec;
  if (!path_.empty()) std::filesystem::remove_all(path_, ec);
}

std::string SharedDir() {
  const char* env = std::getenv("FACEDYN_SHARED_DIR");
  const std::string dir = env ? env : std::string(FACEDYN_SOURCE_DIR) + "/../shared";
  std::error_code ec;
  return std::filesystem::is_directory(dir, ec) ? dir : "";
}

std::string SharedAsset(const std::string& relative) {
  const std::string shared = SharedDir();
  if (shared.empty()) return "";
  const std::string path = shared + "/assets/" + relative;
  std::error_code ec;
  return std::filesystem::exists(path, ec) ? path : "";
}

bool InCi() {
  const char* ci = std::getenv("CI");
  return ci && std::string(ci) == "true";
}

std::string FacedynExecutable() {
  const char* dir = std::getenv("FACEDYN_BINARY_DIR");
  return std::string(dir ? dir : FACEDYN_BINARY_DIR_DEFAULT) + "/app/facedyn";
}

int RunCommand(const std::string& command, std::string* output) {
  output->clear();
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return -1;
  char buffer[4096];
  size_t n;
  while ((n = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) output->append(buffer, n);
  const int status = ::pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

void WriteBytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << "cannot write " << path;
}

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace facedyn::testing
