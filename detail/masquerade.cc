#include "detail/masquerade.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>

#include "core/binary_io.h"
#include "core/file_util.h"
#include "core/parallel_for.h"

namespace facedyn::detail {
namespace {

constexpr char kMagic[8] = {'F', 'D', 'D', 'E', 'T', 'A', 'I', 'L'};
constexpr char kTrailer[4] = {'E', 'N', 'D', '.'};
// Sanity bounds on counts read from a file, so a corrupted count is an error, not a huge
// allocation.
constexpr int64_t kMaxCount = 50'000'000;

Status CheckMarkers(const Eigen::Matrix3Xd& markers_mm, int expected) {
  if (markers_mm.cols() != expected) {
    return FailedPreconditionError(
        fmt::format("detail: {} marker positions given, the model was trained with {}",
                    markers_mm.cols(), expected));
  }
  for (int m = 0; m < markers_mm.cols(); ++m) {
    if (!markers_mm.col(m).allFinite()) {
      return InvalidArgumentError(fmt::format("detail: marker {} has a non-finite position", m));
    }
  }
  return Status::Ok();
}

}  // namespace

Status MasqueradeOptions::Check() const {
  FACEDYN_RETURN_IF_ERROR(large_scale.Check());
  if (!(region_sigma_mm > 0 && std::isfinite(region_sigma_mm))) {
    return InvalidArgumentError(
        fmt::format("MasqueradeOptions.region_sigma_mm must be > 0, got {}", region_sigma_mm));
  }
  if (!(pose_cell_mm >= 0 && std::isfinite(pose_cell_mm))) {
    return InvalidArgumentError(fmt::format(
        "MasqueradeOptions.pose_cell_mm must be >= 0 (0: every triangle), got {}", pose_cell_mm));
  }
  if (!(feature_sigma_mm > 0 && std::isfinite(feature_sigma_mm))) {
    return InvalidArgumentError(
        fmt::format("MasqueradeOptions.feature_sigma_mm must be > 0, got {}", feature_sigma_mm));
  }
  if (global_frames < 0)
    return InvalidArgumentError(
        fmt::format("MasqueradeOptions.global_frames must be >= 0, got {}", global_frames));
  if (per_region_frames < 0) {
    return InvalidArgumentError(
        fmt::format("MasqueradeOptions.per_region_frames must be >= 0, got {}", per_region_frames));
  }
  if (!(output_energy >= 0 && output_energy <= 1)) {
    return InvalidArgumentError(
        fmt::format("MasqueradeOptions.output_energy must be in (0, 1], or 0 to choose it, got {}",
                    output_energy));
  }
  return Status::Ok();
}

Status MasqueradeModel::Build() {
  std::vector<SurfacePoint> points;
  for (const Marker& m : markers_) points.push_back(m.point);
  FACEDYN_ASSIGN_OR_RETURN(deformer_,
                           LaplacianDeformer::Create(neutral_, points, options_.large_scale));
  tangent_ = TangentFrames(neutral_);
  gradients_ = DeformationGradients(neutral_);
  return Status::Ok();
}

void MasqueradeModel::RegionPoses(const Eigen::Matrix3Xd& large_mm, Eigen::MatrixXd* poses) const {
  Eigen::Matrix<double, 9, Eigen::Dynamic> f;
  gradients_.Compute(large_mm, pose_triangles_, &f);
  const Eigen::Matrix<double, 9, 1> identity =
      Eigen::Map<const Eigen::Matrix<double, 9, 1>>(Eigen::Matrix3d::Identity().eval().data());
  poses->resize(9, static_cast<int>(feature_triangles_.size()));
  for (size_t r = 0; r < feature_triangles_.size(); ++r) {
    Eigen::Matrix<double, 9, 1> sum = Eigen::Matrix<double, 9, 1>::Zero();
    for (const PoseTriangle& p : feature_triangles_[r])
      sum += static_cast<double>(p.weight) * (f.col(p.triangle) - identity);
    poses->col(static_cast<int>(r)) = sum;
  }
}

void MasqueradeModel::IndexPoseTriangles() {
  pose_triangles_.clear();
  for (const auto& list : feature_triangles_) {
    for (const PoseTriangle& p : list) pose_triangles_.push_back(p.triangle);
  }
  std::sort(pose_triangles_.begin(), pose_triangles_.end());
  pose_triangles_.erase(std::unique(pose_triangles_.begin(), pose_triangles_.end()),
                        pose_triangles_.end());
  for (auto& list : feature_triangles_) {
    for (PoseTriangle& p : list) {
      p.triangle = static_cast<int32_t>(
          std::lower_bound(pose_triangles_.begin(), pose_triangles_.end(), p.triangle) -
          pose_triangles_.begin());
    }
  }
}

StatusOr<MasqueradeModel> MasqueradeModel::Train(const DetailTrainingSet& set,
                                                 const MasqueradeOptions& options,
                                                 MasqueradeTrainingSummary* summary) {
  const auto start = std::chrono::steady_clock::now();
  FACEDYN_RETURN_IF_ERROR(options.Check());
  FACEDYN_RETURN_IF_ERROR(set.Validate());
  MasqueradeModel model;
  model.subject_ = set.subject;
  model.options_ = options;
  model.neutral_ = set.neutral;
  model.markers_ = set.markers;
  FACEDYN_RETURN_IF_ERROR(model.Build());
  FACEDYN_ASSIGN_OR_RETURN(model.regions_, ComputeMarkerRegions(set.neutral, set.MarkerPoints(),
                                                                options.region_sigma_mm));

  // Pose triangles: Gaussian of the mean edge-path distance of the triangle's corners, times
  // its rest area (so the pose does not depend on how finely an area is meshed); each weight is
  // carried by its patch's representative triangle (options.pose_cell_mm).
  const Eigen::Matrix3Xi& tris = model.gradients_.triangles();
  const Eigen::Matrix3Xd& x0 = set.neutral.positions_mm;
  const int r_count = model.regions_.region_count();
  const double s2 = options.feature_sigma_mm * options.feature_sigma_mm;
  const std::vector<int> representative = PatchRepresentatives(x0, tris, options.pose_cell_mm);
  model.feature_triangles_.assign(r_count, {});
  for (int r = 0; r < r_count; ++r) {
    std::map<int, double> list;  // representative triangle -> weight
    double sum = 0, nearest_d = std::numeric_limits<double>::infinity();
    int nearest_t = -1;
    for (int t = 0; t < tris.cols(); ++t) {
      const double d =
          (model.regions_.distances_mm(r, tris(0, t)) + model.regions_.distances_mm(r, tris(1, t)) +
           model.regions_.distances_mm(r, tris(2, t))) /
          3.0;
      const double area = 0.5 * (x0.col(tris(1, t)) - x0.col(tris(0, t)))
                                    .cross(x0.col(tris(2, t)) - x0.col(tris(0, t)))
                                    .norm();
      if (area > 0 && d < nearest_d) {
        nearest_d = d;
        nearest_t = t;
      }
      if (!(d <= 3 * options.feature_sigma_mm) || area <= 0) continue;
      const double w = area * std::exp(-d * d / (2 * s2));
      list[representative[t]] += w;
      sum += w;
    }
    if (list.empty() && nearest_t >= 0) {
      list[nearest_t] = 1.0;
      sum = 1.0;
    }
    if (list.empty())
      return FailedPreconditionError(fmt::format(
          "detail: marker '{}' has no triangle with area near it", set.markers[r].name));
    for (const auto& [t, w] : list)
      model.feature_triangles_[r].push_back({t, static_cast<float>(w / sum)});
  }
  model.IndexPoseTriangles();

  const LargeScaleFrames analysis = AnalyseFrames(set, model.deformer_, model.tangent_);
  const int n = static_cast<int>(set.frames_mm.size());
  const int v_count = set.neutral.vertex_count();
  std::vector<Eigen::MatrixXd> poses(n);  // 9 x R per frame
  for (int f = 0; f < n; ++f) model.RegionPoses(analysis.large_mm[f], &poses[f]);

  // Global pool.
  std::vector<int> pool;
  if (options.global_frames > 0 && options.global_frames < n) {
    Eigen::MatrixXd features(9 * r_count, n), y(n, 3 * v_count);
    for (int f = 0; f < n; ++f) {
      features.col(f) = Eigen::Map<const Eigen::VectorXd>(poses[f].data(), 9 * r_count);
      y.row(f) =
          Eigen::Map<const Eigen::RowVectorXd>(analysis.local_offsets_mm[f].data(), 3 * v_count);
    }
    const Eigen::MatrixXd gram = y * y.transpose();
    pool = GreedySelectFrames(features, gram, options.global_frames);
  } else {
    for (int f = 0; f < n; ++f) pool.push_back(f);
  }

  model.rbfs_.clear();
  std::vector<Eigen::MatrixXd> region_values;  // each RBF's training values, for compression
  double frames_total = 0;
  int linear_regions = 0;
  for (int r = 0; r < r_count; ++r) {
    const std::vector<int>& verts = model.regions_.vertices[r];
    const int k_out = 3 * static_cast<int>(verts.size());
    const int p = static_cast<int>(pool.size());
    Eigen::MatrixXd features(9, p), values(p, k_out);
    for (int i = 0; i < p; ++i) {
      features.col(i) = poses[pool[i]].col(r);
      for (size_t j = 0; j < verts.size(); ++j) {
        values.block<1, 3>(i, 3 * static_cast<int>(j)) =
            analysis.local_offsets_mm[pool[i]].col(verts[j]).transpose();
      }
    }
    std::vector<int> chosen;
    if (options.per_region_frames > 0 && options.per_region_frames < p) {
      // Weighted offsets: the error that reaches the blended result.
      Eigen::MatrixXd weighted = values;
      for (size_t j = 0; j < verts.size(); ++j)
        weighted.middleCols(3 * static_cast<int>(j), 3) *= model.regions_.weights[r][j];
      chosen =
          GreedySelectFrames(features, weighted * weighted.transpose(), options.per_region_frames);
    } else {
      for (int i = 0; i < p; ++i) chosen.push_back(i);
    }
    Eigen::MatrixXd c(9, static_cast<int>(chosen.size())),
        y(static_cast<int>(chosen.size()), k_out);
    for (size_t i = 0; i < chosen.size(); ++i) {
      c.col(static_cast<int>(i)) = features.col(chosen[i]);
      y.row(static_cast<int>(i)) = values.row(chosen[i]);
    }
    StatusOr<BiharmonicRbf> rbf = BiharmonicRbf::Fit(c, y);
    if (!rbf.ok())
      return rbf.status().WithContext(
          fmt::format("detail: region of marker '{}'", set.markers[r].name));
    frames_total += rbf->centre_count();
    linear_regions += rbf->linear() ? 1 : 0;
    model.rbfs_.push_back(std::move(rbf).value());
    region_values.push_back(std::move(y));
  }

  // Output compression: as asked, or chosen on the training frames the global selection left
  // out (frames the RBFs never interpolate): the smallest candidate energy whose mean vertex
  // error there is within 5% of the uncompressed model's.
  const std::vector<BiharmonicRbf> full = model.rbfs_;
  auto compress = [&](double energy) -> Status {
    model.rbfs_ = full;
    if (energy >= 1.0) return Status::Ok();
    for (int r = 0; r < r_count; ++r) {
      FACEDYN_RETURN_IF_ERROR(model.rbfs_[r].CompressOutputs(region_values[r], energy));
    }
    return Status::Ok();
  };
  double energy = options.output_energy;
  std::vector<int> held_out;
  if (energy == kChooseOutputEnergy) {
    std::vector<char> in_pool(n, 0);
    for (int f : pool) in_pool[f] = 1;
    for (int f = 0; f < n; ++f) {
      if (!in_pool[f]) held_out.push_back(f);
    }
    energy = 1.0;
    double uncompressed = 0.0;
    for (double candidate : kOutputEnergyCandidates) {
      FACEDYN_RETURN_IF_ERROR(compress(candidate));
      double error = 0.0;
      Eigen::Matrix3Xd skin;
      for (int f : held_out) {
        FACEDYN_RETURN_IF_ERROR(model.Apply(set.MarkersOn(set.frames_mm[f]), &skin));
        error += (skin - set.frames_mm[f]).colwise().norm().mean();
      }
      if (candidate == 1.0) uncompressed = error;
      if (!held_out.empty() && error <= 1.05 * uncompressed) energy = candidate;
    }
  }
  FACEDYN_RETURN_IF_ERROR(compress(energy));
  model.options_.output_energy = energy;
  if (summary != nullptr) {
    summary->output_energy = energy;
    summary->output_energy_validation_frames = static_cast<int>(held_out.size());
    summary->global_frames = pool;
    summary->mean_frames_per_region = frames_total / r_count;
    summary->linear_regions = linear_regions;
    summary->train_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return model;
}

Status MasqueradeModel::Apply(const Eigen::Matrix3Xd& markers_mm, Eigen::Matrix3Xd* skin_mm,
                              Eigen::Matrix3Xd* large_scale_mm) const {
  FACEDYN_RETURN_IF_ERROR(CheckMarkers(markers_mm, static_cast<int>(markers_.size())));
  Eigen::Matrix3Xd large;
  deformer_.Deform(markers_mm, &large);
  Eigen::MatrixXd poses;
  RegionPoses(large, &poses);
  const int v_count = vertex_count();
  Eigen::Matrix3Xd local = Eigen::Matrix3Xd::Zero(3, v_count);
  Eigen::VectorXd out;
  for (size_t r = 0; r < rbfs_.size(); ++r) {
    const BiharmonicRbf& rbf = rbfs_[r];
    out.resize(rbf.outputs());
    rbf.Evaluate(poses.col(static_cast<int>(r)), out);
    const std::vector<int>& verts = regions_.vertices[r];
    const std::vector<double>& w = regions_.weights[r];
    for (size_t j = 0; j < verts.size(); ++j)
      local.col(verts[j]) += w[j] * out.segment<3>(3 * static_cast<int>(j));
  }
  Eigen::Matrix<double, 9, Eigen::Dynamic> frames;
  tangent_.Compute(large, &frames);
  TangentFrames::FromLocal(frames, large, local, skin_mm);
  if (large_scale_mm != nullptr) *large_scale_mm = std::move(large);
  return Status::Ok();
}

Status MasqueradeModel::ApplyFrames(const std::vector<Eigen::Matrix3Xd>& markers_mm,
                                    std::vector<Eigen::Matrix3Xd>* skins_mm,
                                    std::vector<Eigen::Matrix3Xd>* large_scale_mm, int threads,
                                    Progress* progress) const {
  const int frames = static_cast<int>(markers_mm.size());
  skins_mm->resize(frames);
  if (large_scale_mm != nullptr) large_scale_mm->resize(frames);
  return ParallelFor(frames, threads, [&](int f) -> Status {
    Status status = Apply(markers_mm[f], &(*skins_mm)[f],
                          large_scale_mm != nullptr ? &(*large_scale_mm)[f] : nullptr);
    if (!status.ok()) return status.WithContext(fmt::format("frame {}", f));
    if (progress != nullptr) progress->Advance();
    return Status::Ok();
  });
}

Status MasqueradeModel::CheckCompatible(const std::vector<std::string>& marker_names,
                                        int vertex_count_in, const std::string& what) const {
  if (vertex_count_in != vertex_count()) {
    return FailedPreconditionError(
        fmt::format("{}: {} vertices, the detail model's rig '{}' has {}", what, vertex_count_in,
                    subject_, vertex_count()));
  }
  for (size_t m = 0; m < markers_.size(); ++m) {
    if (m >= marker_names.size()) {
      return FailedPreconditionError(fmt::format(
          "{}: marker '{}' (#{}) of the detail model is missing", what, markers_[m].name, m));
    }
    if (marker_names[m] != markers_[m].name) {
      return FailedPreconditionError(
          fmt::format("{}: marker #{} is '{}', the detail model expects '{}'", what, m,
                      marker_names[m], markers_[m].name));
    }
  }
  if (marker_names.size() > markers_.size()) {
    return FailedPreconditionError(
        fmt::format("{}: marker '{}' (#{}) is not in the detail model's layout", what,
                    marker_names[markers_.size()], markers_.size()));
  }
  return Status::Ok();
}

MasqueradeModel::MemoryParts MasqueradeModel::MemoryBreakdown() const {
  MemoryParts parts;
  for (const BiharmonicRbf& rbf : rbfs_) {
    parts.rbf_centres += sizeof(double) * rbf.centres().size();
    parts.rbf_coefficients += sizeof(double) * rbf.coefficients().size();
    parts.rbf_output_bases += sizeof(double) * rbf.output_basis().size();
  }
  for (int r = 0; r < regions_.region_count(); ++r) {
    parts.region_vertices += regions_.vertices[r].size() * (sizeof(int) + sizeof(double));
    parts.feature_triangles += feature_triangles_[r].size() * sizeof(PoseTriangle);
  }
  parts.feature_triangles += pose_triangles_.size() * sizeof(int);
  return parts;
}

Status MasqueradeModel::Save(const std::string& path) const {
  BinaryWriter w;
  w.Raw(kMagic, sizeof(kMagic));
  // The oldest version that holds the model: an uncompressed one stays readable by builds that
  // know only version 1.
  bool compressed = false;
  for (const BiharmonicRbf& rbf : rbfs_) compressed = compressed || rbf.output_basis().size() != 0;
  const uint32_t version = compressed ? 2 : 1;
  w.Pod<uint32_t>(version);
  w.Str(subject_);
  w.Pod(options_.large_scale.marker_weight);
  w.Pod(options_.region_sigma_mm);
  w.Pod(options_.feature_sigma_mm);
  w.Pod<int32_t>(options_.global_frames);
  w.Pod<int32_t>(options_.per_region_frames);
  w.Doubles(neutral_.positions_mm.data(), neutral_.positions_mm.size());
  w.Ints(neutral_.face_offsets.data(), static_cast<int64_t>(neutral_.face_offsets.size()));
  w.Ints(neutral_.corner_vertices.data(), static_cast<int64_t>(neutral_.corner_vertices.size()));
  w.Pod<int64_t>(static_cast<int64_t>(markers_.size()));
  for (const Marker& m : markers_) {
    w.Str(m.name);
    for (int k = 0; k < 3; ++k) w.Pod<int32_t>(m.point.vertices[k]);
    for (int k = 0; k < 3; ++k) w.Pod<double>(m.point.weights[k]);
    w.Pod(m.diameter_mm);
  }
  for (int r = 0; r < regions_.region_count(); ++r) {
    w.Ints(regions_.vertices[r].data(), static_cast<int64_t>(regions_.vertices[r].size()));
    w.Doubles(regions_.weights[r].data(), static_cast<int64_t>(regions_.weights[r].size()));
    std::vector<int> tri;
    std::vector<double> tri_w;
    for (const PoseTriangle& p : feature_triangles_[r]) {
      tri.push_back(pose_triangles_[p.triangle]);
      tri_w.push_back(p.weight);  // exact in the file's doubles
    }
    w.Ints(tri.data(), static_cast<int64_t>(tri.size()));
    w.Doubles(tri_w.data(), static_cast<int64_t>(tri_w.size()));
    const BiharmonicRbf& rbf = rbfs_[r];
    w.Pod<int32_t>(rbf.dimension());
    w.Pod<int32_t>(rbf.centre_count());
    w.Pod<uint8_t>(rbf.linear() ? 1 : 0);
    w.Pod<int32_t>(rbf.outputs());
    if (version >= 2) w.Pod<int32_t>(static_cast<int32_t>(rbf.output_basis().rows()));  // 0: none
    w.Doubles(rbf.centres().data(), rbf.centres().size());
    w.Doubles(rbf.coefficients().data(), rbf.coefficients().size());
    if (version >= 2) w.Doubles(rbf.output_basis().data(), rbf.output_basis().size());
  }
  w.Raw(kTrailer, sizeof(kTrailer));
  return WriteFileAtomic(path, w.bytes());
}

StatusOr<MasqueradeModel> MasqueradeModel::Load(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(std::string bytes, ReadFileToString(path));
  BinaryReader r(std::move(bytes), path, kMaxCount);
  char magic[8];
  FACEDYN_RETURN_IF_ERROR(r.Take(magic, sizeof(magic), "the magic"));
  if (std::memcmp(magic, kMagic, sizeof(kMagic)) != 0) {
    return DataLossError(fmt::format("{}: not a facedyn detail model (bad magic)", path));
  }
  uint32_t version = 0;
  FACEDYN_RETURN_IF_ERROR(r.Pod(&version, "the format version"));
  if (version < 1 || version > static_cast<uint32_t>(kDetailModelFormatVersion)) {
    return FailedPreconditionError(
        fmt::format("{}: detail model format version {}, this build reads 1 to {}", path, version,
                    kDetailModelFormatVersion));
  }
  MasqueradeModel model;
  FACEDYN_RETURN_IF_ERROR(r.Str(&model.subject_, "the subject"));
  int32_t global = 0, per_region = 0;
  FACEDYN_RETURN_IF_ERROR(r.Pod(&model.options_.large_scale.marker_weight, "options"));
  FACEDYN_RETURN_IF_ERROR(r.Pod(&model.options_.region_sigma_mm, "options"));
  FACEDYN_RETURN_IF_ERROR(r.Pod(&model.options_.feature_sigma_mm, "options"));
  FACEDYN_RETURN_IF_ERROR(r.Pod(&global, "options"));
  FACEDYN_RETURN_IF_ERROR(r.Pod(&per_region, "options"));
  model.options_.global_frames = global;
  model.options_.per_region_frames = per_region;
  {
    Status s = model.options_.Check();
    if (!s.ok()) return DataLossError(fmt::format("{}: stored options: {}", path, s.message()));
  }
  std::vector<double> positions;
  FACEDYN_RETURN_IF_ERROR(r.Array(&positions, -1, "the neutral positions"));
  if (positions.size() % 3 != 0 || positions.empty()) {
    return DataLossError(
        fmt::format("{}: {} neutral coordinates, not a multiple of 3", path, positions.size()));
  }
  const int v_count = static_cast<int>(positions.size() / 3);
  model.neutral_.positions_mm = Eigen::Map<const Eigen::Matrix3Xd>(positions.data(), 3, v_count);
  FACEDYN_RETURN_IF_ERROR(r.Array(&model.neutral_.face_offsets, -1, "the neutral face offsets"));
  FACEDYN_RETURN_IF_ERROR(r.Array(&model.neutral_.corner_vertices, -1, "the neutral corners"));
  {
    const Mesh& mesh = model.neutral_;
    bool offsets_ok = !mesh.face_offsets.empty() && mesh.face_offsets.front() == 0 &&
                      mesh.face_offsets.back() == static_cast<int>(mesh.corner_vertices.size());
    for (size_t i = 1; offsets_ok && i < mesh.face_offsets.size(); ++i) {
      offsets_ok = mesh.face_offsets[i] > mesh.face_offsets[i - 1];
    }
    if (!offsets_ok)
      return DataLossError(fmt::format("{}: the neutral's face offsets are inconsistent", path));
    Status s = mesh.Validate(path + " neutral");
    if (!s.ok()) return DataLossError(s.message());
  }
  int64_t m_count = 0;
  FACEDYN_RETURN_IF_ERROR(r.Count(&m_count, 100000, "the marker count"));
  if (m_count == 0) return DataLossError(fmt::format("{}: no markers", path));
  for (int64_t m = 0; m < m_count; ++m) {
    Marker marker;
    FACEDYN_RETURN_IF_ERROR(r.Str(&marker.name, "a marker name"));
    for (int k = 0; k < 3; ++k) {
      int32_t v = 0;
      FACEDYN_RETURN_IF_ERROR(r.Pod(&v, "a marker vertex"));
      if (v < 0 || v >= v_count) {
        return DataLossError(fmt::format("{}: marker '{}' refers to vertex {} of {}", path,
                                         marker.name, v, v_count));
      }
      marker.point.vertices[k] = v;
    }
    for (int k = 0; k < 3; ++k)
      FACEDYN_RETURN_IF_ERROR(r.Pod(&marker.point.weights[k], "a marker weight"));
    FACEDYN_RETURN_IF_ERROR(r.Pod(&marker.diameter_mm, "a marker diameter"));
    const Eigen::Vector3d& b = marker.point.weights;
    if (!b.allFinite() || b.minCoeff() < -1e-9 || std::abs(b.sum() - 1.0) > 1e-6) {
      return DataLossError(fmt::format("{}: marker '{}' has barycentric weights ({}, {}, {})", path,
                                       marker.name, b[0], b[1], b[2]));
    }
    model.markers_.push_back(std::move(marker));
  }
  const int t_count = static_cast<int>(model.neutral_.Triangles().cols());
  model.regions_.vertices.resize(m_count);
  model.regions_.weights.resize(m_count);
  model.feature_triangles_.resize(m_count);
  for (int64_t g = 0; g < m_count; ++g) {
    const std::string& name = model.markers_[g].name;
    const std::string what = "region of marker '" + name + "'";
    FACEDYN_RETURN_IF_ERROR(r.Array(&model.regions_.vertices[g], -1, what.c_str()));
    FACEDYN_RETURN_IF_ERROR(r.Array(&model.regions_.weights[g],
                                    static_cast<int64_t>(model.regions_.vertices[g].size()),
                                    what.c_str()));
    for (int v : model.regions_.vertices[g]) {
      if (v < 0 || v >= v_count)
        return DataLossError(fmt::format("{}: {} has vertex {} of {}", path, what, v, v_count));
    }
    for (double wt : model.regions_.weights[g]) {
      if (!(wt >= 0 && wt <= 1))
        return DataLossError(fmt::format("{}: {} has blend weight {}", path, what, wt));
    }
    std::vector<int> tri;
    std::vector<double> tri_w;
    FACEDYN_RETURN_IF_ERROR(r.Array(&tri, -1, what.c_str()));
    FACEDYN_RETURN_IF_ERROR(r.Array(&tri_w, static_cast<int64_t>(tri.size()), what.c_str()));
    for (size_t i = 0; i < tri.size(); ++i) {
      if (tri[i] < 0 || tri[i] >= t_count) {
        return DataLossError(
            fmt::format("{}: {} has triangle {} of {}", path, what, tri[i], t_count));
      }
      if (!(tri_w[i] >= 0 && tri_w[i] <= 1)) {
        return DataLossError(fmt::format("{}: {} has pose weight {}", path, what, tri_w[i]));
      }
      model.feature_triangles_[g].push_back({tri[i], static_cast<float>(tri_w[i])});
    }
    int32_t dim = 0, centres = 0, outputs = 0;
    uint8_t linear = 0;
    FACEDYN_RETURN_IF_ERROR(r.Pod(&dim, what.c_str()));
    FACEDYN_RETURN_IF_ERROR(r.Pod(&centres, what.c_str()));
    FACEDYN_RETURN_IF_ERROR(r.Pod(&linear, what.c_str()));
    FACEDYN_RETURN_IF_ERROR(r.Pod(&outputs, what.c_str()));
    if (dim != 9 || centres <= 0 || centres > 100000 || linear > 1 ||
        outputs != 3 * static_cast<int>(model.regions_.vertices[g].size())) {
      return DataLossError(
          fmt::format("{}: {}: RBF of dimension {}, {} centres, {} outputs do not fit the region",
                      path, what, dim, centres, outputs));
    }
    int32_t basis_rows = 0;
    if (version >= 2) {
      FACEDYN_RETURN_IF_ERROR(r.Pod(&basis_rows, what.c_str()));
      if (basis_rows < 0 || basis_rows > outputs) {
        return DataLossError(fmt::format("{}: {}: an output basis of {} rows for {} outputs", path,
                                         what, basis_rows, outputs));
      }
    }
    std::vector<double> c, coef, basis;
    FACEDYN_RETURN_IF_ERROR(r.Array(&c, int64_t{dim} * centres, what.c_str()));
    const int rows = centres + (linear ? 1 + dim : 1);
    const int coefficient_columns = basis_rows > 0 ? basis_rows : outputs;
    FACEDYN_RETURN_IF_ERROR(r.Array(&coef, int64_t{rows} * coefficient_columns, what.c_str()));
    if (version >= 2)
      FACEDYN_RETURN_IF_ERROR(r.Array(&basis, int64_t{basis_rows} * outputs, what.c_str()));
    for (double value : basis) {
      if (!std::isfinite(value))
        return DataLossError(fmt::format("{}: {}: non-finite RBF output basis", path, what));
    }
    for (double value : c) {
      if (!std::isfinite(value))
        return DataLossError(fmt::format("{}: {}: non-finite RBF centre", path, what));
    }
    for (double value : coef) {
      if (!std::isfinite(value))
        return DataLossError(fmt::format("{}: {}: non-finite RBF coefficient", path, what));
    }
    StatusOr<BiharmonicRbf> rbf = BiharmonicRbf::FromParts(
        Eigen::Map<const Eigen::MatrixXd>(c.data(), dim, centres),
        Eigen::Map<const Eigen::MatrixXd>(coef.data(), rows, coefficient_columns), linear == 1,
        basis_rows > 0
            ? Eigen::MatrixXd(Eigen::Map<const Eigen::MatrixXd>(basis.data(), basis_rows, outputs))
            : Eigen::MatrixXd());
    if (!rbf.ok()) return rbf.status().WithContext(path);
    model.rbfs_.push_back(std::move(rbf).value());
  }
  char trailer[4];
  FACEDYN_RETURN_IF_ERROR(r.Take(trailer, sizeof(trailer), "the trailer"));
  if (std::memcmp(trailer, kTrailer, sizeof(kTrailer)) != 0 || !r.AtEnd()) {
    return DataLossError(
        fmt::format("{}: corrupted: the trailer is not where the counts say", path));
  }
  model.IndexPoseTriangles();
  {
    Status s = model.Build();
    if (!s.ok()) return s.WithContext(path);
  }
  return model;
}

}  // namespace facedyn::detail
