// Helpers shared by facedyn's tests: temporary folders, the shared assets, Eigen matchers.
#pragma once

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace facedyn::testing {

// A fresh empty folder under the system temp dir, removed with the object.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::string& path() const { return path_; }
  std::string Join(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// ../shared (FACEDYN_SHARED_DIR overrides), or "" when absent.
std::string SharedDir();
// Path of a file under ../shared/assets; "" when it is missing.
std::string SharedAsset(const std::string& relative);
// True when the environment says CI=true: there missing shared assets are failures.
bool InCi();

// The facedyn executable in the build tree (FACEDYN_BINARY_DIR is set by CTest).
std::string FacedynExecutable();
// Debian's chromium, or "" when it is not installed.
std::string ChromiumExecutable();
// The start of a headless Chromium command line (the executable and the flags every page test
// uses: no sandbox as root, software WebGL, no network services), with its profile in
// `profile_dir`; append --screenshot=..., --dump-dom, --window-size=... and the URL.
std::string HeadlessChromium(const std::string& profile_dir);
// Runs a shell command, captures stdout+stderr into *output, returns the exit code.
int RunCommand(const std::string& command, std::string* output);

// A child process (argv[0] is a path, no shell) with stdout and stderr in `output_path`;
// killed with SIGKILL and reaped when the object goes.
class ChildProcess {
 public:
  ChildProcess(const std::vector<std::string>& args, const std::string& output_path);
  ~ChildProcess();
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;
  void Signal(int signal_number);
  // Exit code, 128 + signal when killed by one, or -1 when still running after timeout_s.
  int Wait(double timeout_s);
  bool running() const { return pid_ > 0; }

 private:
  int pid_ = -1;
};

// Writes bytes to a file (for crafting corrupt inputs), creating its folder.
void WriteBytes(const std::string& path, const std::string& bytes);
std::string ReadBytes(const std::string& path);

}  // namespace facedyn::testing

// Skips the test when the asset is missing, fails instead when CI=true (shared/README.md).
#define FACEDYN_REQUIRE_SHARED_ASSET(var, relative)                                   \
  const std::string var = ::facedyn::testing::SharedAsset(relative);                  \
  if (var.empty()) {                                                                  \
    if (::facedyn::testing::InCi()) {                                                 \
      FAIL() << "shared asset " << (relative) << " is missing and CI=true";            \
    }                                                                                 \
    GTEST_SKIP() << "shared asset " << (relative) << " not present (../shared/assets)"; \
  }

// EXPECT that two Eigen objects agree elementwise within an absolute tolerance.
#define EXPECT_EIGEN_NEAR(a, b, tol)                                                    \
  do {                                                                                  \
    const auto facedyn_a_ = (a).eval();                                                 \
    const auto facedyn_b_ = (b).eval();                                                 \
    ASSERT_EQ(facedyn_a_.rows(), facedyn_b_.rows());                                    \
    ASSERT_EQ(facedyn_a_.cols(), facedyn_b_.cols());                                    \
    EXPECT_LE((facedyn_a_ - facedyn_b_).cwiseAbs().maxCoeff(), (tol))                   \
        << #a " =\n" << facedyn_a_ << "\n" #b " =\n" << facedyn_b_;                     \
  } while (false)
