// Exporting a Take for other tools: per-frame meshes (OBJ or PLY, one file per frame), the
// topology plus point caches (PC2 or MDD, both of which Blender's Mesh Cache modifier and
// 3ds Max's Point Cache read), or one glTF binary (export/gltf_export.h).
#pragma once

#include <string>

#include "core/status.h"
#include "core/take.h"

namespace facedyn {

enum class ExportFormat { kObj, kPly, kPc2, kMdd, kGlb };

// "obj" | "ply" | "pc2" | "mdd" | "glb".
StatusOr<ExportFormat> ParseExportFormat(const std::string& name);

struct ExportSummary {
  int files_written = 0;
};

// obj/ply: DIR/frame_000000.<ext> ... in world coordinates (mm).
// pc2: DIR/topology.obj, DIR/positions.pc2 and DIR/<channel>.pc2 for every channel.
// mdd: the same with .mdd caches (export/mdd.h), each frame stamped with its time from the
// take's first frame (s).
// glb: DIR/take.glb, the first frame plus one morph target per later frame (gltf_export.h).
// Shows progress for per-frame formats.
StatusOr<ExportSummary> ExportTake(const Take& take, ExportFormat format, const std::string& dir);

}  // namespace facedyn
