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

// fsyncs the directory that holds `path`, so a rename or a new file in it survives a power cut.
Status SyncParentDirectory(const std::string& path);

// Append-only line logs (JSON Lines journals) that a kill -9 or a full disk cannot break.
//
// OpenAppendLog opens `path` for appending (creating it) after repairing a torn tail: if the
// file does not end in '\n' (a crash or a short write mid-record), the unterminated fragment is
// appended to `path`.torn (fsynced) and then cut from the log, so the next record starts on a
// line of its own and nothing that was written is lost. `*torn_bytes` (may be null) gets the
// fragment's size, 0 when the tail was whole.
StatusOr<int> OpenAppendLog(const std::string& path, size_t* torn_bytes = nullptr);
// Appends `line` (which must end in '\n') to a log opened by OpenAppendLog, all or nothing: a
// failed or short write (ENOSPC) is rolled back to the previous size, so no fragment is left.
// The caller serialises calls on one fd.
Status AppendLogLine(int fd, const std::string& line, const std::string& path_for_errors);

// Creates `dir` and its parents; OK when it already exists as a directory.
Status MakeDirectories(const std::string& dir);

// Joins with a single '/'.
std::string JoinPath(const std::string& a, const std::string& b);

// The extension of the path's last component with its dot, lower-cased (".PLY" -> ".ply"), or
// "" when it has none ("take", "dir.v2/take", ".hidden"): what file formats are chosen by.
std::string LowercaseExtension(const std::string& path);

}  // namespace facedyn
