#include "core/take_export.h"

#include <fmt/format.h>

#include "core/file_util.h"
#include "core/progress.h"

namespace facedyn {

StatusOr<ExportFormat> ParseExportFormat(const std::string& name) {
  if (name == "obj") return ExportFormat::kObj;
  if (name == "ply") return ExportFormat::kPly;
  if (name == "pc2") return ExportFormat::kPc2;
  return InvalidArgumentError("unknown export format '" + name + "' (use obj, ply or pc2)");
}

StatusOr<ExportSummary> ExportTake(const Take& take, ExportFormat format, const std::string& dir) {
  FACEDYN_RETURN_IF_ERROR(take.Validate());
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(dir));
  ExportSummary summary;
  if (format == ExportFormat::kPc2) {
    FACEDYN_RETURN_IF_ERROR(WriteMesh(take.topology, JoinPath(dir, "topology.obj")));
    FACEDYN_RETURN_IF_ERROR(WritePc2(JoinPath(dir, "positions.pc2"), take.positions));
    summary.files_written = 2;
    for (const auto& [name, cache] : take.channels) {
      FACEDYN_RETURN_IF_ERROR(WritePc2(JoinPath(dir, name + ".pc2"), cache));
      ++summary.files_written;
    }
    return summary;
  }
  const char* ext = format == ExportFormat::kObj ? "obj" : "ply";
  Progress progress(fmt::format("export {}", ext), take.frame_count());
  for (int f = 0; f < take.frame_count(); ++f) {
    FACEDYN_RETURN_IF_ERROR(WriteMesh(take.topology, take.FramePositions(f),
                                      JoinPath(dir, fmt::format("frame_{:06d}.{}", f, ext))));
    ++summary.files_written;
    progress.Advance();
  }
  progress.Finish();
  return summary;
}

}  // namespace facedyn
