// Helpers shared by the fuzz targets (fuzz/*_fuzzer.cc).
//
// Most of facedyn's parsers take a path, not a buffer, so a target writes its input to a file
// in a scratch directory that belongs to this process (mkdtemp under $TMPDIR, removed at
// exit) and parses that. Logging is switched off: a parser that warns on every bad input
// would spend the fuzzer's time formatting messages.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace facedyn::fuzz {

// The process's scratch directory (created on first use, removed at exit).
const std::string& ScratchDir();

// Writes `size` bytes to ScratchDir()/<relative> (creating parent folders) and returns the
// absolute path. Aborts when the scratch disk refuses: that is the harness failing, not the
// parser.
std::string WriteScratchFile(const std::string& relative, const uint8_t* data, size_t size);
std::string WriteScratchFile(const std::string& relative, const std::string& text);

// Copies the shipped configuration folder (<source>/config/<sub>) to ScratchDir()/<sub>, once,
// so relative references in a fuzzed file ("../drives/sim.yaml") resolve as in the tree.
void CopyConfigFolder(const std::string& sub);

// <source tree>/<relative>.
std::string SourcePath(const std::string& relative);

}  // namespace facedyn::fuzz
