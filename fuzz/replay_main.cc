// A main() for the fuzz targets in builds without libFuzzer (GCC, the default build): runs
// LLVMFuzzerTestOneInput once on every regular file of the directories (or files) given on the
// command line, in name order, so the seed corpus and every crash ever found are replayed by
// ctest (`fuzz/<target>`). A crash or sanitizer report ends the process, which fails the test;
// the name of the input being run is printed first so the failing file is known.
//
// A directory that does not exist is skipped (a target may have no regressions yet), but a run
// that found no input at all fails: a replay of nothing would pass without testing anything.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

namespace {

std::vector<std::filesystem::path> InputsIn(const std::filesystem::path& where) {
  std::vector<std::filesystem::path> inputs;
  std::error_code ec;
  if (std::filesystem::is_regular_file(where, ec)) {
    inputs.push_back(where);
  } else if (std::filesystem::is_directory(where, ec)) {
    for (const auto& entry : std::filesystem::directory_iterator(where, ec)) {
      const std::string name = entry.path().filename().string();
      if (entry.is_regular_file(ec) && !name.empty() && name[0] != '.') {
        inputs.push_back(entry.path());
      }
    }
  }
  std::sort(inputs.begin(), inputs.end());
  return inputs;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s DIR_OR_FILE...\n", argv[0]);
    return 2;
  }
  size_t ran = 0;
  for (int i = 1; i < argc; ++i) {
    const std::vector<std::filesystem::path> inputs = InputsIn(argv[i]);
    if (inputs.empty()) std::printf("%s: no inputs (skipped)\n", argv[i]);
    for (const auto& path : inputs) {
      std::ifstream in(path, std::ios::binary);
      const std::vector<char> bytes((std::istreambuf_iterator<char>(in)),
                                    std::istreambuf_iterator<char>());
      if (!in.eof() && in.fail()) {
        std::fprintf(stderr, "%s: cannot read\n", path.c_str());
        return 1;
      }
      std::printf("replay %s (%zu bytes)\n", path.c_str(), bytes.size());
      std::fflush(stdout);
      LLVMFuzzerTestOneInput(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
      ++ran;
    }
  }
  if (ran == 0) {
    std::fprintf(stderr, "no inputs found: nothing was replayed\n");
    return 1;
  }
  std::printf("%zu input(s) replayed without a crash\n", ran);
  return 0;
}
