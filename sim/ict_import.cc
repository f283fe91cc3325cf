#include "sim/ict_import.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <set>
#include <string_view>

#include "physics/face_anatomy.h"

namespace facedyn::sim {
namespace {

constexpr char kNeutralFile[] = "generic_neutral_mesh.obj";
constexpr int kIctHeadVertexCount = 11248;    // face + head and neck (README: 0..11247)
constexpr int kIctIdentityModes = 4;          // identity000..identity003 ship in the folder
constexpr double kEyeHeightInSkullMm = 15.0;  // the eyes' height above the skull-frame origin

std::string JoinPath(const std::string& dir, const std::string& file) {
  return (std::filesystem::path(dir) / file).string();
}

StatusOr<std::string> ReadWholeFile(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return NotFoundError(path + ": cannot open (" + std::strerror(errno) + ")");
  std::string bytes;
  char buffer[1 << 16];
  size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, f)) > 0) bytes.append(buffer, n);
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) return DataLossError(path + ": read error");
  return bytes;
}

// Parses up to `count` numbers from `line` into `out`; returns how many were read.
int ParseNumbers(std::string_view line, double* out, int count) {
  std::string buffer(line);  // NUL-terminated for strtod
  const char* p = buffer.c_str();
  int k = 0;
  while (k < count) {
    char* end = nullptr;
    const double value = std::strtod(p, &end);
    if (end == p) break;
    if (!std::isfinite(value)) return -1;
    out[k++] = value;
    p = end;
  }
  return k;
}

struct ObjContent {
  Eigen::Matrix3Xd positions;  // the first `keep` vertices
  int vertex_count = 0;        // all 'v' lines
  Eigen::Matrix2Xd uvs;
  std::vector<std::vector<int>> face_vertices;  // 0-based
  std::vector<std::vector<int>> face_uvs;       // 0-based, empty per face when absent
};

// Reads an OBJ: positions of the first `keep` vertices (all when keep < 0), the number of
// vertices, and (with `with_faces`) texture coordinates and faces.
StatusOr<ObjContent> ReadObj(const std::string& path, int keep, bool with_faces) {
  FACEDYN_ASSIGN_OR_RETURN(const std::string bytes, ReadWholeFile(path));
  ObjContent obj;
  std::vector<double> xyz, uv;
  xyz.reserve(3 * static_cast<size_t>(keep > 0 ? keep : 30000));
  size_t pos = 0;
  int line_number = 0;
  while (pos < bytes.size()) {
    size_t end = bytes.find('\n', pos);
    if (end == std::string::npos) end = bytes.size();
    const std::string_view line(bytes.data() + pos, end - pos);
    pos = end + 1;
    ++line_number;
    if (line.size() < 2) continue;
    if (line[0] == 'v' && (line[1] == ' ' || line[1] == '\t')) {
      ++obj.vertex_count;
      if (keep >= 0 && obj.vertex_count > keep) continue;
      double v[3];
      if (ParseNumbers(line.substr(2), v, 3) != 3) {
        return DataLossError(
            fmt::format("{}:{}: vertex line is not three numbers", path, line_number));
      }
      xyz.insert(xyz.end(), v, v + 3);
    } else if (!with_faces) {
      continue;
    } else if (line[0] == 'v' && line[1] == 't') {
      double t[2];
      if (ParseNumbers(line.substr(2), t, 2) != 2) {
        return DataLossError(
            fmt::format("{}:{}: texture coordinate is not two numbers", path, line_number));
      }
      uv.insert(uv.end(), t, t + 2);
    } else if (line[0] == 'f' && (line[1] == ' ' || line[1] == '\t')) {
      std::vector<int> vertices, uvs;
      size_t i = 2;
      while (i < line.size()) {
        while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
        if (i >= line.size()) break;
        size_t j = i;
        while (j < line.size() && !std::isspace(static_cast<unsigned char>(line[j]))) ++j;
        const std::string token(line.substr(i, j - i));
        i = j;
        char* after = nullptr;
        const long v = std::strtol(token.c_str(), &after, 10);
        long t = 0;
        if (*after == '/' && after[1] != '/' && after[1] != '\0')
          t = std::strtol(after + 1, nullptr, 10);
        if (after == token.c_str() || v == 0) {
          return DataLossError(
              fmt::format("{}:{}: bad face corner '{}'", path, line_number, token));
        }
        vertices.push_back(v > 0 ? static_cast<int>(v - 1)
                                 : obj.vertex_count + static_cast<int>(v));
        if (t != 0)
          uvs.push_back(t > 0 ? static_cast<int>(t - 1) : static_cast<int>(uv.size() / 2 + t));
      }
      if (vertices.size() < 3) {
        return DataLossError(
            fmt::format("{}:{}: face with fewer than 3 corners", path, line_number));
      }
      if (!uvs.empty() && uvs.size() != vertices.size()) {
        return DataLossError(
            fmt::format("{}:{}: face has uvs on some corners only", path, line_number));
      }
      obj.face_vertices.push_back(std::move(vertices));
      obj.face_uvs.push_back(std::move(uvs));
    }
  }
  obj.positions =
      Eigen::Map<const Eigen::Matrix3Xd>(xyz.data(), 3, static_cast<Eigen::Index>(xyz.size() / 3));
  obj.uvs =
      Eigen::Map<const Eigen::Matrix2Xd>(uv.data(), 2, static_cast<Eigen::Index>(uv.size() / 2));
  return obj;
}

// Vertices of `path` (first `keep`) after checking it has `expected` vertices in all.
StatusOr<Eigen::Matrix3Xd> ReadShape(const std::string& path, int keep, int expected) {
  FACEDYN_ASSIGN_OR_RETURN(ObjContent obj, ReadObj(path, keep, false));
  if (obj.vertex_count != expected) {
    return FailedPreconditionError(fmt::format(
        "{}: has {} vertices, but {} has {}; ICT-FaceKit shapes must share its topology", path,
        obj.vertex_count, kNeutralFile, expected));
  }
  return std::move(obj.positions);
}

std::string Trim(const std::string& s) {
  size_t a = 0, b = s.size();
  while (a < b && std::isspace(static_cast<unsigned char>(s[a]))) ++a;
  while (b > a && std::isspace(static_cast<unsigned char>(s[b - 1]))) --b;
  return s.substr(a, b - a);
}

struct LoopSummary {
  Eigen::Vector3d centroid;
  Eigen::Vector3d min, max;
  size_t size;
};

}  // namespace

Status IctImportOptions::Check() const {
  if (dir.empty()) return InvalidArgumentError("dir: the ICT-FaceKit folder is not set");
  std::set<std::string> seen;
  for (const auto& [identity, weight] : identity_weights) {
    if (!seen.insert(identity).second) {
      return InvalidArgumentError("identity_weights: '" + identity + "' appears twice");
    }
    if (!std::isfinite(weight) || std::abs(weight) > 10.0) {
      return InvalidArgumentError(
          fmt::format("identity_weights: weight {} of '{}' is not in [-10, 10]", weight, identity));
    }
  }
  return anatomy.Check();
}

StatusOr<std::vector<std::pair<std::string, double>>> ParseIdentitySpec(const std::string& spec) {
  std::vector<std::pair<std::string, double>> result;
  if (Trim(spec).empty()) return result;
  std::set<std::string> seen;
  size_t start = 0;
  while (start <= spec.size()) {
    size_t comma = spec.find(',', start);
    if (comma == std::string::npos) comma = spec.size();
    const std::string item = Trim(spec.substr(start, comma - start));
    start = comma + 1;
    const std::string context = "identity spec '" + spec + "'";
    const size_t colon = item.find(':');
    if (item.empty() || colon == std::string::npos) {
      return InvalidArgumentError(
          fmt::format("{}: item '{}' is not name:weight (e.g. identity000:1.5,identity002:-0.5)",
                      context, item));
    }
    const std::string name = Trim(item.substr(0, colon));
    const std::string number = Trim(item.substr(colon + 1));
    const bool well_formed =
        name.size() == 11 && name.rfind("identity", 0) == 0 &&
        std::all_of(name.begin() + 8, name.end(), [](unsigned char c) { return std::isdigit(c); });
    if (!well_formed || std::stoi(name.substr(8)) >= kIctIdentityModes) {
      return InvalidArgumentError(
          fmt::format("{}: '{}' is not an identity mode; use identity000..identity{:03d}", context,
                      name, kIctIdentityModes - 1));
    }
    char* end = nullptr;
    errno = 0;
    const double weight = std::strtod(number.c_str(), &end);
    if (number.empty() || *end != '\0' || errno != 0 || !std::isfinite(weight) ||
        std::abs(weight) > 10.0) {
      return InvalidArgumentError(
          fmt::format("{}: weight '{}' of {} is not a number in [-10, 10]", context, number, name));
    }
    if (!seen.insert(name).second) {
      return InvalidArgumentError(fmt::format("{}: {} appears twice", context, name));
    }
    result.emplace_back(name, weight);
    if (comma == spec.size()) break;
  }
  return result;
}

StatusOr<FaceRig> ImportIctFaceKit(const IctImportOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  const std::string& dir = options.dir;
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    return NotFoundError("ICT-FaceKit folder '" + dir + "' does not exist or is not a folder");
  }
  const std::string neutral_path = JoinPath(dir, kNeutralFile);
  if (!std::filesystem::is_regular_file(neutral_path, ec)) {
    return NotFoundError(neutral_path + ": missing; is '" + dir + "' the ICT-FaceKit folder?");
  }

  // Neutral: the face region with its faces and uvs, plus the head for the frame.
  FACEDYN_ASSIGN_OR_RETURN(ObjContent neutral, ReadObj(neutral_path, -1, true));
  const int total = neutral.vertex_count;
  if (total < kIctHeadVertexCount) {
    return FailedPreconditionError(
        fmt::format("{}: has {} vertices; the ICT-FaceKit head has {} (face region 0..{})",
                    neutral_path, total, 26719, kIctFaceVertexCount - 1));
  }
  Eigen::Matrix3Xd head = neutral.positions.leftCols(kIctHeadVertexCount) * kIctMmPerUnit;
  const Eigen::Matrix3Xd generic_face = head.leftCols(kIctFaceVertexCount);
  for (const auto& [identity, weight] : options.identity_weights) {
    const std::string path = JoinPath(dir, identity + ".obj");
    if (!std::filesystem::is_regular_file(path, ec)) {
      return NotFoundError(path + ": identity mode file is missing");
    }
    FACEDYN_ASSIGN_OR_RETURN(const Eigen::Matrix3Xd shape,
                             ReadShape(path, kIctHeadVertexCount, total));
    head += weight * (shape * kIctMmPerUnit -
                      neutral.positions.leftCols(kIctHeadVertexCount) * kIctMmPerUnit);
  }

  FaceRig rig;
  rig.name = options.name;
  if (rig.name.empty()) {
    rig.name = "ict";
    for (const auto& [identity, weight] : options.identity_weights)
      rig.name += fmt::format("_{}x{:g}", identity, weight);
  }
  Mesh& mesh = rig.neutral;
  mesh.positions_mm = head.leftCols(kIctFaceVertexCount);
  // Faces entirely inside the face region; uvs renumbered compactly.
  const bool with_uvs = !neutral.face_uvs.empty() &&
                        std::all_of(neutral.face_uvs.begin(), neutral.face_uvs.end(),
                                    [](const std::vector<int>& u) { return !u.empty(); });
  std::vector<int> uv_index(neutral.uvs.cols(), -1);
  std::vector<int> kept_uvs;
  for (size_t f = 0; f < neutral.face_vertices.size(); ++f) {
    const auto& vertices = neutral.face_vertices[f];
    bool inside = true;
    for (int v : vertices) {
      if (v < 0 || v >= total) {
        return DataLossError(fmt::format("{}: face {} refers to vertex {} (file has {})",
                                         neutral_path, f, v + 1, total));
      }
      inside = inside && v < kIctFaceVertexCount;
    }
    if (!inside) continue;
    std::vector<int> uvs;
    if (with_uvs) {
      for (int t : neutral.face_uvs[f]) {
        if (t < 0 || t >= neutral.uvs.cols()) {
          return DataLossError(
              fmt::format("{}: face {} refers to texture coordinate {} (file has {})", neutral_path,
                          f, t + 1, neutral.uvs.cols()));
        }
        if (uv_index[t] < 0) {
          uv_index[t] = static_cast<int>(kept_uvs.size());
          kept_uvs.push_back(t);
        }
        uvs.push_back(uv_index[t]);
      }
    }
    mesh.AddFace(vertices, uvs);
  }
  if (mesh.face_count() == 0)
    return FailedPreconditionError(neutral_path + ": no faces in the face region");
  mesh.uvs.resize(2, static_cast<Eigen::Index>(kept_uvs.size()));
  for (size_t k = 0; k < kept_uvs.size(); ++k) mesh.uvs.col(k) = neutral.uvs.col(kept_uvs[k]);

  // Expressions: every other OBJ of the folder, deltas against the generic neutral.
  std::vector<std::string> stems;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    if (!entry.is_regular_file() || entry.path().extension() != ".obj") continue;
    const std::string stem = entry.path().stem().string();
    if (stem == "generic_neutral_mesh" || stem.rfind("identity", 0) == 0) continue;
    stems.push_back(stem);
  }
  if (ec) return UnavailableError("cannot list '" + dir + "': " + ec.message());
  std::sort(stems.begin(), stems.end());
  if (stems.empty())
    return FailedPreconditionError("ICT-FaceKit folder '" + dir + "' has no expression OBJs");
  for (const auto& stem : stems) {
    FACEDYN_ASSIGN_OR_RETURN(const Eigen::Matrix3Xd shape,
                             ReadShape(JoinPath(dir, stem + ".obj"), kIctFaceVertexCount, total));
    rig.blendshape_names.push_back(stem);
    rig.blendshape_deltas_mm.push_back(shape * kIctMmPerUnit - generic_face);
  }

  // The face's frame from its openings: the outer rim is the longest boundary loop; the eyes are
  // the two largest remaining loops left and right of the midline, the mouth the largest one
  // below them on the midline.
  std::vector<LoopSummary> loops;
  for (const auto& loop : physics::BoundaryLoops(mesh)) {
    LoopSummary s{Eigen::Vector3d::Zero(), Eigen::Vector3d::Constant(1e300),
                  Eigen::Vector3d::Constant(-1e300), loop.size()};
    for (int v : loop) {
      s.centroid += mesh.positions_mm.col(v);
      s.min = s.min.cwiseMin(mesh.positions_mm.col(v));
      s.max = s.max.cwiseMax(mesh.positions_mm.col(v));
    }
    s.centroid /= static_cast<double>(loop.size());
    loops.push_back(s);
  }
  std::sort(loops.begin(), loops.end(),
            [](const LoopSummary& a, const LoopSummary& b) { return a.size > b.size; });
  const LoopSummary* left_eye = nullptr;
  const LoopSummary* right_eye = nullptr;
  const LoopSummary* mouth = nullptr;
  const double mid_x =
      0.5 * (mesh.positions_mm.row(0).minCoeff() + mesh.positions_mm.row(0).maxCoeff());
  for (size_t i = 1; i < loops.size(); ++i) {
    const LoopSummary& s = loops[i];
    const double x = s.centroid.x() - mid_x;
    if (x > 15.0 && left_eye == nullptr) left_eye = &s;
    if (x < -15.0 && right_eye == nullptr) right_eye = &s;
  }
  if (left_eye == nullptr || right_eye == nullptr) {
    return FailedPreconditionError(neutral_path +
                                   ": cannot find the eye openings of the face region");
  }
  const double eye_y = 0.5 * (left_eye->centroid.y() + right_eye->centroid.y());
  for (size_t i = 1; i < loops.size(); ++i) {
    const LoopSummary& s = loops[i];
    if (std::abs(s.centroid.x() - mid_x) < 10.0 && s.centroid.y() < eye_y - 30.0) {
      mouth = &s;
      break;
    }
  }
  if (mouth == nullptr)
    return FailedPreconditionError(neutral_path +
                                   ": cannot find the mouth opening of the face region");

  // Skull frame: x centred between the eyes; z at the middle of the cranium's depth (the head
  // above the eyes, back of the head included); y so the eyes sit kEyeHeightInSkullMm above it.
  const double center_x = 0.5 * (left_eye->centroid.x() + right_eye->centroid.x());
  double z_min = 1e300, z_max = -1e300;
  for (Eigen::Index v = 0; v < head.cols(); ++v) {
    if (head(1, v) > eye_y && std::abs(head(0, v) - center_x) < 30.0) {
      z_min = std::min(z_min, head(2, v));
      z_max = std::max(z_max, head(2, v));
    }
  }
  const Eigen::Vector3d origin(center_x, eye_y - kEyeHeightInSkullMm, 0.5 * (z_min + z_max));
  mesh.positions_mm.colwise() -= origin;
  const Eigen::Vector3d shift = -origin;
  auto in_skull = [&](const Eigen::Vector3d& p) -> Eigen::Vector3d { return p + shift; };
  const Eigen::Matrix3Xd& p = mesh.positions_mm;

  // Nose tip: the most forward vertex near the midline between eyes and mouth.
  int tip = -1;
  for (Eigen::Index v = 0; v < p.cols(); ++v) {
    if (std::abs(p(0, v)) < 10.0 && p(1, v) < kEyeHeightInSkullMm &&
        p(1, v) > in_skull(mouth->centroid).y() && (tip < 0 || p(2, v) > p(2, tip))) {
      tip = static_cast<int>(v);
    }
  }
  if (tip < 0) return FailedPreconditionError(neutral_path + ": cannot find the nose tip");
  const Eigen::Matrix3Xd normals = VertexNormals(mesh, p);
  // Chin bottom (menton): the front-most point of the chin's underside on the midline.
  int menton = -1;
  for (Eigen::Index v = 0; v < p.cols(); ++v) {
    if (std::abs(p(0, v)) < 5.0 && p(1, v) < in_skull(mouth->centroid).y() - 20.0 &&
        normals(1, v) < -0.5 && (menton < 0 || p(2, v) > p(2, menton))) {
      menton = static_cast<int>(v);
    }
  }
  if (menton < 0) return FailedPreconditionError(neutral_path + ": cannot find the chin");
  const double chin_y = p(1, menton);
  double side_x = 0.0;
  for (Eigen::Index v = 0; v < p.cols(); ++v) {
    if (std::abs(p(1, v) - kEyeHeightInSkullMm) < 15.0 && normals(2, v) > 0.0)
      side_x = std::max(side_x, std::abs(p(0, v)));
  }

  physics::FaceLayout layout;
  layout.eye_center_x_mm = 0.5 * (left_eye->centroid.x() - right_eye->centroid.x());
  layout.eye_center_y_mm = kEyeHeightInSkullMm;
  layout.eye_half_width_mm =
      0.25 * ((left_eye->max - left_eye->min).x() + (right_eye->max - right_eye->min).x());
  layout.eye_half_height_mm =
      0.25 * ((left_eye->max - left_eye->min).y() + (right_eye->max - right_eye->min).y());
  layout.brow_y_mm = kEyeHeightInSkullMm + 17.0;
  layout.nose_tip_y_mm = p(1, tip);
  layout.nose_half_width_mm = 17.0;
  layout.mouth_y_mm = in_skull(mouth->centroid).y();
  layout.mouth_half_width_mm = 0.5 * (mouth->max - mouth->min).x();
  layout.chin_y_mm = chin_y;
  layout.temple_max_x_mm = 0.95 * side_x;

  // Jaw: where jawOpen moves the skin by more than a third of its peak; hinge fitted to it.
  const int jaw_shape = rig.BlendshapeIndex("jawOpen");
  Eigen::VectorXd jaw_weight = Eigen::VectorXd::Zero(p.cols());
  if (jaw_shape >= 0) {
    const Eigen::VectorXd moved = rig.blendshape_deltas_mm[jaw_shape].colwise().norm().transpose();
    const double peak = moved.maxCoeff();
    if (peak > 0) jaw_weight = (moved / (0.66 * peak)).cwiseMin(1.0);
  }
  rig.regions = physics::LabelFaceRegions(p, normals, layout, jaw_weight);
  rig.jaw.axis_in_skull = Eigen::Vector3d::UnitX();
  rig.jaw.region = "jaw";
  // Hinge (temporomandibular joint): 10 mm below the ear's centre and 5 mm in front of its
  // front-most point; the ears are the face region's vertices within 15 mm of its widest |x|.
  const double widest = p.row(0).cwiseAbs().maxCoeff();
  double ear_y = 0.0, ear_front_z = -1e300;
  int ear_count = 0;
  for (Eigen::Index v = 0; v < p.cols(); ++v) {
    if (std::abs(p(0, v)) < widest - 15.0) continue;
    ear_y += p(1, v);
    ear_front_z = std::max(ear_front_z, p(2, v));
    ++ear_count;
  }
  rig.jaw.pivot_in_skull = Eigen::Vector3d(0.0, ear_y / ear_count - 10.0, ear_front_z + 5.0);

  FACEDYN_RETURN_IF_ERROR(physics::CompleteFaceAnatomy(options.anatomy, &rig).WithContext(dir));
  FACEDYN_RETURN_IF_ERROR(rig.Validate());
  return rig;
}

}  // namespace facedyn::sim
