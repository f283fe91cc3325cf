// Small file helpers shared by every format: whole-file reads that report what went wrong,
// and atomic writes (temporary file + rename) so an interrupted save never leaves a
// half-written file under the real name.
#pragma once

#include <string>

#include "core/status.h"

namespace facedyn {

StatusOr<std::string> ReadFileToString(const std::string& path);

// Writes `contents` to `path` through `path.tmp` + fsync + rename.
Status WriteFileAtomic(const std::string& path, const std::string& contents);

// Creates `dir` and its parents; OK when it already exists as a directory.
Status MakeDirectories(const std::string& dir);

// Joins with a single '/'.
std::string JoinPath(const std::string& a, const std::string& b);

}  // namespace facedyn
