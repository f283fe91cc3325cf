#include "core/face_rig.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>

#include <fmt/format.h>

#include "core/config_node.h"
#include "core/csv.h"
#include "core/file_util.h"
#include "core/json_io.h"
#include "core/pc2.h"

namespace facedyn {
namespace {

constexpr char kSamplesHeader[] = "v0,v1,v2,w0,w1,w2";
constexpr char kMarkersHeader[] = "name,v0,v1,v2,w0,w1,w2,diameter_mm";
constexpr double kBarycentricTolerance = 1e-6;

Status CheckSurfacePoint(const SurfacePoint& p, int vertex_count, const std::string& what) {
  for (int v : p.vertices) {
    if (v < 0 || v >= vertex_count) {
      return FailedPreconditionError(fmt::format("{}: vertex {} out of range (mesh has {})", what, v, vertex_count));
    }
  }
  if (!p.weights.allFinite() || std::abs(p.weights.sum() - 1.0) > kBarycentricTolerance ||
      p.weights.minCoeff() < -kBarycentricTolerance) {
    return FailedPreconditionError(fmt::format("{}: weights ({}, {}, {}) are not barycentric", what,
                                               p.weights[0], p.weights[1], p.weights[2]));
  }
  return Status::Ok();
}

// Reads the v0,v1,v2,w0,w1,w2 columns starting at `first`.
StatusOr<SurfacePoint> ReadSurfacePoint(const CsvTable& table, size_t row, size_t first, int vertex_count) {
  SurfacePoint p;
  for (int i = 0; i < 3; ++i) {
    FACEDYN_ASSIGN_OR_RETURN(p.vertices[i], table.Integer(row, first + i));
    FACEDYN_ASSIGN_OR_RETURN(p.weights[i], table.Number(row, first + 3 + i));
  }
  const Status ok = CheckSurfacePoint(p, vertex_count, "point");
  if (!ok.ok()) return table.RowError(row, ok.message());
  return p;
}

std::string SurfacePointCsv(const SurfacePoint& p) {
  return fmt::format("{},{},{},{:.9g},{:.9g},{:.9g}", p.vertices[0], p.vertices[1], p.vertices[2],
                     p.weights[0], p.weights[1], p.weights[2]);
}

StatusOr<Eigen::Vector3d> ReadVector3(const ConfigNode& node, const std::string& key) {
  FACEDYN_ASSIGN_OR_RETURN(const std::vector<double> v, node.Get<std::vector<double>>(key));
  if (v.size() != 3) return node.Error(key, fmt::format("expected [x, y, z], got {} numbers", v.size()));
  return Eigen::Vector3d(v[0], v[1], v[2]);
}

Json Vector3Json(const Eigen::Vector3d& v) { return Json::array({v.x(), v.y(), v.z()}); }

}  // namespace

int FaceRig::BlendshapeIndex(const std::string& shape) const {
  for (size_t i = 0; i < blendshape_names.size(); ++i) {
    if (blendshape_names[i] == shape) return static_cast<int>(i);
  }
  return -1;
}

Eigen::Matrix3Xd FaceRig::Evaluate(const Eigen::VectorXd& weights) const {
  FACEDYN_CHECK(weights.size() == static_cast<Eigen::Index>(blendshape_deltas_mm.size()),
                "one weight per blendshape");
  Eigen::Matrix3Xd positions = neutral.positions_mm;
  for (Eigen::Index k = 0; k < weights.size(); ++k) {
    if (weights[k] != 0.0) positions += weights[k] * blendshape_deltas_mm[k];
  }
  return positions;
}

Eigen::Matrix3Xd FaceRig::SamplePositions(const Eigen::Matrix3Xd& skin_positions) const {
  Eigen::Matrix3Xd samples(3, skin_samples.size());
  for (size_t i = 0; i < skin_samples.size(); ++i) samples.col(i) = skin_samples[i].Evaluate(skin_positions);
  return samples;
}

Status FaceRig::Validate() const {
  const std::string what = "face rig '" + name + "'";
  FACEDYN_RETURN_IF_ERROR(neutral.Validate(what + " neutral mesh"));
  if (skull.vertex_count() > 0) FACEDYN_RETURN_IF_ERROR(skull.Validate(what + " skull mesh"));
  if (blendshape_names.size() != blendshape_deltas_mm.size()) {
    return FailedPreconditionError(what + ": blendshape names and deltas differ in number");
  }
  std::set<std::string> names;
  for (size_t k = 0; k < blendshape_names.size(); ++k) {
    if (!names.insert(blendshape_names[k]).second) {
      return FailedPreconditionError(what + ": blendshape '" + blendshape_names[k] + "' appears twice");
    }
    if (blendshape_deltas_mm[k].cols() != vertex_count() || !blendshape_deltas_mm[k].allFinite()) {
      return FailedPreconditionError(what + ": blendshape '" + blendshape_names[k] +
                                     "' does not match the neutral mesh or is not finite");
    }
  }
  for (const auto& landmark : skull_landmarks) {
    if (!landmark.position_in_skull.allFinite()) {
      return FailedPreconditionError(what + ": landmark '" + landmark.name + "' is not finite");
    }
  }
  for (size_t i = 0; i < skin_samples.size(); ++i) {
    FACEDYN_RETURN_IF_ERROR(CheckSurfacePoint(skin_samples[i], vertex_count(), fmt::format("{}: skin sample {}", what, i)));
  }
  for (const auto& marker : markers) {
    // markers.csv has no quoting, so such a name would save into a file that cannot be read.
    if (marker.name.find_first_of(",\r\n") != std::string::npos) {
      return FailedPreconditionError(what + ": marker name '" + marker.name +
                                     "' cannot be stored in markers.csv (no commas or line breaks)");
    }
    FACEDYN_RETURN_IF_ERROR(CheckSurfacePoint(marker.point, vertex_count(), what + ": marker " + marker.name));
    if (!(marker.diameter_mm > 0)) return FailedPreconditionError(what + ": marker " + marker.name + " has no size");
  }
  for (const auto& [region, vertices] : regions) {
    for (int v : vertices) {
      if (v < 0 || v >= vertex_count()) {
        return FailedPreconditionError(fmt::format("{}: region '{}' has vertex {} out of range", what, region, v));
      }
    }
  }
  for (const auto& region : stable_regions) {
    if (!regions.count(region)) return FailedPreconditionError(what + ": stable region '" + region + "' is not defined");
  }
  if (!jaw.region.empty() && !regions.count(jaw.region)) {
    return FailedPreconditionError(what + ": jaw region '" + jaw.region + "' is not defined");
  }
  if (std::abs(jaw.axis_in_skull.norm() - 1.0) > 1e-6) {
    return FailedPreconditionError(what + ": jaw axis must be a unit vector");
  }
  return Status::Ok();
}

StatusOr<FaceRig> LoadFaceRig(const std::string& dir) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return NotFoundError(dir + ": no such face rig folder");
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode json, ConfigNode::ReadFile(JoinPath(dir, "face_rig.json")));
  if (!json.IsMap()) return json.Error("expected a JSON object");
  FACEDYN_ASSIGN_OR_RETURN(const int version, json.Get<int>("format_version"));
  if (version != kFaceRigFormatVersion) {
    return json.Error("format_version", fmt::format("version {} is not supported", version));
  }
  FACEDYN_ASSIGN_OR_RETURN(const std::string units, json.Get<std::string>("units"));
  if (units != "mm") return json.Error("units", "'" + units + "' is not supported; face rigs are in mm");

  FaceRig rig;
  FACEDYN_ASSIGN_OR_RETURN(rig.name, json.Get<std::string>("name"));
  FACEDYN_ASSIGN_OR_RETURN(rig.neutral, ReadMesh(JoinPath(dir, "neutral.obj")));
  const int vertex_count = rig.neutral.vertex_count();
  FACEDYN_ASSIGN_OR_RETURN(rig.blendshape_names, json.GetOr<std::vector<std::string>>("blendshapes", {}));
  if (!rig.blendshape_names.empty()) {
    const std::string path = JoinPath(dir, "blendshapes.pc2");
    FACEDYN_ASSIGN_OR_RETURN(const PointCache deltas, ReadPc2(path));
    if (deltas.vertex_count != vertex_count || deltas.frame_count() != int(rig.blendshape_names.size())) {
      return FailedPreconditionError(fmt::format(
          "{}: holds {} shapes of {} vertices; face_rig.json names {} shapes, neutral.obj has {} vertices",
          path, deltas.frame_count(), deltas.vertex_count, rig.blendshape_names.size(), vertex_count));
    }
    for (int k = 0; k < deltas.frame_count(); ++k) rig.blendshape_deltas_mm.push_back(deltas.Frame(k).cast<double>());
  }
  const std::string skull_path = JoinPath(dir, "skull.obj");
  if (std::filesystem::exists(skull_path, ec)) {
    FACEDYN_ASSIGN_OR_RETURN(rig.skull, ReadMesh(skull_path));
  }

  if (json.Has("skull_landmarks")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode landmarks, json.Child("skull_landmarks"));
    if (!landmarks.IsSequence()) return json.Error("skull_landmarks", "expected a list");
    for (size_t i = 0; i < landmarks.size(); ++i) {
      FACEDYN_ASSIGN_OR_RETURN(const ConfigNode item, landmarks.At(i));
      SkullLandmark landmark;
      FACEDYN_ASSIGN_OR_RETURN(landmark.name, item.Get<std::string>("name"));
      FACEDYN_ASSIGN_OR_RETURN(landmark.position_in_skull, ReadVector3(item, "position_in_skull"));
      rig.skull_landmarks.push_back(landmark);
    }
  }
  if (json.Has("regions")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode regions, json.Child("regions"));
    if (!regions.IsMap()) return json.Error("regions", "expected an object of vertex lists");
    for (const auto& region : regions.Keys()) {
      FACEDYN_ASSIGN_OR_RETURN(rig.regions[region], regions.Get<std::vector<int>>(region));
      for (int v : rig.regions[region]) {
        if (v < 0 || v >= vertex_count) {
          return regions.Error(region, fmt::format("vertex {} out of range (neutral.obj has {})", v, vertex_count));
        }
      }
    }
  }
  FACEDYN_ASSIGN_OR_RETURN(rig.stable_regions, json.GetOr<std::vector<std::string>>("stable_regions", {}));
  if (json.Has("jaw")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode jaw, json.Child("jaw"));
    FACEDYN_ASSIGN_OR_RETURN(rig.jaw.pivot_in_skull, ReadVector3(jaw, "pivot_in_skull"));
    FACEDYN_ASSIGN_OR_RETURN(rig.jaw.axis_in_skull, ReadVector3(jaw, "axis_in_skull"));
    if (rig.jaw.axis_in_skull.norm() < 1e-9) return jaw.Error("axis_in_skull", "must be non-zero");
    rig.jaw.axis_in_skull.normalize();
    FACEDYN_ASSIGN_OR_RETURN(rig.jaw.region, jaw.GetOr<std::string>("region", ""));
  }

  const std::string samples_path = JoinPath(dir, "skin_samples.csv");
  if (std::filesystem::exists(samples_path, ec)) {
    FACEDYN_ASSIGN_OR_RETURN(const CsvTable samples, CsvTable::Read(samples_path, kSamplesHeader));
    for (size_t row = 0; row < samples.row_count(); ++row) {
      FACEDYN_ASSIGN_OR_RETURN(SurfacePoint p, ReadSurfacePoint(samples, row, 0, vertex_count));
      rig.skin_samples.push_back(p);
    }
  }
  const std::string markers_path = JoinPath(dir, "markers.csv");
  if (std::filesystem::exists(markers_path, ec)) {
    FACEDYN_ASSIGN_OR_RETURN(const CsvTable markers, CsvTable::Read(markers_path, kMarkersHeader));
    for (size_t row = 0; row < markers.row_count(); ++row) {
      Marker marker;
      marker.name = markers.Text(row, 0);
      FACEDYN_ASSIGN_OR_RETURN(marker.point, ReadSurfacePoint(markers, row, 1, vertex_count));
      FACEDYN_ASSIGN_OR_RETURN(marker.diameter_mm, markers.Number(row, 7));
      rig.markers.push_back(marker);
    }
  }
  FACEDYN_RETURN_IF_ERROR(rig.Validate().WithContext(dir));
  return rig;
}

Status SaveFaceRig(const FaceRig& rig, const std::string& dir) {
  FACEDYN_RETURN_IF_ERROR(rig.Validate());
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(dir));
  std::error_code ec;
  std::filesystem::remove(JoinPath(dir, "face_rig.json"), ec);  // written last: marks completeness
  FACEDYN_RETURN_IF_ERROR(WriteMesh(rig.neutral, JoinPath(dir, "neutral.obj")));
  if (!rig.blendshape_names.empty()) {
    PointCache deltas;
    deltas.vertex_count = rig.vertex_count();
    deltas.positions.resize(3 * rig.vertex_count(), rig.blendshape_names.size());
    for (size_t k = 0; k < rig.blendshape_deltas_mm.size(); ++k) {
      deltas.Frame(static_cast<int>(k)) = rig.blendshape_deltas_mm[k].cast<float>();
    }
    FACEDYN_RETURN_IF_ERROR(WritePc2(JoinPath(dir, "blendshapes.pc2"), deltas));
  }
  if (rig.skull.vertex_count() > 0) FACEDYN_RETURN_IF_ERROR(WriteMesh(rig.skull, JoinPath(dir, "skull.obj")));
  std::string samples = std::string(kSamplesHeader) + "\n";
  for (const auto& p : rig.skin_samples) samples += SurfacePointCsv(p) + "\n";
  FACEDYN_RETURN_IF_ERROR(WriteFileAtomic(JoinPath(dir, "skin_samples.csv"), samples));
  std::string markers = std::string(kMarkersHeader) + "\n";
  for (const auto& m : rig.markers) {
    markers += fmt::format("{},{},{:.6g}\n", m.name, SurfacePointCsv(m.point), m.diameter_mm);
  }
  FACEDYN_RETURN_IF_ERROR(WriteFileAtomic(JoinPath(dir, "markers.csv"), markers));

  Json json;
  json["format_version"] = kFaceRigFormatVersion;
  json["name"] = rig.name;
  json["units"] = "mm";
  json["blendshapes"] = rig.blendshape_names;
  Json landmarks = Json::array();
  for (const auto& l : rig.skull_landmarks) {
    landmarks.push_back({{"name", l.name}, {"position_in_skull", Vector3Json(l.position_in_skull)}});
  }
  json["skull_landmarks"] = landmarks;
  json["jaw"] = {{"pivot_in_skull", Vector3Json(rig.jaw.pivot_in_skull)},
                 {"axis_in_skull", Vector3Json(rig.jaw.axis_in_skull)},
                 {"region", rig.jaw.region}};
  json["stable_regions"] = rig.stable_regions;
  Json regions = Json::object();
  for (const auto& [region, vertices] : rig.regions) regions[region] = vertices;
  json["regions"] = regions;
  return WriteJsonFile(JoinPath(dir, "face_rig.json"), json);
}

StatusOr<std::vector<Marker>> SelectMarkerLayout(const FaceRig& rig, const std::string& spec,
                                                 const std::string& what) {
  const bool all_digits =
      !spec.empty() && spec.find_first_not_of("0123456789") == std::string::npos;
  if (all_digits) {
    const long long n = std::stoll(spec.substr(0, 9));
    if (n < 4 || n > static_cast<long long>(rig.markers.size())) {
      return InvalidArgumentError(what + " " + spec + ": need 4.." +
                                  std::to_string(rig.markers.size()) + " (rig '" + rig.name +
                                  "' has " + std::to_string(rig.markers.size()) + " markers)");
    }
    return std::vector<Marker>(rig.markers.begin(), rig.markers.begin() + n);
  }
  std::ifstream in(spec);
  if (!in) {
    return NotFoundError(what + " " + spec +
                         ": neither a count nor a readable file of marker names");
  }
  std::vector<Marker> markers;
  std::set<std::string> seen;
  std::string line;
  int line_number = 0;
  bool rig_csv = false;  // a FaceRig's markers.csv: the names are its first column
  while (std::getline(in, line)) {
    ++line_number;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    if (markers.empty() && !rig_csv && line.rfind("name,", 0) == 0) {
      rig_csv = true;
      continue;
    }
    if (rig_csv) line = line.substr(0, line.find(','));
    const Marker* found = nullptr;
    for (const Marker& m : rig.markers) {
      if (m.name == line) found = &m;
    }
    if (found == nullptr) {
      return NotFoundError(spec + ":" + std::to_string(line_number) + ": marker '" + line +
                           "' is not in rig '" + rig.name + "'");
    }
    if (!seen.insert(line).second) {
      return InvalidArgumentError(spec + ":" + std::to_string(line_number) + ": marker '" + line +
                                  "' listed twice");
    }
    markers.push_back(*found);
  }
  if (markers.size() < 4) return InvalidArgumentError(what + " " + spec + ": fewer than 4 markers");
  return markers;
}

}  // namespace facedyn
