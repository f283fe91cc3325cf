#include "core/mesh.h"

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Geometry>  // cross (VertexNormals)
#include <fmt/format.h>

#include "core/file_util.h"
#include "core/utf8.h"

namespace facedyn {
namespace {

struct OmTraits : public OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;
  using Normal = OpenMesh::Vec3d;
  using TexCoord2D = OpenMesh::Vec2d;
};
using OmMesh = OpenMesh::PolyMesh_ArrayKernelT<OmTraits>;

// OpenMesh prints its own diagnostics to omerr; facedyn reports through Status instead.
void SilenceOpenMesh() {
  static const bool silenced = [] {
    omerr().disable();
    omlog().disable();
    omout().disable();
    return true;
  }();
  (void)silenced;
}

// Number of vertices or faces (`element` "vertex" or "face") a file declares, read
// independently of OpenMesh, so a read that renumbered vertices or silently dropped faces
// (OpenMesh skips a face whose vertex index is out of range) can be detected. Returns -1
// when the header cannot be understood.
int DeclaredElementCount(const std::string& path, const std::string& ext,
                         const std::string& element) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return -1;
  std::string line;
  if (ext == ".obj") {
    const char tag = element == "vertex" ? 'v' : 'f';
    int count = 0;
    while (std::getline(in, line)) {
      if (line.size() > 2 && line[0] == tag && (line[1] == ' ' || line[1] == '\t')) ++count;
    }
    return count;
  }
  // PLY: "element <element> N" in the header.
  while (std::getline(in, line)) {
    std::istringstream words(line);
    std::string a, b;
    long n = -1;
    words >> a >> b >> n;
    if (a == "element" && b == element) return n >= 0 && n < std::numeric_limits<int>::max() ? int(n) : -1;
    if (a == "end_header") break;
  }
  return -1;
}

// Checks every index of every OBJ face line before OpenMesh sees the file: OpenMesh
// dereferences them unchecked, so a relative vertex index past the start ("f -4 -3 -9" with 4
// vertices) segfaulted, and a uv or normal index past the end ("f 2/1 4/9 3/3" with 3 uvs) was
// read from outside its array and became a garbage texture coordinate. Each corner is
// "v", "v/vt", "v//vn" or "v/vt/vn" with nonzero integers; negative indices are relative
// (-1 is the last one defined so far). An index must name an element defined before its line,
// which is also all OpenMesh, reading in one pass, can resolve. The OBJ spec requires every
// corner of a face to have a uv when one does (and likewise normals).
Status CheckObjFaceIndices(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return UnavailableError(path + ": cannot read");
  static constexpr const char* kKind[3] = {"vertex", "uv", "normal"};
  int64_t defined[3] = {0, 0, 0};  // v, vt, vn lines so far
  std::string line;
  int64_t line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    std::istringstream words(line);
    std::string tag;
    words >> tag;
    if (tag == "v" || tag == "vt" || tag == "vn") {
      // OpenMesh reads these coordinates as floats and silently skips a "v" line whose three do
      // not parse ("v 0 1", "v nan 0 0", "v 1e50 0 0"), so counting every "v" line made a face
      // index that passed here name a vertex OpenMesh never added, and it wrote that vertex's uv
      // past the end of its array (heap overflow, found by fuzz/mesh_obj). Such a line is an
      // error naming it instead.
      const int kind = tag == "v" ? 0 : tag == "vt" ? 1 : 2;
      const int needed = kind == 1 ? 2 : 3;
      for (int k = 0; k < needed; ++k) {
        float value = 0.0f;
        if (!(words >> value)) {
          return DataLossError(fmt::format(
              "{}:{}: '{}' line does not start with {} numbers (each a finite float)", path,
              line_number, tag, needed));
        }
      }
      ++defined[kind];
    } else if (tag == "f") {
      std::string corner;
      int corner_number = 0;
      bool first_has[3] = {true, false, false};
      while (words >> corner) {
        ++corner_number;
        auto fail = [&](const std::string& why) {
          return DataLossError(fmt::format("{}:{}: face corner {} '{}' {}", path, line_number,
                                           corner_number, corner, why));
        };
        // Split on '/' into at most three fields; an empty field means "not given".
        std::string_view fields[3];
        int field_count = 0;
        size_t start = 0;
        while (true) {
          const size_t slash = corner.find('/', start);
          if (field_count == 3) return fail("has more than three '/'-separated indices");
          fields[field_count++] = std::string_view(corner).substr(
              start, slash == std::string::npos ? slash : slash - start);
          if (slash == std::string::npos) break;
          start = slash + 1;
        }
        bool has[3] = {false, false, false};
        for (int k = 0; k < field_count; ++k) {
          const std::string_view text = fields[k];
          if (text.empty()) {
            if (k == 0) return fail("has no vertex index");
            continue;
          }
          int64_t value = 0;
          const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
          if (error == std::errc::result_out_of_range) {
            return fail(fmt::format("has {} index {}, far past the {} defined before this line",
                                    kKind[k], text, defined[k]));
          }
          if (error != std::errc() || end != text.data() + text.size())
            return fail(fmt::format("has {} index '{}', which is not an integer", kKind[k], text));
          if (value == 0) return fail(fmt::format("has {} index 0 (OBJ counts from 1)", kKind[k]));
          // Relative index -n names the n-th most recent element.
          const int64_t absolute = value > 0 ? value : defined[k] + value + 1;
          if (absolute < 1 || absolute > defined[k]) {
            return fail(fmt::format("refers to {} {} but {} {} defined before this line", kKind[k],
                                    value, defined[k], defined[k] == 1 ? "is" : "are"));
          }
          has[k] = true;
        }
        if (corner_number == 1) {
          std::copy(has, has + 3, first_has);
        } else if (has[1] != first_has[1] || has[2] != first_has[2]) {
          return fail(
              "gives uv/normal indices unlike the face's first corner (a face gives them "
              "for every corner or for none)");
        }
      }
    }
  }
  return Status::Ok();
}

// The body of an ASCII PLY, token by token, against its header: every vertex value a finite
// number, every list a count of 1..1000 followed by that many vertex indices in range, and
// nothing left over. OpenMesh's ASCII reader never returned on a face line whose count was
// "-10" followed by bytes that are not numbers (fuzz/mesh_ply), so it only sees a body that
// passed. `in` is positioned after end_header; `line_number` is end_header's line.
template <typename Elements>
Status CheckPlyAsciiBody(const std::string& path, std::istream& in, int line_number,
                         const Elements& elements) {
  long long vertex_count = 0;
  for (const auto& element : elements)
    if (element.name == "vertex") vertex_count = element.count;
  std::string line;
  std::istringstream tokens;
  auto next = [&](std::string* token) {
    while (!(tokens >> *token)) {
      if (!std::getline(in, line)) return false;
      ++line_number;
      tokens.clear();
      tokens.str(line);
    }
    return true;
  };
  auto fail = [&](const std::string& why) {
    return DataLossError(fmt::format("{}:{}: PLY body: {}", path, line_number, why));
  };
  std::string token;
  for (const auto& element : elements) {
    for (long long item = 0; item < element.count; ++item) {
      for (const bool is_list : element.list_properties) {
        if (!next(&token)) {
          return fail(fmt::format("the file ends in {} {} of {}", element.name, item,
                                  element.count));
        }
        char* end = nullptr;
        if (!is_list) {
          const double value = std::strtod(token.c_str(), &end);
          if (*end != '\0' || !std::isfinite(value))
            return fail(fmt::format("{} {}: '{}' is not a finite number", element.name, item,
                                    EscapeInvalidUtf8(token)));
          continue;
        }
        const long long corners = std::strtoll(token.c_str(), &end, 10);
        if (*end != '\0' || corners < 1 || corners > 1000)
          return fail(fmt::format("{} {}: list count '{}' is not an integer in 1..1000",
                                  element.name, item, EscapeInvalidUtf8(token)));
        for (long long k = 0; k < corners; ++k) {
          if (!next(&token)) return fail(fmt::format("the file ends in {} {}", element.name, item));
          const long long index = std::strtoll(token.c_str(), &end, 10);
          if (*end != '\0' || index < 0 || index >= vertex_count)
            return fail(fmt::format("{} {}: vertex index '{}' is not in 0..{}", element.name, item,
                                    EscapeInvalidUtf8(token), vertex_count - 1));
        }
      }
    }
  }
  if (next(&token)) return fail("data after the last element: '" + EscapeInvalidUtf8(token) + "'");
  return Status::Ok();
}

// Checks a PLY header's grammar before OpenMesh sees it: "ply", a format line, then element,
// property, comment and obj_info lines up to "end_header". OpenMesh's header reader never
// returned on some malformed headers: a "property list uchar" without its index type and name
// made can_u_read read past end_header and loop at the end of the file (found by
// fuzz/mesh_ply). Errors name the file and the line.
Status CheckPlyHeader(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return UnavailableError(path + ": cannot read");
  static const std::set<std::string> kTypes = {
      "char",  "uchar",  "short", "ushort",  "int",    "uint",    "float",   "double",
      "int8",  "uint8",  "int16", "uint16",  "int32",  "uint32",  "float32", "float64"};
  std::string line;
  int line_number = 0;
  bool have_element = false;
  bool ascii = false;
  std::string element;
  struct Element {
    std::string name;
    long long count = 0;
    std::vector<bool> list_properties;  // per property: a list (count then values)?
  };
  std::vector<Element> elements;
  while (std::getline(in, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream stream(line);
    std::vector<std::string> words;
    for (std::string word; stream >> word;) words.push_back(word);
    auto fail = [&](const std::string& why) {
      return DataLossError(fmt::format("{}:{}: PLY header: {}", path, line_number, why));
    };
    if (line_number == 1) {
      if (line != "ply") return fail("the file must start with a line 'ply'");
      continue;
    }
    if (line_number == 2) {
      if (words.size() != 3 || words[0] != "format" ||
          (words[1] != "ascii" && words[1] != "binary_little_endian" &&
           words[1] != "binary_big_endian") ||
          words[2] != "1.0") {
        // 1.0 is the only PLY version; OpenMesh looped forever in can_u_read on a binary file
        // whose version was "\xff.0" (fuzz/mesh_ply).
        return fail("expected 'format ascii|binary_little_endian|binary_big_endian 1.0'");
      }
      ascii = words[1] == "ascii";
      continue;
    }
    if (words.empty()) return fail("empty line");
    const std::string& key = words[0];
    if (key == "comment" || key == "obj_info") continue;
    if (key == "end_header") {
      // Every element takes at least one byte of the file in either encoding: more elements
      // than bytes is a corrupt header (and the ASCII body check would read to the end first).
      std::error_code ec;
      const auto file_bytes = std::filesystem::file_size(path, ec);
      for (const auto& e : elements) {
        if (!ec && e.count > 0 && static_cast<uintmax_t>(e.count) > file_bytes) {
          return DataLossError(fmt::format("{}: declares {} {} elements in a file of {} bytes "
                                           "(corrupt header)",
                                           path, e.count, e.name, file_bytes));
        }
      }
      return ascii ? CheckPlyAsciiBody(path, in, line_number, elements) : Status::Ok();
    }
    if (key == "element") {
      long long count = -1;
      std::istringstream number(words.size() == 3 ? words[2] : "");
      if (words.size() != 3 || !(number >> count) || !number.eof() || count < 0) {
        return fail("expected 'element <name> <count>' with a count >= 0");
      }
      // facedyn meshes have vertices and faces only; OpenMesh also looped forever on a header
      // whose only element was an unknown one carrying a list property (fuzz/mesh_ply).
      if (words[1] != "vertex" && words[1] != "face") {
        return fail("element '" + words[1] + "' is not supported (only vertex and face)");
      }
      element = words[1];
      have_element = true;
      elements.push_back({element, count, {}});
    } else if (key == "property") {
      if (!have_element) return fail("a property before any element");
      const bool is_list = words.size() >= 2 && words[1] == "list";
      if (is_list != (element == "face")) {
        return fail(element == "face" ? "a face's property must be a list"
                                      : "a vertex property must not be a list");
      }
      const bool ok = is_list ? words.size() == 5 && kTypes.count(words[2]) && kTypes.count(words[3])
                              : words.size() == 3 && kTypes.count(words[1]);
      if (!ok) {
        return fail("expected 'property <type> <name>' or 'property list <count type> <type> "
                    "<name>' with known types");
      }
      elements.back().list_properties.push_back(is_list);
    } else {
      return fail("unknown header keyword '" + key + "'");
    }
  }
  return DataLossError(path + ": PLY header has no end_header line");
}

}  // namespace

void Mesh::AddFace(const std::vector<int>& vertices, const std::vector<int>& uv_indices) {
  FACEDYN_CHECK(vertices.size() >= 3, "a face needs at least 3 corners");
  FACEDYN_CHECK(uv_indices.empty() || uv_indices.size() == vertices.size(),
                "uv indices must match the face's corners");
  FACEDYN_CHECK(uv_indices.empty() == corner_uvs.empty() || face_count() == 0,
                "all faces must have uvs, or none");
  corner_vertices.insert(corner_vertices.end(), vertices.begin(), vertices.end());
  corner_uvs.insert(corner_uvs.end(), uv_indices.begin(), uv_indices.end());
  face_offsets.push_back(static_cast<int>(corner_vertices.size()));
}

Eigen::Matrix3Xi Mesh::Triangles() const {
  int count = 0;
  for (int f = 0; f < face_count(); ++f) count += FaceSize(f) - 2;
  Eigen::Matrix3Xi triangles(3, count);
  int t = 0;
  for (int f = 0; f < face_count(); ++f) {
    const int* c = corner_vertices.data() + face_offsets[f];
    for (int k = 1; k + 1 < FaceSize(f); ++k) triangles.col(t++) << c[0], c[k], c[k + 1];
  }
  return triangles;
}

Eigen::Matrix2Xd Mesh::VertexUvs() const {
  FACEDYN_CHECK(has_uvs(), "VertexUvs needs a mesh with uvs");
  Eigen::Matrix2Xd result =
      Eigen::Matrix2Xd::Constant(2, vertex_count(), std::numeric_limits<double>::quiet_NaN());
  std::vector<bool> seen(vertex_count(), false);
  for (size_t c = 0; c < corner_vertices.size(); ++c) {
    const int v = corner_vertices[c];
    if (!seen[v]) {
      result.col(v) = uvs.col(corner_uvs[c]);
      seen[v] = true;
    }
  }
  return result;
}

Status Mesh::Validate(const std::string& what) const {
  if (face_offsets.empty() || face_offsets.front() != 0 ||
      face_offsets.back() != static_cast<int>(corner_vertices.size())) {
    return FailedPreconditionError(what + ": face table is inconsistent");
  }
  if (!corner_uvs.empty() && corner_uvs.size() != corner_vertices.size()) {
    return FailedPreconditionError(what + ": uv table does not match the face corners");
  }
  for (int v = 0; v < vertex_count(); ++v) {
    if (!positions_mm.col(v).allFinite()) {
      return DataLossError(fmt::format("{}: vertex {} has a non-finite coordinate", what, v));
    }
  }
  for (int f = 0; f < face_count(); ++f) {
    if (FaceSize(f) < 3) return DataLossError(fmt::format("{}: face {} has fewer than 3 corners", what, f));
    for (int c = face_offsets[f]; c < face_offsets[f + 1]; ++c) {
      if (corner_vertices[c] < 0 || corner_vertices[c] >= vertex_count()) {
        return DataLossError(fmt::format("{}: face {} refers to vertex {} but the mesh has {}", what,
                                         f, corner_vertices[c], vertex_count()));
      }
      if (has_uvs() && (corner_uvs[c] < 0 || corner_uvs[c] >= uvs.cols())) {
        return DataLossError(fmt::format("{}: face {} refers to uv {} but the mesh has {}", what, f,
                                         corner_uvs[c], uvs.cols()));
      }
    }
  }
  if (has_uvs() && !uvs.allFinite()) return DataLossError(what + ": non-finite texture coordinate");
  return Status::Ok();
}

bool SameTopology(const Mesh& a, const Mesh& b) {
  if (a.vertex_count() != b.vertex_count() || a.face_offsets != b.face_offsets ||
      a.corner_vertices != b.corner_vertices || a.has_uvs() != b.has_uvs()) {
    return false;
  }
  if (!a.has_uvs()) return true;
  // uv tables may be numbered differently; compare the uv values at each corner.
  for (size_t c = 0; c < a.corner_uvs.size(); ++c) {
    if (!a.uvs.col(a.corner_uvs[c]).isApprox(b.uvs.col(b.corner_uvs[c]), 1e-6) &&
        (a.uvs.col(a.corner_uvs[c]) - b.uvs.col(b.corner_uvs[c])).norm() > 1e-6) {
      return false;
    }
  }
  return true;
}

StatusOr<Mesh> ReadMesh(const std::string& path) {
  SilenceOpenMesh();
  const std::string ext = LowercaseExtension(path);
  if (ext != ".obj" && ext != ".ply") {
    return InvalidArgumentError(path + ": unsupported mesh format '" + ext + "' (use .obj or .ply)");
  }
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return NotFoundError(path + ": no such file");

  if (ext == ".obj") FACEDYN_RETURN_IF_ERROR(CheckObjFaceIndices(path));
  // OpenMesh reserves a PLY's declared element counts before reading one element, so a header
  // claiming 2e9 vertices threw std::bad_alloc out of read_mesh (found by fuzz/mesh_ply). Every
  // element takes at least one byte of the file in either encoding: more elements than bytes is
  // a corrupt header.
  if (ext == ".ply") {
    FACEDYN_RETURN_IF_ERROR(CheckPlyHeader(path));
    const auto file_bytes = std::filesystem::file_size(path, ec);
    for (const char* element : {"vertex", "face"}) {
      const int declared = DeclaredElementCount(path, ext, element);
      if (!ec && declared > 0 && static_cast<uintmax_t>(declared) > file_bytes) {
        return DataLossError(fmt::format("{}: declares {} {} elements in a file of {} bytes "
                                         "(corrupt header)",
                                         path, declared, element, file_bytes));
      }
    }
  }
  OmMesh om;
  om.request_vertex_texcoords2D();
  om.request_halfedge_texcoords2D();
  OpenMesh::IO::Options options;
  options += OpenMesh::IO::Options::VertexTexCoord;
  options += OpenMesh::IO::Options::FaceTexCoord;
  if (!OpenMesh::IO::read_mesh(om, path, options)) {
    return DataLossError(path + ": not a readable " + ext.substr(1) + " mesh (corrupt or truncated)");
  }
  const int declared = DeclaredElementCount(path, ext, "vertex");
  if (declared >= 0 && declared != static_cast<int>(om.n_vertices())) {
    return DataLossError(fmt::format(
        "{}: declares {} vertices but {} could be read (truncated file, or non-manifold faces "
        "that would need duplicated vertices)",
        path, declared, om.n_vertices()));
  }
  const int declared_faces = DeclaredElementCount(path, ext, "face");
  if (declared_faces >= 0 && declared_faces != static_cast<int>(om.n_faces())) {
    return DataLossError(fmt::format(
        "{}: declares {} faces but {} could be read (a face refers to a vertex that does not "
        "exist, or is degenerate)",
        path, declared_faces, om.n_faces()));
  }
  if (om.n_vertices() == 0) return DataLossError(path + ": mesh has no vertices");

  Mesh mesh;
  mesh.positions_mm.resize(3, om.n_vertices());
  for (auto vh : om.vertices()) {
    const auto& p = om.point(vh);
    mesh.positions_mm.col(vh.idx()) << p[0], p[1], p[2];
  }
  const bool corner_uvs = options.check(OpenMesh::IO::Options::FaceTexCoord);
  const bool vertex_uvs = !corner_uvs && options.check(OpenMesh::IO::Options::VertexTexCoord);
  std::map<std::pair<double, double>, int> uv_index;  // dedupe corner uvs by value
  std::vector<std::pair<double, double>> uv_values;
  auto uv_id = [&](const OpenMesh::Vec2d& uv) {
    const auto key = std::make_pair(uv[0], uv[1]);
    auto [it, inserted] = uv_index.emplace(key, static_cast<int>(uv_values.size()));
    if (inserted) uv_values.push_back(key);
    return it->second;
  };
  std::vector<int> vertices, uvs;
  for (auto fh : om.faces()) {
    vertices.clear();
    uvs.clear();
    for (auto heh : om.fh_range(fh)) {
      const auto vh = om.to_vertex_handle(heh);
      vertices.push_back(vh.idx());
      if (corner_uvs) uvs.push_back(uv_id(om.texcoord2D(heh)));
      if (vertex_uvs) uvs.push_back(uv_id(om.texcoord2D(vh)));
    }
    // OpenMesh's face circulator starts at the face's first corner as it was added, so the
    // corner order matches the file (checked by the round-trip tests).
    mesh.AddFace(vertices, uvs);
  }
  if (!uv_values.empty()) {
    mesh.uvs.resize(2, uv_values.size());
    for (size_t i = 0; i < uv_values.size(); ++i) mesh.uvs.col(i) << uv_values[i].first, uv_values[i].second;
  }
  FACEDYN_RETURN_IF_ERROR(mesh.Validate(path));
  return mesh;
}

Status WriteMesh(const Mesh& mesh, const std::string& path) {
  return WriteMesh(mesh, mesh.positions_mm, path);
}

Status WriteMesh(const Mesh& mesh, const Eigen::Matrix3Xd& positions_mm, const std::string& path) {
  SilenceOpenMesh();
  FACEDYN_CHECK(positions_mm.cols() == mesh.vertex_count(), "positions must match the mesh");
  const std::string ext = LowercaseExtension(path);
  if (ext != ".obj" && ext != ".ply") {
    return InvalidArgumentError(path + ": unsupported mesh format '" + ext + "' (use .obj or .ply)");
  }
  OmMesh om;
  om.request_vertex_texcoords2D();
  om.request_halfedge_texcoords2D();
  std::vector<OmMesh::VertexHandle> handles(mesh.vertex_count());
  for (int v = 0; v < mesh.vertex_count(); ++v) {
    handles[v] = om.add_vertex(OmMesh::Point(positions_mm(0, v), positions_mm(1, v), positions_mm(2, v)));
  }
  const Eigen::Matrix2Xd vertex_uvs = mesh.has_uvs() ? mesh.VertexUvs() : Eigen::Matrix2Xd();
  std::vector<OmMesh::VertexHandle> face;
  for (int f = 0; f < mesh.face_count(); ++f) {
    face.clear();
    for (int c = mesh.face_offsets[f]; c < mesh.face_offsets[f + 1]; ++c) {
      face.push_back(handles[mesh.corner_vertices[c]]);
    }
    const auto fh = om.add_face(face);
    if (!fh.is_valid()) {
      return FailedPreconditionError(
          fmt::format("{}: face {} is non-manifold and cannot be written", path, f));
    }
    if (!mesh.has_uvs()) continue;
    for (auto heh : om.fh_range(fh)) {
      const int v = om.to_vertex_handle(heh).idx();
      for (int c = mesh.face_offsets[f]; c < mesh.face_offsets[f + 1]; ++c) {
        if (mesh.corner_vertices[c] == v) {
          const auto uv = mesh.uvs.col(mesh.corner_uvs[c]);
          om.set_texcoord2D(heh, OmMesh::TexCoord2D(uv[0], uv[1]));
          break;
        }
      }
    }
  }
  OpenMesh::IO::Options options;
  if (mesh.has_uvs()) {
    // OpenMesh's texcoord properties start uninitialised, and its OBJ writer collects the
    // texcoords of every vertex and every halfedge (boundary halfedges included) into its "vt"
    // table, so each one must hold a finite value or garbage/NaN reaches the file. A vertex no
    // face uses gets (0, 0); a boundary halfedge gets its vertex's uv (already in the table).
    for (int v = 0; v < mesh.vertex_count(); ++v) {
      const bool used = vertex_uvs.col(v).allFinite();
      om.set_texcoord2D(handles[v], used ? OmMesh::TexCoord2D(vertex_uvs(0, v), vertex_uvs(1, v))
                                         : OmMesh::TexCoord2D(0.0, 0.0));
    }
    for (auto heh : om.halfedges()) {
      if (om.is_boundary(heh)) om.set_texcoord2D(heh, om.texcoord2D(om.to_vertex_handle(heh)));
    }
    options += OpenMesh::IO::Options::VertexTexCoord;
    if (ext == ".obj") options += OpenMesh::IO::Options::FaceTexCoord;
  }
  if (ext == ".ply") options += OpenMesh::IO::Options::Binary;
  const std::string tmp = path + ".tmp" + ext;
  if (!OpenMesh::IO::write_mesh(om, tmp, options, /*precision=*/9)) {
    std::filesystem::remove(tmp);
    return UnavailableError(path + ": cannot write mesh");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) return UnavailableError(path + ": cannot move mesh into place: " + ec.message());
  return Status::Ok();
}

Eigen::Matrix3Xd VertexNormals(const Mesh& mesh, const Eigen::Matrix3Xd& positions_mm) {
  Eigen::Matrix3Xd normals = Eigen::Matrix3Xd::Zero(3, positions_mm.cols());
  const Eigen::Matrix3Xi triangles = mesh.Triangles();
  for (Eigen::Index t = 0; t < triangles.cols(); ++t) {
    const Eigen::Vector3d a = positions_mm.col(triangles(0, t));
    const Eigen::Vector3d n =
        (positions_mm.col(triangles(1, t)) - a).cross(positions_mm.col(triangles(2, t)) - a);
    for (int k = 0; k < 3; ++k) normals.col(triangles(k, t)) += n;  // |n| = 2 * area
  }
  for (Eigen::Index v = 0; v < normals.cols(); ++v) {
    const double n = normals.col(v).norm();
    if (n > 1e-12) {
      normals.col(v) /= n;
    } else {
      normals.col(v) = Eigen::Vector3d::UnitZ();
    }
  }
  return normals;
}

}  // namespace facedyn
