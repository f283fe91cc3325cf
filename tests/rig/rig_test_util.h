// Helpers for the rig and drive-sim tests: profile paths, and pymodbus as an independent peer
// run as a child process.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <string>
#include <thread>

#include "rig/drive_profile.h"
#include "tests/support/test_support.h"

#ifndef FACEDYN_SOURCE_DIR
#error "FACEDYN_SOURCE_DIR must be defined by the test's CMakeLists.txt"
#endif

namespace facedyn::testing {

inline std::string DriveProfilePath(const std::string& name) {
  return std::string(FACEDYN_SOURCE_DIR) + "/config/drives/" + name + ".yaml";
}

inline std::string RigConfigPath(const std::string& name) {
  return std::string(FACEDYN_SOURCE_DIR) + "/config/rigs/" + name + ".yaml";
}

inline std::string SweepConfigPath(const std::string& name) {
  return std::string(FACEDYN_SOURCE_DIR) + "/config/sweeps/" + name + ".yaml";
}

inline std::string RigTestScript(const std::string& name) {
  return std::string(FACEDYN_SOURCE_DIR) + "/tests/rig/" + name;
}

inline rig::DriveProfile LoadProfileOrDie(const std::string& name) {
  auto profile = rig::LoadDriveProfile(DriveProfilePath(name));
  if (!profile.ok()) {
    ADD_FAILURE() << profile.status().ToString();
    return rig::DriveProfile();
  }
  return *profile;
}

inline bool PymodbusAvailable() {
  std::string output;
  return RunCommand("/usr/bin/python3 -c 'import pymodbus'", &output) == 0;
}

// A pymodbus TCP server (tests/rig/pymodbus_server.py) on a free 127.0.0.1 port, killed with
// the object. Writes it receives are in log_path as "<address> <value>" lines.
class PymodbusServer {
 public:
  PymodbusServer(const TempDir& dir, int size, const std::vector<std::string>& presets = {})
      : log_path_(dir.Join("writes.log")), ready_path_(dir.Join("ready")) {
    std::vector<std::string> args = {"/usr/bin/python3",
                                     RigTestScript("pymodbus_server.py"),
                                     "--ready",
                                     ready_path_,
                                     "--log",
                                     log_path_,
                                     "--size",
                                     std::to_string(size)};
    for (const std::string& preset : presets) {
      args.push_back("--preset");
      args.push_back(preset);
    }
    pid_ = ::fork();
    if (pid_ == 0) {
      std::vector<char*> argv;
      for (std::string& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (std::chrono::steady_clock::now() < deadline) {
      std::ifstream ready(ready_path_);
      if (ready >> port_) return;
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    port_ = 0;
  }
  ~PymodbusServer() {
    if (pid_ > 0) {
      ::kill(pid_, SIGTERM);
      int status = 0;
      ::waitpid(pid_, &status, 0);
    }
  }
  PymodbusServer(const PymodbusServer&) = delete;
  PymodbusServer& operator=(const PymodbusServer&) = delete;

  int port() const { return port_; }  // 0 when it did not start
  std::string Writes() const { return ReadBytes(log_path_); }

 private:
  std::string log_path_;
  std::string ready_path_;
  pid_t pid_ = -1;
  int port_ = 0;
};

}  // namespace facedyn::testing

// Skips when python3-pymodbus is missing, fails instead when CI=true.
#define FACEDYN_REQUIRE_PYMODBUS()                                                       \
  if (!::facedyn::testing::PymodbusAvailable()) {                                        \
    if (::facedyn::testing::InCi()) FAIL() << "python3-pymodbus is missing and CI=true"; \
    GTEST_SKIP() << "python3-pymodbus not installed";                                    \
  }
