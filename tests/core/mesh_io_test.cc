// Mesh: procedural round trips through OBJ and PLY, the in-memory helpers, every bad-input
// path of ReadMesh, and the MediaPipe canonical face from shared/assets.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "core/mesh.h"
#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::ReadBytes;
using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::HasSubstr;

constexpr int kNx = 5;  // grid vertices along x
constexpr int kNy = 4;  // grid vertices along y
constexpr int kSeamColumn = 2;

int GridVertex(int i, int j) { return j * kNx + i; }

// OpenMesh parses OBJ and PLY coordinates into float32, so a round trip keeps positions to
// float precision (~6e-8 relative): within 1e-6 of the largest coordinate's magnitude.
double FloatTolerance(const Eigen::MatrixXd& values) {
  return 1e-6 * std::max(1.0, values.cwiseAbs().maxCoeff());
}

// A 5x4-vertex grid, gently curved, with quads in rows 0 and 2 and triangle pairs in row 1.
// UVs are per corner with a seam along column 2: faces right of it use a second chart whose
// u is shifted by +1, so the seam vertices carry two uvs (as a cylindrical face chart does).
Mesh MakeGridMesh() {
  Mesh mesh;
  mesh.positions_mm.resize(3, kNx * kNy);
  for (int j = 0; j < kNy; ++j) {
    for (int i = 0; i < kNx; ++i) {
      const double x = 10.0 * i + 0.123456 * j, y = 7.5 * j - 0.0314159 * i;
      mesh.positions_mm.col(GridVertex(i, j)) << x, y, 0.01 * x * x - 0.02 * y * y + 3.3;
    }
  }
  const int seam_uv_base = kNx * kNy;
  mesh.uvs.resize(2, kNx * kNy + kNy);
  for (int j = 0; j < kNy; ++j) {
    for (int i = 0; i < kNx; ++i) {
      mesh.uvs.col(GridVertex(i, j)) << 0.25 * i, j / 3.0;
    }
    mesh.uvs.col(seam_uv_base + j) << 0.25 * kSeamColumn + 1.0, j / 3.0;
  }
  auto uv = [&](int i, int j, int face_column) {
    return (i == kSeamColumn && face_column >= kSeamColumn) ? seam_uv_base + j : GridVertex(i, j);
  };
  for (int j = 0; j + 1 < kNy; ++j) {
    for (int i = 0; i + 1 < kNx; ++i) {
      const int a = GridVertex(i, j), b = GridVertex(i + 1, j), c = GridVertex(i + 1, j + 1),
                d = GridVertex(i, j + 1);
      const int ua = uv(i, j, i), ub = uv(i + 1, j, i), uc = uv(i + 1, j + 1, i),
                ud = uv(i, j + 1, i);
      if (j == 1) {
        mesh.AddFace({a, b, c}, {ua, ub, uc});
        mesh.AddFace({a, c, d}, {ua, uc, ud});
      } else {
        mesh.AddFace({a, b, c, d}, {ua, ub, uc, ud});
      }
    }
  }
  return mesh;
}

// Two triangles sharing the edge 1-2, each with its own uv at the shared corners, and a
// vertex (4) no face uses.
Mesh MakeTwoTriangles() {
  Mesh mesh;
  mesh.positions_mm.resize(3, 5);
  mesh.positions_mm << 0, 1, 0, 1, 5,  //
      0, 0, 1, 1, 5,                   //
      0, 0, 0, 0, 5;
  mesh.uvs.resize(2, 6);
  mesh.uvs << 0.0, 0.5, 0.0, 0.9, 0.6, 0.1,  //
      0.0, 0.0, 0.5, 0.9, 0.1, 0.6;
  mesh.AddFace({0, 1, 2}, {0, 1, 2});
  mesh.AddFace({1, 3, 2}, {4, 3, 5});
  return mesh;
}

TEST(MeshAddFace, BuildsCompressedFaceTable) {
  const Mesh mesh = MakeGridMesh();
  EXPECT_EQ(mesh.vertex_count(), 20);
  // Rows 0 and 2: 4 quads each; row 1: 4 quads split in 2 triangles.
  EXPECT_EQ(mesh.face_count(), 4 + 8 + 4);
  EXPECT_EQ(mesh.FaceSize(0), 4);
  EXPECT_EQ(mesh.FaceSize(4), 3);
  EXPECT_EQ(mesh.FaceSize(15), 4);
  EXPECT_EQ(mesh.face_offsets.back(), static_cast<int>(mesh.corner_vertices.size()));
  EXPECT_EQ(mesh.corner_vertices.size(), 4u * 4 + 8u * 3 + 4u * 4);
  EXPECT_EQ(mesh.corner_uvs.size(), mesh.corner_vertices.size());
  EXPECT_TRUE(mesh.has_uvs());
  EXPECT_TRUE(mesh.Validate("grid").ok());
}

TEST(MeshTriangles, FanTriangulatesEveryFace) {
  const Mesh mesh = MakeGridMesh();
  const Eigen::Matrix3Xi triangles = mesh.Triangles();
  EXPECT_EQ(triangles.cols(), 8 * 2 + 8);  // 8 quads -> 2 each, 8 triangles -> 1 each
  // First quad (0, 1, 6, 5) -> (0, 1, 6), (0, 6, 5).
  EXPECT_EQ(triangles.col(0), Eigen::Vector3i(0, 1, 6));
  EXPECT_EQ(triangles.col(1), Eigen::Vector3i(0, 6, 5));
  // Face 4 is the first triangle of row 1: (5, 6, 11).
  EXPECT_EQ(triangles.col(8), Eigen::Vector3i(5, 6, 11));

  Mesh pentagon;
  pentagon.positions_mm = Eigen::Matrix3Xd::Random(3, 5);
  pentagon.AddFace({0, 1, 2, 3, 4});
  EXPECT_EQ(pentagon.Triangles().cols(), 3);
  EXPECT_EQ(pentagon.Triangles().col(2), Eigen::Vector3i(0, 3, 4));
}

TEST(MeshVertexUvs, TakesTheFirstCornerAndNaNForUnusedVertices) {
  const Mesh mesh = MakeTwoTriangles();
  const Eigen::Matrix2Xd uv = mesh.VertexUvs();
  ASSERT_EQ(uv.cols(), 5);
  EXPECT_EQ(uv.col(0), Eigen::Vector2d(0.0, 0.0));
  EXPECT_EQ(uv.col(1), Eigen::Vector2d(0.5, 0.0));  // face 0's uv, not face 1's (0.6, 0.1)
  EXPECT_EQ(uv.col(2), Eigen::Vector2d(0.0, 0.5));  // face 0's uv, not face 1's (0.1, 0.6)
  EXPECT_EQ(uv.col(3), Eigen::Vector2d(0.9, 0.9));
  EXPECT_TRUE(std::isnan(uv(0, 4)) && std::isnan(uv(1, 4)));
}

TEST(MeshVertexUvs, GridSeamVerticesUseTheLeftChart) {
  const Mesh mesh = MakeGridMesh();
  const Eigen::Matrix2Xd uv = mesh.VertexUvs();
  for (int j = 0; j < kNy; ++j) {
    for (int i = 0; i < kNx; ++i) {
      EXPECT_EIGEN_NEAR(uv.col(GridVertex(i, j)), Eigen::Vector2d(0.25 * i, j / 3.0), 1e-15);
    }
  }
}

TEST(MeshValidate, IndexOutOfRange) {
  Mesh mesh = MakeGridMesh();
  mesh.corner_vertices[5] = 20;
  const Status status = mesh.Validate("grid.obj");
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("grid.obj"));
  EXPECT_THAT(status.message(), HasSubstr("face 1 refers to vertex 20 but the mesh has 20"));

  mesh = MakeGridMesh();
  mesh.corner_vertices[0] = -1;
  EXPECT_THAT(mesh.Validate("grid").message(), HasSubstr("face 0 refers to vertex -1"));
}

TEST(MeshValidate, UvIndexOutOfRange) {
  Mesh mesh = MakeGridMesh();
  mesh.corner_uvs[4] = 999;
  EXPECT_THAT(mesh.Validate("grid").message(), HasSubstr("face 1 refers to uv 999"));
}

TEST(MeshValidate, NonFinitePositionAndUv) {
  Mesh mesh = MakeGridMesh();
  mesh.positions_mm(1, 7) = std::numeric_limits<double>::quiet_NaN();
  Status status = mesh.Validate("grid");
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("vertex 7 has a non-finite coordinate"));

  mesh = MakeGridMesh();
  mesh.uvs(0, 3) = std::numeric_limits<double>::infinity();
  status = mesh.Validate("grid");
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("non-finite texture coordinate"));
}

TEST(MeshValidate, InconsistentTables) {
  Mesh mesh = MakeGridMesh();
  mesh.face_offsets.back() += 1;
  EXPECT_THAT(mesh.Validate("grid").message(), HasSubstr("face table is inconsistent"));
  mesh = MakeGridMesh();
  mesh.corner_uvs.pop_back();
  EXPECT_THAT(mesh.Validate("grid").message(), HasSubstr("uv table does not match"));
}

TEST(SameTopology, DetectsDifferences) {
  const Mesh a = MakeGridMesh();
  Mesh b = a;
  b.positions_mm *= 3.0;  // positions may differ
  EXPECT_TRUE(SameTopology(a, b));
  b = a;
  std::swap(b.corner_vertices[0], b.corner_vertices[1]);
  EXPECT_FALSE(SameTopology(a, b));
  b = a;
  b.uvs(0, b.corner_uvs[0]) += 0.01;
  EXPECT_FALSE(SameTopology(a, b));
  b = a;
  b.corner_uvs.clear();
  b.uvs.resize(2, 0);
  EXPECT_FALSE(SameTopology(a, b));
}

TEST(WriteMesh, ObjRoundTrip) {
  TempDir dir;
  const std::string path = dir.Join("grid.obj");
  const Mesh mesh = MakeGridMesh();
  ASSERT_TRUE(WriteMesh(mesh, path).ok());
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp.obj"));
  const auto read = ReadMesh(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->vertex_count(), mesh.vertex_count());
  EXPECT_EQ(read->face_count(), mesh.face_count());
  EXPECT_EQ(read->face_offsets, mesh.face_offsets);
  EXPECT_EQ(read->corner_vertices, mesh.corner_vertices);  // corner order kept
  EXPECT_TRUE(read->has_uvs());
  EXPECT_EQ(read->uvs.cols(), mesh.uvs.cols());  // the seam's extra uvs survive
  EXPECT_TRUE(SameTopology(mesh, *read));
  EXPECT_EIGEN_NEAR(read->positions_mm, mesh.positions_mm, FloatTolerance(mesh.positions_mm));
}

TEST(WriteMesh, PlyRoundTripKeepsPerVertexUvs) {
  TempDir dir;
  const std::string path = dir.Join("grid.ply");
  const Mesh mesh = MakeGridMesh();
  ASSERT_TRUE(WriteMesh(mesh, path).ok());
  const auto read = ReadMesh(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->face_offsets, mesh.face_offsets);
  EXPECT_EQ(read->corner_vertices, mesh.corner_vertices);
  EXPECT_EIGEN_NEAR(read->positions_mm, mesh.positions_mm, FloatTolerance(mesh.positions_mm));
  ASSERT_TRUE(read->has_uvs());
  // One uv per vertex: the seam collapses onto VertexUvs(), so the topology (with its
  // per-corner uv layout) differs from the original but matches the per-vertex version.
  EXPECT_FALSE(SameTopology(mesh, *read));
  EXPECT_EIGEN_NEAR(read->VertexUvs(), mesh.VertexUvs(), 1e-6);
  for (size_t c = 0; c < read->corner_vertices.size(); ++c) {
    EXPECT_EIGEN_NEAR(read->uvs.col(read->corner_uvs[c]),
                      mesh.VertexUvs().col(read->corner_vertices[c]), 1e-6);
  }
}

TEST(WriteMesh, WithoutUvs) {
  TempDir dir;
  Mesh mesh = MakeGridMesh();
  mesh.corner_uvs.clear();
  mesh.uvs.resize(2, 0);
  for (const char* name : {"plain.obj", "plain.ply"}) {
    const std::string path = dir.Join(name);
    ASSERT_TRUE(WriteMesh(mesh, path).ok()) << name;
    const auto read = ReadMesh(path);
    ASSERT_TRUE(read.ok()) << read.status().message();
    EXPECT_FALSE(read->has_uvs()) << name;
    EXPECT_TRUE(SameTopology(mesh, *read)) << name;
  }
}

TEST(WriteMesh, AlternativePositions) {
  TempDir dir;
  const std::string path = dir.Join("frame.obj");
  const Mesh mesh = MakeGridMesh();
  const Eigen::Matrix3Xd moved = (2.0 * mesh.positions_mm).colwise() + Eigen::Vector3d(1, -2, 0.5);
  ASSERT_TRUE(WriteMesh(mesh, moved, path).ok());
  const auto read = ReadMesh(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_TRUE(SameTopology(mesh, *read));
  EXPECT_EIGEN_NEAR(read->positions_mm, moved, FloatTolerance(moved));
  EXPECT_GT((read->positions_mm - mesh.positions_mm).cwiseAbs().maxCoeff(), 1.0);
}

// Every "vt" line of an OBJ as (u, v).
std::vector<Eigen::Vector2d> ObjTexcoords(const std::string& text) {
  std::vector<Eigen::Vector2d> result;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("vt ", 0) != 0) continue;
    std::istringstream words(line.substr(3));
    std::string u, v;
    words >> u >> v;
    result.emplace_back(std::strtod(u.c_str(), nullptr), std::strtod(v.c_str(), nullptr));
  }
  return result;
}

TEST(WriteMesh, ObjTexcoordsAreOnlyTheMeshUvs) {
  // Regression: OpenMesh's OBJ writer also collects the texcoords of boundary halfedges, which
  // WriteMesh never set, so uninitialised memory (often NaN) reached the "vt" table and some
  // files could not be read back. Heap contents vary, so write many times.
  TempDir dir;
  const std::string path = dir.Join("grid.obj");
  for (int round = 0; round < 40; ++round) {
    SCOPED_TRACE("round " + std::to_string(round));
    // Fill freed heap blocks with NaN, as other code in a real process would.
    { std::vector<double> junk(4096, std::numeric_limits<double>::quiet_NaN()); }
    const Mesh mesh = round % 2 ? MakeGridMesh() : MakeTwoTriangles();
    ASSERT_TRUE(WriteMesh(mesh, path).ok());
    const std::string text = ReadBytes(path);
    ASSERT_EQ(text.find("nan"), std::string::npos) << text;
    const std::vector<Eigen::Vector2d> vts = ObjTexcoords(text);
    ASSERT_FALSE(vts.empty());
    for (const Eigen::Vector2d& vt : vts) {
      double nearest = std::numeric_limits<double>::infinity();
      for (int t = 0; t < mesh.uvs.cols(); ++t)
        nearest = std::min(nearest, (mesh.uvs.col(t) - vt).norm());
      // (0, 0) is the placeholder WriteMesh gives a vertex that no face uses.
      nearest = std::min(nearest, vt.norm());
      ASSERT_LT(nearest, 1e-6) << "vt " << vt.transpose() << " is not a uv of the mesh";
    }
    const auto read = ReadMesh(path);
    ASSERT_TRUE(read.ok()) << read.status().message();
    ASSERT_TRUE(SameTopology(mesh, *read));
  }
}

TEST(WriteMesh, UnusedVertexRoundTrips) {
  TempDir dir;
  const Mesh mesh = MakeTwoTriangles();  // vertex 4 is on no face
  for (const char* name : {"two.obj", "two.ply"}) {
    const std::string path = dir.Join(name);
    ASSERT_TRUE(WriteMesh(mesh, path).ok()) << name;
    const auto read = ReadMesh(path);
    ASSERT_TRUE(read.ok()) << read.status().message();
    EXPECT_EQ(read->vertex_count(), 5) << name;
    EXPECT_EQ(read->corner_vertices, mesh.corner_vertices) << name;
    EXPECT_EIGEN_NEAR(read->positions_mm.col(4), Eigen::Vector3d(5, 5, 5), 1e-6);
  }
}

TEST(WriteMesh, UnsupportedExtension) {
  TempDir dir;
  const std::string path = dir.Join("grid.stl");
  const Status status = WriteMesh(MakeGridMesh(), path);
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr(path));
  EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(ReadMesh, ObjCornerOrderAndUvsAsInTheFile) {
  TempDir dir;
  const std::string path = dir.Join("hand.obj");
  WriteBytes(path,
             "# two faces, uv indices differ from vertex indices\n"
             "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
             "vt 0.1 0.2\nvt 0.3 0.4\nvt 0.5 0.6\nvt 0.7 0.8\n"
             "f 2/4 3/3 1/1\n"
             "f 3/3 4/2 1/1\n");
  const auto read = ReadMesh(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->vertex_count(), 4);
  EXPECT_EQ(read->corner_vertices, (std::vector<int>{1, 2, 0, 2, 3, 0}));
  ASSERT_TRUE(read->has_uvs());
  const std::vector<Eigen::Vector2d> expected_uvs = {{0.7, 0.8}, {0.5, 0.6}, {0.1, 0.2},
                                                     {0.5, 0.6}, {0.3, 0.4}, {0.1, 0.2}};
  for (size_t c = 0; c < expected_uvs.size(); ++c) {
    SCOPED_TRACE("corner " + std::to_string(c));
    EXPECT_EIGEN_NEAR(read->uvs.col(read->corner_uvs[c]), expected_uvs[c], 1e-7);
  }
  EXPECT_EIGEN_NEAR(read->positions_mm.col(2), Eigen::Vector3d(1, 1, 0), 0.0);
}

// Every face index is checked against what the file defined before that line, and the error
// names the file, the line and the corner. Before, OpenMesh used these indices unchecked: the
// relative vertex index -9 (of 4) segfaulted, and uv 9 of 3, uv 0, uv -9 or normal 7 of 1 were
// read from outside their arrays and the mesh "loaded" with garbage texture coordinates.
TEST(ReadMesh, ObjFaceIndicesOutOfRangeNameFileAndLine) {
  const std::string header =
      "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n"
      "f 1/1 2/2 3/3\n";  // lines 1-9; the face under test is line 10
  struct Case {
    const char* face;
    const char* expected;
  };
  const Case cases[] = {
      {"f 2/1 4/9 3/3", "corner 2 '4/9' refers to uv 9 but 3 are defined before this line"},
      {"f 2/1 4/0 3/3", "corner 2 '4/0' has uv index 0 (OBJ counts from 1)"},
      {"f 2/1 4/-9 3/3", "corner 2 '4/-9' refers to uv -9 but 3 are defined"},
      {"f -4/-3 -3/-2 -9/-1", "corner 3 '-9/-1' refers to vertex -9 but 4 are defined"},
      {"f 1 2 5", "corner 3 '5' refers to vertex 5 but 4 are defined before this line"},
      {"f 1/1/1 2/2/1 3/3/7", "corner 3 '3/3/7' refers to normal 7 but 1 is defined"},
      {"f 1//1 2//1 3//-5", "corner 3 '3//-5' refers to normal -5 but 1 is defined"},
      {"f 1/1 2/2 3/x", "corner 3 '3/x' has uv index 'x', which is not an integer"},
      {"f 1/1 2/2 3/99999999999999999999", "has uv index 99999999999999999999, far past the 3"},
      {"f 1/1/1/1 2/2 3/3", "corner 1 '1/1/1/1' has more than three"},
      {"f 1/1 2/2 3/3 4", "corner 4 '4' gives uv/normal indices unlike the face's first corner"},
      {"f /1 2/2 3/3", "corner 1 '/1' has no vertex index"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.face);
    TempDir dir;
    const std::string path = dir.Join("bad_corner.obj");
    WriteBytes(path, header + c.face + "\n");
    const auto read = ReadMesh(path);
    ASSERT_FALSE(read.ok());
    EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
    EXPECT_THAT(read.status().message(), HasSubstr(path + ":10: face corner"));
    EXPECT_THAT(read.status().message(), HasSubstr(c.expected));
  }
}

// Relative indices that are in range read like the absolute ones they stand for (the check
// above must not refuse legal OBJ).
TEST(ReadMesh, ObjRelativeIndicesInRangeRead) {
  TempDir dir;
  const std::string absolute = dir.Join("absolute.obj");
  const std::string relative = dir.Join("relative.obj");
  const std::string header =
      "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n";
  WriteBytes(absolute, header + "f 1/1/1 2/2/1 4/3/1\n");
  WriteBytes(relative, header + "f -4/-3/-1 -3/-2/-1 -1/-1/-1\n");
  const auto a = ReadMesh(absolute);
  const auto r = ReadMesh(relative);
  ASSERT_TRUE(a.ok()) << a.status().message();
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(r->corner_vertices, (std::vector<int>{0, 1, 3}));
  EXPECT_TRUE(SameTopology(*a, *r));
}

TEST(ReadMesh, MissingFile) {
  TempDir dir;
  const std::string path = dir.Join("missing.obj");
  const auto read = ReadMesh(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(read.status().message(), HasSubstr(path));
}

TEST(ReadMesh, UnsupportedExtension) {
  TempDir dir;
  const std::string path = dir.Join("mesh.off");
  WriteBytes(path, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  const auto read = ReadMesh(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(read.status().message(), HasSubstr(path));
  EXPECT_THAT(read.status().message(), HasSubstr("unsupported mesh format '.off'"));
}

TEST(ReadMesh, GarbageObj) {
  TempDir dir;
  const std::string path = dir.Join("garbage.obj");
  std::string bytes;
  for (int i = 0; i < 4096; ++i) bytes.push_back(static_cast<char>((i * 7919 + 13) % 256));
  WriteBytes(path, bytes);
  const auto read = ReadMesh(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr(path));
}

TEST(ReadMesh, ObjWithoutVertices) {
  TempDir dir;
  const std::string path = dir.Join("empty.obj");
  WriteBytes(path, "# nothing here\n");
  const auto read = ReadMesh(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr(path));
}

TEST(ReadMesh, ObjFaceReferencesVertexPastTheEnd) {
  TempDir dir;
  const std::string path = dir.Join("bad_index.obj");
  WriteBytes(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 3 9\n");
  const auto read = ReadMesh(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr(path));
  // Caught by the index check before OpenMesh (which drops such a face), so it names the line.
  EXPECT_THAT(read.status().message(),
              HasSubstr(":5: face corner 3 '9' refers to vertex 9 but 3 are defined"));
}

TEST(ReadMesh, PlyFaceReferencesVertexPastTheEnd) {
  TempDir dir;
  const std::string path = dir.Join("bad_index.ply");
  WriteBytes(path,
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
             "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
             "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 7\n");
  const auto read = ReadMesh(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr(path));
  // The ASCII body is checked before OpenMesh reads it: the line and the index are named.
  EXPECT_THAT(read.status().message(),
              HasSubstr(":14: PLY body: face 1: vertex index '7' is not in 0..2"));
}

TEST(ReadMesh, TruncatedPly) {
  TempDir dir;
  const std::string full = dir.Join("full.ply");
  ASSERT_TRUE(WriteMesh(MakeGridMesh(), full).ok());
  const std::string bytes = ReadBytes(full);
  const size_t header_end = bytes.find("end_header\n");
  ASSERT_NE(header_end, std::string::npos);
  const size_t payload = header_end + std::string("end_header\n").size();
  // Cut in the vertex block, and in the face block.
  for (size_t keep : {payload + 10, payload + (bytes.size() - payload) / 2, bytes.size() - 5}) {
    const std::string path = dir.Join("truncated.ply");
    WriteBytes(path, bytes.substr(0, keep));
    const auto read = ReadMesh(path);
    EXPECT_FALSE(read.ok()) << "kept " << keep << " of " << bytes.size() << " bytes";
    if (!read.ok()) {
      EXPECT_THAT(read.status().message(), HasSubstr(path));
    }
  }
}

TEST(ReadMesh, PlyHeaderOnly) {
  TempDir dir;
  const std::string path = dir.Join("header.ply");
  WriteBytes(path,
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
             "property float z\nend_header\n");
  const auto read = ReadMesh(path);
  ASSERT_FALSE(read.ok());
  EXPECT_THAT(read.status().message(), HasSubstr(path));
}

TEST(ReadMesh, MediaPipeCanonicalFace) {
  FACEDYN_REQUIRE_SHARED_ASSET(path, "mediapipe-face/canonical_face_model.obj");
  const auto read = ReadMesh(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  const Mesh& face = *read;
  EXPECT_EQ(face.vertex_count(), 468);
  EXPECT_EQ(face.face_count(), 898);
  EXPECT_EQ(face.Triangles().cols(), 898);
  for (int f = 0; f < face.face_count(); ++f) ASSERT_EQ(face.FaceSize(f), 3) << "face " << f;
  EXPECT_TRUE(face.has_uvs());
  EXPECT_TRUE(face.Validate(path).ok());
  EXPECT_TRUE(face.VertexUvs().allFinite());  // every vertex is on some face
  // The canonical model is centimetre-sized: all coordinates within +-20.
  EXPECT_LT(face.positions_mm.cwiseAbs().maxCoeff(), 20.0);

  TempDir dir;
  const std::string copy = dir.Join("face.obj");
  ASSERT_TRUE(WriteMesh(face, copy).ok());
  const auto again = ReadMesh(copy);
  ASSERT_TRUE(again.ok()) << again.status().message();
  EXPECT_TRUE(SameTopology(face, *again));
  EXPECT_EIGEN_NEAR(again->positions_mm, face.positions_mm, 1e-6);  // coordinates below 10
}

// A PLY header may claim any element count; OpenMesh reserves it before reading, so 2e9
// vertices in a 189-byte file threw std::bad_alloc (fuzz/mesh_ply). Now a DataLoss naming it.
TEST(ReadMesh, PlyElementCountLargerThanTheFileIsCorrupt) {
  TempDir dir;
  const std::string path = dir.Join("huge.ply");
  WriteBytes(path,
             "ply\nformat ascii 1.0\nelement vertex 2000000000\nproperty float x\n"
             "property float y\nproperty float z\nelement face 1\n"
             "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  const auto read = ReadMesh(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr("declares 2000000000 vertex elements"));
}

// OpenMesh skips a "v" line whose three coordinates do not parse as floats; counting it as a
// vertex let "f 1/1 2/2 3/3" through with 2 vertices read, and OpenMesh wrote the third
// vertex's uv past the end of its array (heap overflow under ASan; fuzz/mesh_obj).
TEST(ReadMesh, ObjCoordinateLinesThatDoNotParseNameFileAndLine) {
  for (const char* bad : {"v 0 1", "v nan 0 0", "v 1e50 0 0", "vt 0", "vn 0 0 x"}) {
    SCOPED_TRACE(bad);
    TempDir dir;
    const std::string path = dir.Join("bad_line.obj");
    WriteBytes(path, std::string("v 0 0 0\nv 1 0 0\n") + bad +
                         "\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n");
    const auto read = ReadMesh(path);
    ASSERT_FALSE(read.ok());
    EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
    EXPECT_THAT(read.status().message(), HasSubstr(path + ":3: '"));
    EXPECT_THAT(read.status().message(), HasSubstr("numbers"));
  }
}

// OpenMesh's PLY header reader never returned on some malformed headers ("property list uchar"
// without its index type and name read past end_header and looped at end of file;
// fuzz/mesh_ply). The header grammar is checked first; errors name file and line.
TEST(ReadMesh, MalformedPlyHeaderNamesFileAndLine) {
  const std::string vertex = "element vertex 3\nproperty float x\nproperty float y\n"
                             "property float z\n";
  const std::string body = "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  struct Case {
    std::string text;
    std::string expected;
  };
  const Case cases[] = {
      {"ply\nformat ascii 1.0\n" + vertex + "element face 1\nproperty list uchar\n" + body,
       ":8: PLY header: expected 'property <type> <name>'"},
      {"ply\nformat ascii 1.0\n" + vertex + "element face 1\nproperty list uchar int v\n",
       "PLY header has no end_header line"},
      {"ply\nformat text 1.0\n" + vertex + body, ":2: PLY header: expected 'format"},
      {"ply\nformat ascii 1.0\nproperty float x\n" + body, ":3: PLY header: a property before"},
      {"ply\nformat ascii 1.0\nelement vertex -3\n" + body, ":3: PLY header: expected 'element"},
      {"ply\nformat ascii 1.0\n" + vertex + "frobnicate\n" + body, "unknown header keyword"},
      {"ply\nformat ascii 1.0\nelement veface 1\nproperty list uchar int v\n" + body,
       ":3: PLY header: element 'veface' is not supported"},
      // OpenMesh never returned on these two (fuzz/mesh_ply): a version that is not 1.0, and
      // an ASCII face line whose count is negative and whose values are not numbers.
      {"ply\nformat binary_little_endian \xff.0\n" + vertex + body, ":2: PLY header: expected"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
       "property float z\nelement face 3\nproperty list uchar int vertex_indices\nend_header\n"
       "1 0 0\n-10   \xcf\xf5\xdf\xcc\xcf\xcf\xdf\xe1" "1 7\n",
       ":11: PLY body: face 0: list count '-10' is not an integer in 1..1000"},
      {"ply\nformat ascii 1.0\n" + vertex + "end_header\n0 0 0\n1 x 0\n0 1 0\n",
       ":9: PLY body: vertex 1: 'x' is not a finite number"},
      {"ply\nformat ascii 1.0\n" + vertex + body + "3 0 1 2\n",
       ":11: PLY body: data after the last element: '3'"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.text);
    TempDir dir;
    const std::string path = dir.Join("bad_header.ply");
    WriteBytes(path, c.text);
    const auto read = ReadMesh(path);
    ASSERT_FALSE(read.ok());
    EXPECT_EQ(read.status().code(), StatusCode::kDataLoss);
    EXPECT_THAT(read.status().message(), HasSubstr(c.expected));
  }
}

}  // namespace
}  // namespace facedyn
