// The exports read back by Blender (Debian's blender, headless), the way an artist uses them:
// `facedyn export` writes topology.obj + positions.pc2/.mdd, take.glb and rig.glb (animated by
// a weights CSV); tests/export/blender_read_back.py imports the OBJ with a Mesh Cache modifier
// per cache (PC2 by frame, MDD by its stored times), and both .glb files, and records what
// Blender evaluates. This test compares that with the take and the CSV: every vertex within
// 1e-4 mm at the first, a middle and the last frame; morph target names, count and weights.
// Skipped (visible as such) where Blender is not installed; `make test` installs it.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/blendshape_weights.h"
#include "core/face_rig.h"
#include "core/take.h"
#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::FacedynExecutable;
using ::facedyn::testing::RunCommand;
using ::facedyn::testing::TempDir;

std::string Facedyn(const std::string& args) { return FacedynExecutable() + " --quiet " + args; }

void RunOrFail(const std::string& command) {
  std::string out;
  ASSERT_EQ(RunCommand(command, &out), 0) << command << "\n" << out;
}

// Largest distance (mm) between Blender's vertices (given in Blender's frame and units by
// `to_facedyn_mm`) and the take's frame `f`.
template <typename Convert>
double MaxErrorMm(const nlohmann::json& vertices, const Take& take, int f, Convert to_facedyn_mm) {
  const Eigen::Matrix3Xd truth = take.FramePositions(f);
  EXPECT_GE(static_cast<int>(vertices.size()), take.vertex_count());
  double worst = 0.0;
  for (int v = 0; v < take.vertex_count() && v < static_cast<int>(vertices.size()); ++v) {
    const Eigen::Vector3d blender(vertices[v][0].get<double>(), vertices[v][1].get<double>(),
                                  vertices[v][2].get<double>());
    worst = std::max(worst, (to_facedyn_mm(blender) - truth.col(v)).norm());
  }
  return worst;
}

TEST(Blender, ReadsTheCachesAndTheGltfFilesAsTheTakeAndWeights) {
  std::string out;
  if (RunCommand("blender --version", &out) != 0) {
    GTEST_SKIP() << "blender is not installed (scripts/install-deps.sh installs it)";
  }
  TempDir dir;
  const std::string face = dir.Join("face"), take_dir = dir.Join("take"), exported = dir.Join("export");
  RunOrFail(Facedyn("sim face --out " + face));
  // 10 frames at 50 fps: the times 0.02 k s fall on whole frames of a 100 fps Blender scene.
  RunOrFail(Facedyn("sim perform --face " + face +
              " --expression smile --hz 8 --seconds 0.2 --fps 50 --out " + take_dir));
  for (const char* format : {"pc2", "mdd", "glb"}) {
    RunOrFail(Facedyn("export --take " + take_dir + " --format " + format + " --out " + exported));
  }
  const auto rig = LoadFaceRig(face);
  ASSERT_TRUE(rig.ok()) << rig.status().message();
  ASSERT_GE(rig->blendshape_names.size(), 3u);
  // Weights of three shapes, not in the rig's order; the others stay at 0.
  BlendshapeWeightsTrack weights;
  weights.names = {rig->blendshape_names[2], rig->blendshape_names[0], rig->blendshape_names[1]};
  weights.time_s = {3.0, 3.5, 4.25};  // the export starts the animation at 0
  weights.weights.resize(3, 3);
  weights.weights << 0.0, 1.0, 0.25,  //
      0.5, 0.5, 0.0,                  //
      1.0, 0.0, 0.75;
  const std::string csv = dir.Join("weights.csv");
  ASSERT_TRUE(WriteBlendshapeWeightsCsv(csv, weights).ok());
  RunOrFail(Facedyn("export --rig " + face + " --weights " + csv + " --format glb --out " + exported));

  const auto take = LoadTake(take_dir);
  ASSERT_TRUE(take.ok()) << take.status().message();
  const int last = take->frame_count() - 1;
  ASSERT_EQ(last, 9);
  const std::vector<int> frames = {0, 4, last};
  nlohmann::json spec = {{"obj", exported + "/topology.obj"},
                         {"pc2", exported + "/positions.pc2"},
                         {"mdd", exported + "/positions.mdd"},
                         {"fps", take->info.fps},
                         {"frames", frames},
                         {"rig_glb", exported + "/rig.glb"},
                         // the samples, and a time between the first two (linear there)
                         {"rig_times_s", {0.0, 0.25, 0.5, 1.25}},
                         {"take_glb", exported + "/take.glb"},
                         {"take_times_s", {0.0, 0.08, 0.18}}};
  std::ofstream(dir.Join("spec.json")) << spec.dump();
  const std::string script = std::string(FACEDYN_SOURCE_DIR) + "/tests/export/blender_read_back.py";
  RunOrFail("blender --background --factory-startup --python " + script + " -- " + dir.Join("spec.json") +
      " " + dir.Join("result.json"));
  std::ifstream result_file(dir.Join("result.json"));
  ASSERT_TRUE(result_file.good());
  const nlohmann::json result = nlohmann::json::parse(result_file);

  // OBJ + Mesh Cache: the cache's coordinates as written (mm, facedyn's axes).
  EXPECT_EQ(result["obj_vertex_count"].get<int>(), take->vertex_count());
  const auto same = [](const Eigen::Vector3d& p) -> Eigen::Vector3d { return p; };
  for (const char* format : {"pc2", "mdd"}) {
    for (int f : frames) {
      EXPECT_LE(MaxErrorMm(result[format][std::to_string(f)], *take, f, same), 1e-4)
          << format << " frame " << f;
    }
  }
  // take.glb: Blender converts glTF's +Y up to +Z up, (x, y, z) -> (x, -z, y), in metres.
  const auto from_gltf = [](const Eigen::Vector3d& b) -> Eigen::Vector3d { return Eigen::Vector3d(b.x(), b.z(), -b.y()) * 1e3; };
  EXPECT_EQ(result["take"]["shape_key_count"].get<int>(), take->frame_count() - 1);
  for (size_t i = 0; i < 3; ++i) {
    const int f = frames[i];
    EXPECT_LE(MaxErrorMm(result["take"]["positions"][i], *take, f, from_gltf), 1e-4) << "glb frame " << f;
  }
  // rig.glb: every blendshape a shape key under its name, in order, and the weights in time.
  EXPECT_EQ(result["rig"]["shape_keys"].get<std::vector<std::string>>(), rig->blendshape_names);
  const std::vector<std::vector<double>> expected = {
      {0.0, 1.0, 0.25}, {0.25, 0.75, 0.125}, {0.5, 0.5, 0.0}, {1.0, 0.0, 0.75}};
  ASSERT_EQ(result["rig"]["weights"].size(), expected.size());
  for (size_t t = 0; t < expected.size(); ++t) {
    const nlohmann::json& at = result["rig"]["weights"][t];
    for (size_t c = 0; c < weights.names.size(); ++c) {
      EXPECT_NEAR(at[weights.names[c]].get<double>(), expected[t][c], 1e-6)
          << weights.names[c] << " at sample " << t;
    }
    for (size_t k = 3; k < rig->blendshape_names.size(); ++k) {
      EXPECT_EQ(at[rig->blendshape_names[k]].get<double>(), 0.0) << rig->blendshape_names[k];
    }
  }
}

}  // namespace
}  // namespace facedyn
