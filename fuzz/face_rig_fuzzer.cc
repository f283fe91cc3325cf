// LoadFaceRig (core/face_rig.h): a FaceRig folder's face_rig.json (names, landmarks, regions,
// jaw, stable regions) and markers.csv (surface points into the neutral mesh). The folder's
// meshes and point cache are a fixed small rig written once; their parsers have their own
// targets (mesh_obj, pc2). The input is face_rig.json, optionally followed by a line
// "=== markers.csv ===" and the markers table.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "core/face_rig.h"
#include "core/file_util.h"
#include "core/mesh_primitives.h"
#include "fuzz/fuzz_util.h"

namespace {

// A 3 x 3 patch (16 vertices) with two blendshapes, a skull, markers and samples: every file
// LoadFaceRig reads exists, so the fuzzed text decides how far loading gets.
const std::string& TemplateDir() {
  static const std::string dir = [] {
    facedyn::FaceRig rig;
    rig.name = "fuzz";
    rig.neutral = facedyn::MakeEllipsoidPatch(80, 100, 90, 0.6, 0.6, 3, 3);
    rig.blendshape_names = {"smile", "jaw_open"};
    for (int k = 0; k < 2; ++k) {
      rig.blendshape_deltas_mm.push_back(Eigen::Matrix3Xd::Constant(3, 16, 0.5 * (k + 1)));
    }
    rig.skull = facedyn::MakeEllipsoidPatch(70, 90, 80, 0.6, 0.6, 2, 2);
    rig.skull_landmarks = {{"nasion", Eigen::Vector3d(0, 10, 80)}};
    rig.skin_samples = {facedyn::SurfacePoint::AtVertex(0), facedyn::SurfacePoint::AtVertex(5)};
    rig.markers = {{"m0", facedyn::SurfacePoint::AtVertex(1), 2.0},
                   {"m1", facedyn::SurfacePoint{{2, 3, 6}, {0.2, 0.3, 0.5}}, 2.5}};
    rig.regions = {{"forehead", {0, 1, 2, 3}}, {"mouth", {8, 9, 12, 13}}};
    rig.stable_regions = {"forehead"};
    rig.jaw.region = "mouth";
    const std::string out = facedyn::fuzz::ScratchDir() + "/face_rig";
    if (!facedyn::SaveFaceRig(rig, out).ok()) __builtin_trap();  // the harness failing
    return out;
  }();
  return dir;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string& dir = TemplateDir();
  static const std::string template_markers = *facedyn::ReadFileToString(dir + "/markers.csv");
  const std::string input(reinterpret_cast<const char*>(data), size);
  static const std::string kSeparator = "\n=== markers.csv ===\n";
  const size_t split = input.find(kSeparator);
  facedyn::fuzz::WriteScratchFile("face_rig/face_rig.json", input.substr(0, split));
  facedyn::fuzz::WriteScratchFile(
      "face_rig/markers.csv",
      split == std::string::npos ? template_markers : input.substr(split + kSeparator.size()));
  const auto rig = facedyn::LoadFaceRig(dir);
  if (!rig.ok()) return 0;
  // What loading promises (Validate): indices in range and counts consistent, so evaluating the
  // rig and its sample points is safe.
  const Eigen::VectorXd weights = Eigen::VectorXd::Ones(rig->blendshape_names.size());
  const Eigen::Matrix3Xd skin = rig->Evaluate(weights);
  (void)rig->SamplePositions(skin);
  for (const auto& marker : rig->markers) (void)marker.point.Evaluate(skin);
  for (const auto& [name, vertices] : rig->regions) {
    for (const int v : vertices) (void)skin.col(v);
  }
  return 0;
}
