#include "export/take_export.h"

#include <fmt/format.h>

#include "core/file_util.h"
#include "export/gltf_export.h"
#include "export/mdd.h"
#include "core/progress.h"

namespace facedyn {

StatusOr<ExportFormat> ParseExportFormat(const std::string& name) {
  if (name == "obj") return ExportFormat::kObj;
  if (name == "ply") return ExportFormat::kPly;
  if (name == "pc2") return ExportFormat::kPc2;
  if (name == "mdd") return ExportFormat::kMdd;
  if (name == "glb") return ExportFormat::kGlb;
  return InvalidArgumentError("unknown export format '" + name + "' (use obj, ply, pc2, mdd or glb)");
}

StatusOr<ExportSummary> ExportTake(const Take& take, ExportFormat format, const std::string& dir) {
  FACEDYN_RETURN_IF_ERROR(take.Validate());
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(dir));
  ExportSummary summary;
  if (format == ExportFormat::kGlb) {
    FACEDYN_RETURN_IF_ERROR(WriteTakeGlb(take, JoinPath(dir, "take.glb")).status());
    summary.files_written = 1;
    return summary;
  }
  if (format == ExportFormat::kPc2 || format == ExportFormat::kMdd) {
    const bool mdd = format == ExportFormat::kMdd;
    // MDD frame times from the take's first frame (time_s is the session clock), so a tool
    // that plays the cache by time starts it at 0.
    std::vector<double> time_from_first_s(take.time_s.size());
    for (size_t f = 0; f < take.time_s.size(); ++f)
      time_from_first_s[f] = take.time_s[f] - take.time_s.front();
    auto write = [&](const std::string& name, const PointCache& cache) {
      return mdd ? WriteMdd(JoinPath(dir, name + ".mdd"), cache, time_from_first_s)
                 : WritePc2(JoinPath(dir, name + ".pc2"), cache);
    };
    FACEDYN_RETURN_IF_ERROR(WriteMesh(take.topology, JoinPath(dir, "topology.obj")));
    FACEDYN_RETURN_IF_ERROR(write("positions", take.positions));
    summary.files_written = 2;
    for (const auto& [name, cache] : take.channels) {
      FACEDYN_RETURN_IF_ERROR(write(name, cache));
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
