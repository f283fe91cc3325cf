// glTF export read back with tinygltf's loader (a different code path from its writer: the
// JSON and GLB parsers), checked against the rig and the take: units (metres), the seam split,
// morph targets and their names, normals, the animation's times and weights, and the errors.
// Blender reads the same files in tests/export/blender_test.
#include "export/gltf_export.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "core/blendshape_weights.h"
#include "core/file_util.h"
#include "core/mesh_primitives.h"
#include "export/take_export.h"
#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::TempDir;
using ::testing::HasSubstr;

// A 3 x 2 patch whose last column of quads has its own uvs: a seam along one grid line.
Mesh SeamedPatch() {
  Mesh mesh = MakeEllipsoidPatch(80, 100, 90, 0.6, 0.5, 3, 2);
  const int uv_count = static_cast<int>(mesh.uvs.cols());
  Eigen::Matrix2Xd uvs(2, 2 * uv_count);
  uvs << mesh.uvs, (mesh.uvs.array() * 0.5 + 0.25).matrix();
  mesh.uvs = uvs;
  for (int f = 0; f < mesh.face_count(); ++f) {
    // Faces whose corners all lie at x >= the column boundary use the second uv set.
    bool right = true;
    for (int c = mesh.face_offsets[f]; c < mesh.face_offsets[f + 1]; ++c) {
      right = right && mesh.positions_mm(0, mesh.corner_vertices[c]) > 10.0;
    }
    if (!right) continue;
    for (int c = mesh.face_offsets[f]; c < mesh.face_offsets[f + 1]; ++c) mesh.corner_uvs[c] += uv_count;
  }
  return mesh;
}

FaceRig PatchRig() {
  FaceRig rig;
  rig.name = "patch_subject";
  rig.neutral = SeamedPatch();
  const int v_count = rig.neutral.vertex_count();
  rig.blendshape_names = {"mouthSmileLeft", "jawOpen", "browInnerUp"};
  for (int k = 0; k < 3; ++k) {
    Eigen::Matrix3Xd delta(3, v_count);
    for (int v = 0; v < v_count; ++v) delta.col(v) << 0.5 * (k + 1), 0.25 * v - k, std::sin(v + k);
    rig.blendshape_deltas_mm.push_back(delta);
  }
  return rig;
}

tinygltf::Model LoadGlb(const std::string& path) {
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string error, warning;
  const bool ok = loader.LoadBinaryFromFile(&model, &error, &warning, path);
  EXPECT_TRUE(ok) << path << ": " << error;
  EXPECT_EQ(warning, "");
  return model;
}

// Accessor `index` as floats (tightly packed float accessors only, which is what facedyn writes).
std::vector<float> Floats(const tinygltf::Model& model, int index) {
  const tinygltf::Accessor& accessor = model.accessors.at(index);
  EXPECT_EQ(accessor.componentType, TINYGLTF_COMPONENT_TYPE_FLOAT);
  const tinygltf::BufferView& view = model.bufferViews.at(accessor.bufferView);
  const int components = tinygltf::GetNumComponentsInType(accessor.type);
  std::vector<float> values(accessor.count * components);
  EXPECT_EQ(view.byteLength, values.size() * sizeof(float));
  std::memcpy(values.data(), model.buffers.at(view.buffer).data.data() + view.byteOffset + accessor.byteOffset,
              values.size() * sizeof(float));
  return values;
}

std::vector<uint32_t> Indices(const tinygltf::Model& model, int index) {
  const tinygltf::Accessor& accessor = model.accessors.at(index);
  EXPECT_EQ(accessor.componentType, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT);
  const tinygltf::BufferView& view = model.bufferViews.at(accessor.bufferView);
  std::vector<uint32_t> values(accessor.count);
  std::memcpy(values.data(), model.buffers.at(view.buffer).data.data() + view.byteOffset, values.size() * 4);
  return values;
}

std::vector<std::string> TargetNames(const tinygltf::Mesh& mesh) {
  std::vector<std::string> names;
  const tinygltf::Value& array = mesh.extras.Get("targetNames");
  for (size_t i = 0; i < array.ArrayLen(); ++i) names.push_back(array.Get(static_cast<int>(i)).Get<std::string>());
  return names;
}

// glb vertex -> facedyn vertex, from the documented layout (i < V is i; the rest in extras).
std::vector<int> SourceVertices(const tinygltf::Mesh& mesh, int facedyn_vertices, int glb_vertices) {
  std::vector<int> source(glb_vertices);
  for (int i = 0; i < facedyn_vertices; ++i) source[i] = i;
  const tinygltf::Value& copies = mesh.extras.Get("facedyn_seam_source_vertices");
  EXPECT_EQ(static_cast<int>(copies.ArrayLen()), glb_vertices - facedyn_vertices);
  for (size_t i = 0; i < copies.ArrayLen(); ++i) {
    source[facedyn_vertices + i] = copies.Get(static_cast<int>(i)).Get<int>();
  }
  return source;
}

TEST(RigGlb, NeutralInMetresMorphTargetsNamedAndSeamsSplit) {
  TempDir dir;
  const FaceRig rig = PatchRig();
  const std::string path = dir.path() + "/rig.glb";
  const auto summary = WriteRigGlb(rig, nullptr, path);
  ASSERT_TRUE(summary.ok()) << summary.status().message();
  const tinygltf::Model model = LoadGlb(path);
  ASSERT_EQ(model.meshes.size(), 1u);
  ASSERT_EQ(model.meshes[0].primitives.size(), 1u);
  const tinygltf::Primitive& primitive = model.meshes[0].primitives[0];
  EXPECT_EQ(TargetNames(model.meshes[0]), rig.blendshape_names);
  ASSERT_EQ(primitive.targets.size(), 3u);
  EXPECT_TRUE(model.animations.empty());

  const int v_count = rig.vertex_count();
  const std::vector<float> positions = Floats(model, primitive.attributes.at("POSITION"));
  const int glb_count = static_cast<int>(positions.size() / 3);
  EXPECT_EQ(glb_count, summary->vertex_count);
  // The seam runs along one grid line of 3 vertices (rows + 1), each copied once.
  EXPECT_EQ(glb_count, v_count + 3);
  const std::vector<int> source = SourceVertices(model.meshes[0], v_count, glb_count);
  for (int i = 0; i < glb_count; ++i) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(positions[3 * i + k], rig.neutral.positions_mm(k, source[i]) * 1e-3, 1e-7);
    }
  }
  // Each triangle is a triangle of the rig (through the source map), in order.
  const std::vector<uint32_t> indices = Indices(model, primitive.indices);
  const Eigen::Matrix3Xi triangles = rig.neutral.Triangles();
  ASSERT_EQ(indices.size(), static_cast<size_t>(3 * triangles.cols()));
  for (Eigen::Index t = 0; t < triangles.cols(); ++t) {
    for (int k = 0; k < 3; ++k) EXPECT_EQ(source[indices[3 * t + k]], triangles(k, t));
  }
  // Every corner's uv survives (v flipped to glTF's top-left origin), seams included.
  const std::vector<float> uvs = Floats(model, primitive.attributes.at("TEXCOORD_0"));
  int corner = 0;
  for (int f = 0; f < rig.neutral.face_count(); ++f) {
    const int size = rig.neutral.FaceSize(f);
    for (int c = 1; c + 1 < size; ++c) {
      for (int k : {0, c, c + 1}) {
        const int uv = rig.neutral.corner_uvs[rig.neutral.face_offsets[f] + k];
        const uint32_t glb = indices[corner++];
        EXPECT_NEAR(uvs[2 * glb], rig.neutral.uvs(0, uv), 1e-6);
        EXPECT_NEAR(uvs[2 * glb + 1], 1.0 - rig.neutral.uvs(1, uv), 1e-6);
      }
    }
  }
  // Morph deltas in metres; base normals unit; normal deltas make the shape's normals.
  const std::vector<float> normals = Floats(model, primitive.attributes.at("NORMAL"));
  for (size_t t = 0; t < 3; ++t) {
    const std::vector<float> delta = Floats(model, primitive.targets[t].at("POSITION"));
    const std::vector<float> normal_delta = Floats(model, primitive.targets[t].at("NORMAL"));
    const Eigen::Matrix3Xd shape_normals =
        VertexNormals(rig.neutral, rig.neutral.positions_mm + rig.blendshape_deltas_mm[t]);
    for (int i = 0; i < glb_count; ++i) {
      for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(delta[3 * i + k], rig.blendshape_deltas_mm[t](k, source[i]) * 1e-3, 1e-8);
        EXPECT_NEAR(normals[3 * i + k] + normal_delta[3 * i + k], shape_normals(k, source[i]), 1e-6);
      }
    }
    EXPECT_FALSE(model.accessors[primitive.targets[t].at("POSITION")].minValues.empty());
  }
  EXPECT_EQ(model.nodes.at(0).mesh, 0);
  EXPECT_EQ(model.scenes.at(0).nodes, std::vector<int>{0});
  EXPECT_EQ(model.asset.version, "2.0");
}

TEST(RigGlb, WeightsAnimationInRigOrderFromTimeZero) {
  TempDir dir;
  const FaceRig rig = PatchRig();
  BlendshapeWeightsTrack track;
  track.names = {"browInnerUp", "mouthSmileLeft"};  // not the rig's order; jawOpen absent
  track.time_s = {10.0, 10.5, 11.25};
  track.weights.resize(3, 2);
  track.weights << 0.1, 0.9,  //
      0.2, 0.0,               //
      1.0, 0.5;
  const std::string csv = dir.path() + "/weights.csv";
  ASSERT_TRUE(WriteBlendshapeWeightsCsv(csv, track).ok());
  const auto read = ReadBlendshapeWeightsCsv(csv);
  ASSERT_TRUE(read.ok()) << read.status().message();
  const std::string path = dir.path() + "/rig.glb";
  const auto summary = WriteRigGlb(rig, &*read, path);
  ASSERT_TRUE(summary.ok()) << summary.status().message();
  EXPECT_EQ(summary->animation_samples, 3);
  const tinygltf::Model model = LoadGlb(path);
  ASSERT_EQ(model.animations.size(), 1u);
  const tinygltf::Animation& animation = model.animations[0];
  ASSERT_EQ(animation.channels.size(), 1u);
  EXPECT_EQ(animation.channels[0].target_path, "weights");
  EXPECT_EQ(animation.channels[0].target_node, 0);
  const tinygltf::AnimationSampler& sampler = animation.samplers.at(animation.channels[0].sampler);
  EXPECT_EQ(sampler.interpolation, "LINEAR");
  EXPECT_THAT(Floats(model, sampler.input), ::testing::ElementsAre(0.0f, 0.5f, 1.25f));
  EXPECT_EQ(model.accessors[sampler.input].maxValues, std::vector<double>{1.25});
  // Output: per sample, one weight per morph target in the rig's order.
  EXPECT_THAT(Floats(model, sampler.output),
              ::testing::Pointwise(::testing::FloatEq(),
                                   std::vector<float>{0.9f, 0.0f, 0.1f,  //
                                                      0.0f, 0.0f, 0.2f,  //
                                                      0.5f, 0.0f, 1.0f}));
}

TEST(RigGlb, WeightsNamingAnUnknownShapeAreAnErrorAndNothingIsWritten) {
  TempDir dir;
  BlendshapeWeightsTrack track;
  track.names = {"jawOpen", "tongueOut"};
  track.time_s = {0.0};
  track.weights = Eigen::MatrixXd::Zero(1, 2);
  const std::string path = dir.path() + "/rig.glb";
  const auto summary = WriteRigGlb(PatchRig(), &track, path);
  ASSERT_FALSE(summary.ok());
  EXPECT_THAT(summary.status().message(), HasSubstr("'tongueOut'"));
  EXPECT_FALSE(std::filesystem::exists(path));
}

Take ThreeFrameTake() {
  Take take;
  take.info.fps = 4.0;
  take.info.subject = "A";
  take.info.expression = "smile";
  take.info.motion = "platform";
  take.topology = SeamedPatch();
  const int v_count = take.topology.vertex_count();
  take.positions.vertex_count = v_count;
  take.positions.positions.resize(3 * v_count, 3);
  for (int f = 0; f < 3; ++f) {
    Eigen::Matrix3Xd frame = take.topology.positions_mm;
    frame.row(1).array() += 2.0 * f;
    frame.row(2).array() += std::sin(f);
    take.positions.Frame(f) = frame.cast<float>();
    take.time_s.push_back(100.0 + 0.25 * f);
    take.world_from_skull.push_back(Rigid3::Identity());
  }
  return take;
}

TEST(TakeGlb, FramesAreOneHotMorphTargetsAtTheirTimes) {
  TempDir dir;
  const Take take = ThreeFrameTake();
  ASSERT_TRUE(take.Validate().ok()) << take.Validate().message();
  const auto exported = ExportTake(take, ExportFormat::kGlb, dir.path());
  ASSERT_TRUE(exported.ok()) << exported.status().message();
  const tinygltf::Model model = LoadGlb(dir.path() + "/take.glb");
  const tinygltf::Primitive& primitive = model.meshes.at(0).primitives.at(0);
  EXPECT_EQ(TargetNames(model.meshes[0]), (std::vector<std::string>{"frame_000001", "frame_000002"}));
  EXPECT_EQ(model.meshes[0].name, "A_smile_platform");
  const int v_count = take.vertex_count();
  const std::vector<float> base = Floats(model, primitive.attributes.at("POSITION"));
  const int glb_count = static_cast<int>(base.size() / 3);
  const std::vector<int> source = SourceVertices(model.meshes[0], v_count, glb_count);
  const tinygltf::AnimationSampler& sampler = model.animations.at(0).samplers.at(0);
  EXPECT_THAT(Floats(model, sampler.input), ::testing::ElementsAre(0.0f, 0.25f, 0.5f));
  const std::vector<float> weights = Floats(model, sampler.output);
  ASSERT_EQ(weights.size(), 6u);
  for (int f = 0; f < 3; ++f) {
    // Position of frame f = base + sum_t w_t(f) delta_t, checked against the take.
    std::vector<double> position(base.begin(), base.end());
    for (int t = 0; t < 2; ++t) {
      EXPECT_EQ(weights[2 * f + t], f == t + 1 ? 1.0f : 0.0f);
      const std::vector<float> delta = Floats(model, primitive.targets.at(t).at("POSITION"));
      for (size_t i = 0; i < position.size(); ++i) position[i] += weights[2 * f + t] * delta[i];
    }
    const Eigen::Matrix3Xd truth = take.FramePositions(f);
    for (int i = 0; i < glb_count; ++i) {
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(position[3 * i + k] * 1e3, truth(k, source[i]), 1e-4);
    }
  }
  EXPECT_DOUBLE_EQ(model.meshes[0].extras.Get("facedyn_fps").GetNumberAsDouble(), 4.0);
}

TEST(TakeGlb, OneFrameIsAStaticMesh) {
  TempDir dir;
  Take take = ThreeFrameTake();
  take.positions.positions.conservativeResize(Eigen::NoChange, 1);
  take.time_s.resize(1);
  take.world_from_skull.resize(1);
  const auto summary = WriteTakeGlb(take, dir.path() + "/one.glb");
  ASSERT_TRUE(summary.ok()) << summary.status().message();
  EXPECT_EQ(summary->morph_target_count, 0);
  const tinygltf::Model model = LoadGlb(dir.path() + "/one.glb");
  EXPECT_TRUE(model.animations.empty());
  EXPECT_TRUE(model.meshes.at(0).primitives.at(0).targets.empty());
}

TEST(BlendshapeWeightsCsv, ErrorsNameTheFileLineAndColumn) {
  TempDir dir;
  const std::string path = dir.path() + "/w.csv";
  testing::WriteBytes(path, "time_s,jawOpen\n0.0,0.5\n0.0,0.25\n");
  auto read = ReadBlendshapeWeightsCsv(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr("w.csv:3"));
  EXPECT_THAT(read.status().message(), HasSubstr("not after"));
  testing::WriteBytes(path, "time_s,jawOpen\n0.0,x\n");
  read = ReadBlendshapeWeightsCsv(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr("column jawOpen"));
  testing::WriteBytes(path, "t,jawOpen\n0.0,1\n");
  EXPECT_THAT(ReadBlendshapeWeightsCsv(path).status().message(), HasSubstr("first column must be time_s"));
  testing::WriteBytes(path, "time_s,jawOpen,jawOpen\n0.0,1,1\n");
  EXPECT_THAT(ReadBlendshapeWeightsCsv(path).status().message(), HasSubstr("'jawOpen' twice"));
  testing::WriteBytes(path, "time_s,jawOpen\n");
  EXPECT_THAT(ReadBlendshapeWeightsCsv(path).status().message(), HasSubstr("no samples"));
}

}  // namespace
}  // namespace facedyn
