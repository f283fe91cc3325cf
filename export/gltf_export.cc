#include "export/gltf_export.h"

#include <fmt/format.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <functional>
#include <limits>
#include <map>
#include <sstream>
#include <utility>
#include <vector>

#include "core/file_util.h"
#include "core/mesh.h"
#include "core/progress.h"
#include "facedyn_version.h"

namespace facedyn {
namespace {

constexpr double kMetresPerMm = 1e-3;
// The GLB container's lengths are uint32 (glTF 2.0 spec, "Binary glTF Layout").
constexpr uint64_t kMaxGlbBytes = std::numeric_limits<uint32_t>::max();

// The mesh as glTF needs it: one uv per vertex, so vertices on UV seams are split.
struct GlbTopology {
  std::vector<int> source_vertex;  // per glb vertex: the facedyn vertex it copies
  std::vector<int> uv_index;       // per glb vertex: its uv (-1: none), only when has_uvs
  std::vector<uint32_t> triangle_indices;
};

GlbTopology SplitAtUvSeams(const Mesh& mesh) {
  GlbTopology topology;
  const int vertex_count = mesh.vertex_count();
  topology.source_vertex.resize(vertex_count);
  for (int v = 0; v < vertex_count; ++v) topology.source_vertex[v] = v;
  std::vector<int> corner_glb(mesh.corner_vertices.size());
  if (!mesh.has_uvs()) {
    for (size_t c = 0; c < corner_glb.size(); ++c) corner_glb[c] = mesh.corner_vertices[c];
  } else {
    // A vertex keeps its own index for the first uv it is seen with; every other uv it has
    // gets a copy appended after the V originals.
    topology.uv_index.assign(vertex_count, -1);
    std::map<std::pair<int, int>, int> copies;
    for (size_t c = 0; c < corner_glb.size(); ++c) {
      const int v = mesh.corner_vertices[c];
      const int uv = mesh.corner_uvs[c];
      if (topology.uv_index[v] < 0) topology.uv_index[v] = uv;
      if (topology.uv_index[v] == uv) {
        corner_glb[c] = v;
        continue;
      }
      auto [it, inserted] = copies.emplace(std::make_pair(v, uv), 0);
      if (inserted) {
        it->second = static_cast<int>(topology.source_vertex.size());
        topology.source_vertex.push_back(v);
        topology.uv_index.push_back(uv);
      }
      corner_glb[c] = it->second;
    }
  }
  for (int f = 0; f < mesh.face_count(); ++f) {
    const int begin = mesh.face_offsets[f], end = mesh.face_offsets[f + 1];
    for (int c = begin + 1; c + 1 < end; ++c) {
      topology.triangle_indices.push_back(static_cast<uint32_t>(corner_glb[begin]));
      topology.triangle_indices.push_back(static_cast<uint32_t>(corner_glb[c]));
      topology.triangle_indices.push_back(static_cast<uint32_t>(corner_glb[c + 1]));
    }
  }
  return topology;
}

// Builds the glTF document: buffer 0 holds every accessor's data, 4-byte aligned.
class GlbBuilder {
 public:
  GlbBuilder() {
    model_.asset.version = "2.0";
    model_.asset.generator = fmt::format("facedyn {} ({})", FACEDYN_VERSION, FACEDYN_GIT_REVISION);
    model_.buffers.emplace_back();
  }

  // Floats (already converted to the accessor's units), count elements of `components`.
  int AddFloats(const std::vector<float>& values, int type, int components, bool with_min_max,
                int target) {
    const int view = AddView(values.data(), values.size() * sizeof(float), target);
    tinygltf::Accessor accessor;
    accessor.bufferView = view;
    accessor.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
    accessor.type = type;
    accessor.count = values.size() / static_cast<size_t>(components);
    if (with_min_max) {
      accessor.minValues.assign(components, std::numeric_limits<double>::infinity());
      accessor.maxValues.assign(components, -std::numeric_limits<double>::infinity());
      for (size_t i = 0; i < values.size(); ++i) {
        const size_t k = i % static_cast<size_t>(components);
        accessor.minValues[k] = std::min(accessor.minValues[k], static_cast<double>(values[i]));
        accessor.maxValues[k] = std::max(accessor.maxValues[k], static_cast<double>(values[i]));
      }
    }
    model_.accessors.push_back(std::move(accessor));
    return static_cast<int>(model_.accessors.size()) - 1;
  }

  int AddIndices(const std::vector<uint32_t>& indices) {
    const int view = AddView(indices.data(), indices.size() * sizeof(uint32_t),
                             TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
    tinygltf::Accessor accessor;
    accessor.bufferView = view;
    accessor.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    accessor.type = TINYGLTF_TYPE_SCALAR;
    accessor.count = indices.size();
    model_.accessors.push_back(std::move(accessor));
    return static_cast<int>(model_.accessors.size()) - 1;
  }

  tinygltf::Model& model() { return model_; }

  uint64_t buffer_bytes() const { return model_.buffers[0].data.size(); }

 private:
  int AddView(const void* data, size_t bytes, int target) {
    std::vector<unsigned char>& buffer = model_.buffers[0].data;
    while (buffer.size() % 4 != 0) buffer.push_back(0);
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = buffer.size();
    view.byteLength = bytes;
    view.target = target;
    const auto* begin = static_cast<const unsigned char*>(data);
    buffer.insert(buffer.end(), begin, begin + bytes);
    model_.bufferViews.push_back(view);
    return static_cast<int>(model_.bufferViews.size()) - 1;
  }

  tinygltf::Model model_;
};

// Per glb vertex, xyz of `columns` (3 x V, facedyn vertices) times `scale`.
std::vector<float> PerGlbVertex(const GlbTopology& topology, const Eigen::Matrix3Xd& columns,
                                double scale) {
  std::vector<float> values(3 * topology.source_vertex.size());
  for (size_t i = 0; i < topology.source_vertex.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      values[3 * i + k] = static_cast<float>(columns(k, topology.source_vertex[i]) * scale);
    }
  }
  return values;
}

struct MorphMesh {
  std::string name;
  const Mesh* mesh = nullptr;
  Eigen::Matrix3Xd base_mm;
  std::vector<std::string> target_names;
  // Positions of target t (3 x V, mm), produced on demand so a take's frames are not all
  // held twice.
  std::function<Eigen::Matrix3Xd(int)> target_positions_mm;
  // Animation of the morph weights: times from 0 (s) and samples x targets weights.
  std::vector<float> animation_times_s;
  std::vector<float> animation_weights;  // row-major samples x targets
  tinygltf::Value::Object extras;
};

uint64_t EstimateGlbBytes(size_t glb_vertices, size_t triangles, size_t targets, size_t samples,
                          bool uvs) {
  const uint64_t per_vertex = 24 + (uvs ? 8 : 0);
  return static_cast<uint64_t>(glb_vertices) * per_vertex + 12ull * triangles +
         24ull * glb_vertices * targets + 4ull * samples * (targets + 1) + (1ull << 20);
}

StatusOr<GlbSummary> WriteMorphGlb(const MorphMesh& input, const std::string& path,
                                   const std::string& progress_label) {
  const Mesh& mesh = *input.mesh;
  const GlbTopology topology = SplitAtUvSeams(mesh);
  const size_t targets = input.target_names.size();
  const size_t samples = input.animation_times_s.size();
  const uint64_t estimate = EstimateGlbBytes(topology.source_vertex.size(),
                                             topology.triangle_indices.size() / 3, targets,
                                             samples, mesh.has_uvs());
  if (estimate > kMaxGlbBytes) {
    return InvalidArgumentError(fmt::format(
        "{}: {} morph targets of {} vertices make a {:.1f} GB .glb, over glTF's 4 GiB binary "
        "limit; export a take this long as pc2 or mdd",
        path, targets, topology.source_vertex.size(), estimate / 1e9));
  }

  GlbBuilder builder;
  tinygltf::Model& model = builder.model();
  tinygltf::Primitive primitive;
  primitive.mode = TINYGLTF_MODE_TRIANGLES;
  primitive.indices = builder.AddIndices(topology.triangle_indices);
  const Eigen::Matrix3Xd base_normals = VertexNormals(mesh, input.base_mm);
  primitive.attributes["POSITION"] = builder.AddFloats(
      PerGlbVertex(topology, input.base_mm, kMetresPerMm), TINYGLTF_TYPE_VEC3, 3, true,
      TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive.attributes["NORMAL"] = builder.AddFloats(PerGlbVertex(topology, base_normals, 1.0),
                                                     TINYGLTF_TYPE_VEC3, 3, false,
                                                     TINYGLTF_TARGET_ARRAY_BUFFER);
  if (mesh.has_uvs()) {
    // glTF's uv origin is the image's top-left corner, facedyn's (OBJ's) the bottom-left.
    std::vector<float> uvs(2 * topology.uv_index.size(), 0.0f);
    for (size_t i = 0; i < topology.uv_index.size(); ++i) {
      const int uv = topology.uv_index[i];
      if (uv < 0) continue;  // a vertex no face uses
      uvs[2 * i] = static_cast<float>(mesh.uvs(0, uv));
      uvs[2 * i + 1] = static_cast<float>(1.0 - mesh.uvs(1, uv));
    }
    primitive.attributes["TEXCOORD_0"] =
        builder.AddFloats(uvs, TINYGLTF_TYPE_VEC2, 2, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  }
  Progress progress(progress_label, static_cast<long>(targets));
  for (size_t t = 0; t < targets; ++t) {
    const Eigen::Matrix3Xd positions_mm = input.target_positions_mm(static_cast<int>(t));
    const Eigen::Matrix3Xd delta_mm = positions_mm - input.base_mm;
    const Eigen::Matrix3Xd delta_normals = VertexNormals(mesh, positions_mm) - base_normals;
    std::map<std::string, int> target;
    // Morph target POSITION accessors need min and max like any POSITION (glTF 2.0, 3.7.2.1).
    target["POSITION"] = builder.AddFloats(PerGlbVertex(topology, delta_mm, kMetresPerMm),
                                           TINYGLTF_TYPE_VEC3, 3, true,
                                           TINYGLTF_TARGET_ARRAY_BUFFER);
    target["NORMAL"] = builder.AddFloats(PerGlbVertex(topology, delta_normals, 1.0),
                                         TINYGLTF_TYPE_VEC3, 3, false, TINYGLTF_TARGET_ARRAY_BUFFER);
    primitive.targets.push_back(std::move(target));
    progress.Advance();
  }
  progress.Finish();

  tinygltf::Mesh gltf_mesh;
  gltf_mesh.name = input.name;
  gltf_mesh.primitives.push_back(std::move(primitive));
  gltf_mesh.weights.assign(targets, 0.0);
  tinygltf::Value::Object extras = input.extras;
  tinygltf::Value::Array names;
  for (const std::string& name : input.target_names) names.emplace_back(name);
  extras["targetNames"] = tinygltf::Value(std::move(names));
  if (topology.source_vertex.size() > static_cast<size_t>(mesh.vertex_count())) {
    tinygltf::Value::Array seam_sources;
    for (size_t i = mesh.vertex_count(); i < topology.source_vertex.size(); ++i) {
      seam_sources.emplace_back(topology.source_vertex[i]);
    }
    extras["facedyn_seam_source_vertices"] = tinygltf::Value(std::move(seam_sources));
  }
  gltf_mesh.extras = tinygltf::Value(std::move(extras));
  model.meshes.push_back(std::move(gltf_mesh));

  tinygltf::Node node;
  node.name = input.name;
  node.mesh = 0;
  model.nodes.push_back(std::move(node));
  tinygltf::Scene scene;
  scene.name = input.name;
  scene.nodes.push_back(0);
  model.scenes.push_back(std::move(scene));
  model.defaultScene = 0;

  if (samples > 0 && targets > 0) {
    tinygltf::AnimationSampler sampler;
    // Animation inputs need min and max (glTF 2.0, 3.11: "animation.sampler.input").
    sampler.input = builder.AddFloats(input.animation_times_s, TINYGLTF_TYPE_SCALAR, 1, true, 0);
    sampler.output = builder.AddFloats(input.animation_weights, TINYGLTF_TYPE_SCALAR, 1, false, 0);
    sampler.interpolation = "LINEAR";
    tinygltf::AnimationChannel channel;
    channel.sampler = 0;
    channel.target_node = 0;
    channel.target_path = "weights";
    tinygltf::Animation animation;
    animation.name = input.name;
    animation.samplers.push_back(std::move(sampler));
    animation.channels.push_back(std::move(channel));
    model.animations.push_back(std::move(animation));
  }
  model.buffers[0].name = "facedyn";

  std::ostringstream glb;
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToStream(&model, glb, /*prettyPrint=*/false, /*writeBinary=*/true)) {
    return InternalError(path + ": tinygltf could not serialise the glTF document");
  }
  const std::string bytes = glb.str();
  FACEDYN_RETURN_IF_ERROR(WriteFileAtomic(path, bytes));
  GlbSummary summary;
  summary.vertex_count = static_cast<int>(topology.source_vertex.size());
  summary.morph_target_count = static_cast<int>(targets);
  summary.animation_samples = targets > 0 ? static_cast<int>(samples) : 0;
  summary.bytes = bytes.size();
  return summary;
}

}  // namespace

StatusOr<GlbSummary> WriteRigGlb(const FaceRig& rig, const BlendshapeWeightsTrack* animation,
                                 const std::string& path) {
  FACEDYN_RETURN_IF_ERROR(rig.Validate());
  MorphMesh input;
  input.name = rig.name.empty() ? "face" : rig.name;
  input.mesh = &rig.neutral;
  input.base_mm = rig.neutral.positions_mm;
  input.target_names = rig.blendshape_names;
  input.target_positions_mm = [&rig](int t) -> Eigen::Matrix3Xd {
    return rig.neutral.positions_mm + rig.blendshape_deltas_mm[t];
  };
  if (animation != nullptr) {
    FACEDYN_RETURN_IF_ERROR(animation->Validate());
    std::vector<int> rig_column(animation->names.size());
    for (size_t c = 0; c < animation->names.size(); ++c) {
      rig_column[c] = rig.BlendshapeIndex(animation->names[c]);
      if (rig_column[c] < 0) {
        return InvalidArgumentError(fmt::format(
            "the weights name a blendshape '{}' that the rig '{}' does not have ({} shapes)",
            animation->names[c], rig.name, rig.blendshape_names.size()));
      }
    }
    const size_t targets = rig.blendshape_names.size();
    const int samples = animation->sample_count();
    input.animation_times_s.resize(samples);
    input.animation_weights.assign(samples * targets, 0.0f);
    for (int s = 0; s < samples; ++s) {
      // Times from the first sample: players start an animation at 0.
      input.animation_times_s[s] = static_cast<float>(animation->time_s[s] - animation->time_s[0]);
      for (size_t c = 0; c < rig_column.size(); ++c) {
        input.animation_weights[s * targets + rig_column[c]] =
            static_cast<float>(animation->weights(s, static_cast<Eigen::Index>(c)));
      }
    }
    // float32 times must stay strictly increasing or the sampler is invalid.
    for (int s = 1; s < samples; ++s) {
      if (!(input.animation_times_s[s] > input.animation_times_s[s - 1])) {
        return InvalidArgumentError(fmt::format(
            "weights samples {} and {} are {} s apart, closer than float32 time can tell apart",
            s - 1, s, animation->time_s[s] - animation->time_s[s - 1]));
      }
    }
  }
  input.extras["facedyn_kind"] = tinygltf::Value(std::string("face_rig"));
  return WriteMorphGlb(input, path, "export glb (blendshapes)");
}

StatusOr<GlbSummary> WriteTakeGlb(const Take& take, const std::string& path) {
  FACEDYN_RETURN_IF_ERROR(take.Validate());
  MorphMesh input;
  for (const std::string* part : {&take.info.subject, &take.info.expression, &take.info.motion}) {
    if (part->empty()) continue;
    input.name += (input.name.empty() ? "" : "_") + *part;
  }
  if (input.name.empty()) input.name = "take";
  input.mesh = &take.topology;
  input.base_mm = take.FramePositions(0);
  const int frames = take.frame_count();
  for (int f = 1; f < frames; ++f) input.target_names.push_back(fmt::format("frame_{:06d}", f));
  input.target_positions_mm = [&take](int t) -> Eigen::Matrix3Xd { return take.FramePositions(t + 1); };
  if (frames > 1) {
    const size_t targets = static_cast<size_t>(frames - 1);
    input.animation_times_s.resize(frames);
    input.animation_weights.assign(static_cast<size_t>(frames) * targets, 0.0f);
    for (int f = 0; f < frames; ++f) {
      input.animation_times_s[f] = static_cast<float>(take.time_s[f] - take.time_s[0]);
      if (f > 0) input.animation_weights[static_cast<size_t>(f) * targets + (f - 1)] = 1.0f;
      if (f > 0 && !(input.animation_times_s[f] > input.animation_times_s[f - 1])) {
        return InvalidArgumentError(fmt::format(
            "take frames {} and {} are {} s apart, closer than float32 time can tell apart", f - 1,
            f, take.time_s[f] - take.time_s[f - 1]));
      }
    }
  }
  input.extras["facedyn_kind"] = tinygltf::Value(std::string("take"));
  input.extras["facedyn_fps"] = tinygltf::Value(take.info.fps);
  input.extras["facedyn_source"] = tinygltf::Value(take.info.source);
  if (take.info.platform_hz) input.extras["facedyn_platform_hz"] = tinygltf::Value(*take.info.platform_hz);
  return WriteMorphGlb(input, path, "export glb (frames)");
}

}  // namespace facedyn
