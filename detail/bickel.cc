#include "detail/bickel.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include "core/parallel_for.h"
#include "detail/rbf.h"
#include "detail/regions.h"

namespace facedyn::detail {

Status BickelOptions::Check() const {
  FACEDYN_RETURN_IF_ERROR(large_scale.Check());
  if (!(edge_sigma_mm > 0 && std::isfinite(edge_sigma_mm))) {
    return InvalidArgumentError(
        fmt::format("BickelOptions.edge_sigma_mm must be > 0, got {}", edge_sigma_mm));
  }
  if (frames < 0)
    return InvalidArgumentError(fmt::format("BickelOptions.frames must be >= 0, got {}", frames));
  return Status::Ok();
}

Eigen::VectorXd BickelModel::Strains(const Eigen::Matrix3Xd& markers_mm) const {
  Eigen::VectorXd s(edges_.size());
  for (size_t e = 0; e < edges_.size(); ++e) {
    s[static_cast<int>(e)] =
        (markers_mm.col(edges_[e].first) - markers_mm.col(edges_[e].second)).norm() /
            rest_length_mm_[static_cast<int>(e)] -
        1.0;
  }
  return s;
}

StatusOr<BickelModel> BickelModel::Train(const DetailTrainingSet& set, const BickelOptions& options,
                                         std::vector<int>* selected_frames) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  FACEDYN_RETURN_IF_ERROR(set.Validate());
  BickelModel model;
  const std::vector<SurfacePoint> points = set.MarkerPoints();
  model.marker_count_ = static_cast<int>(points.size());
  FACEDYN_ASSIGN_OR_RETURN(model.deformer_,
                           LaplacianDeformer::Create(set.neutral, points, options.large_scale));
  model.tangent_ = TangentFrames(set.neutral);
  // Marker graph from the nearest-marker cells (edge-path distance).
  FACEDYN_ASSIGN_OR_RETURN(const MarkerRegions regions,
                           ComputeMarkerRegions(set.neutral, points, options.edge_sigma_mm));
  const int v_count = set.neutral.vertex_count();
  std::vector<int> cell(v_count);
  for (int v = 0; v < v_count; ++v) regions.distances_mm.col(v).minCoeff(&cell[v]);
  std::set<std::pair<int, int>> edge_set;
  const Mesh& mesh = set.neutral;
  for (int f = 0; f < mesh.face_count(); ++f) {
    const int begin = mesh.face_offsets[f], size = mesh.FaceSize(f);
    for (int k = 0; k < size; ++k) {
      const int a = cell[mesh.corner_vertices[begin + k]],
                b = cell[mesh.corner_vertices[begin + (k + 1) % size]];
      if (a != b) edge_set.emplace(std::min(a, b), std::max(a, b));
    }
  }
  model.edges_.assign(edge_set.begin(), edge_set.end());
  if (model.edges_.empty())
    return FailedPreconditionError("detail (Bickel): the marker graph has no edge");
  const Eigen::Matrix3Xd neutral_markers = set.MarkersOn(set.neutral.positions_mm);
  const int e_count = static_cast<int>(model.edges_.size());
  model.rest_length_mm_.resize(e_count);
  for (int e = 0; e < e_count; ++e) {
    const double l =
        (neutral_markers.col(model.edges_[e].first) - neutral_markers.col(model.edges_[e].second))
            .norm();
    if (!(l > 0)) {
      return FailedPreconditionError(fmt::format(
          "detail (Bickel): markers '{}' and '{}' coincide on the neutral",
          set.markers[model.edges_[e].first].name, set.markers[model.edges_[e].second].name));
    }
    model.rest_length_mm_[e] = l;
  }

  const LargeScaleFrames analysis = AnalyseFrames(set, model.deformer_, model.tangent_);
  const int n = static_cast<int>(set.frames_mm.size());
  Eigen::MatrixXd strains(e_count, n);
  for (int f = 0; f < n; ++f) strains.col(f) = model.Strains(set.MarkersOn(set.frames_mm[f]));
  std::vector<int> chosen;
  if (options.frames > 0 && options.frames < n) {
    Eigen::MatrixXd y(n, 3 * v_count);
    for (int f = 0; f < n; ++f)
      y.row(f) =
          Eigen::Map<const Eigen::RowVectorXd>(analysis.local_offsets_mm[f].data(), 3 * v_count);
    chosen = GreedySelectFrames(strains, y * y.transpose(), options.frames);
  } else {
    for (int f = 0; f < n; ++f) chosen.push_back(f);
  }
  if (selected_frames != nullptr) *selected_frames = chosen;
  const int k = static_cast<int>(chosen.size());
  model.training_strains_.resize(e_count, k);
  for (int i = 0; i < k; ++i) model.training_strains_.col(i) = strains.col(chosen[i]);

  // Per-vertex edge weights.
  const double s2 = options.edge_sigma_mm * options.edge_sigma_mm;
  model.vertex_offsets_.assign(1, 0);
  Eigen::VectorXd d(e_count);
  for (int v = 0; v < v_count; ++v) {
    for (int e = 0; e < e_count; ++e) {
      d[e] = 0.5 * (regions.distances_mm(model.edges_[e].first, v) +
                    regions.distances_mm(model.edges_[e].second, v));
    }
    const double d_min = d.minCoeff();
    double sum = 0;
    const size_t begin = model.edge_alpha_.size();
    for (int e = 0; e < e_count; ++e) {
      const double excess =
          std::isfinite(d_min) ? d[e] * d[e] - d_min * d_min : (e == 0 ? 0.0 : 1e300);
      if (excess > 9 * s2) continue;
      const double g = std::exp(-excess / (2 * s2));
      model.edge_index_.push_back(e);
      model.edge_alpha_.push_back(g);
      sum += g;
    }
    for (size_t i = begin; i < model.edge_alpha_.size(); ++i) model.edge_alpha_[i] /= sum;
    model.vertex_offsets_.push_back(static_cast<int>(model.edge_index_.size()));
  }

  // One interpolant per vertex (constant polynomial part), on that vertex's weighted distance.
  model.coefficients_.resize(k + 1, 3 * v_count);
  Eigen::MatrixXd kernel(k, k), values(k, 3);
  for (int v = 0; v < v_count; ++v) {
    for (int a = 0; a < k; ++a) {
      kernel(a, a) = 0;
      for (int b = a + 1; b < k; ++b) {
        double s = 0;
        for (int i = model.vertex_offsets_[v]; i < model.vertex_offsets_[v + 1]; ++i) {
          const double diff = model.training_strains_(model.edge_index_[i], a) -
                              model.training_strains_(model.edge_index_[i], b);
          s += model.edge_alpha_[i] * diff * diff;
        }
        kernel(a, b) = kernel(b, a) = std::sqrt(s);
      }
      values.row(a) = analysis.local_offsets_mm[chosen[a]].col(v).transpose();
    }
    // Poses this vertex's weighting can not tell apart (its edges' strains equal, or nearly:
    // the system is then too ill-conditioned to solve) are one centre: keep the first, as
    // BiharmonicRbf::Fit does, merging at a coarser relative distance until the system solves.
    const double extent = std::max(kernel.maxCoeff(), 1e-300);
    std::vector<int> keep;
    StatusOr<Eigen::MatrixXd> x = InternalError("unsolved");
    for (double tolerance : {1e-12, 1e-6, 1e-4, 1e-2}) {
      keep.clear();
      for (int a = 0; a < k; ++a) {
        bool repeated = false;
        for (int b : keep) repeated = repeated || kernel(a, b) <= tolerance * extent;
        if (!repeated) keep.push_back(a);
      }
      const int kk = static_cast<int>(keep.size());
      Eigen::MatrixXd sub_kernel(kk, kk), sub_values(kk, 3);
      for (int a = 0; a < kk; ++a) {
        for (int b = 0; b < kk; ++b) sub_kernel(a, b) = kernel(keep[a], keep[b]);
        sub_values.row(a) = values.row(keep[a]);
      }
      x = SolveRbfSystem(sub_kernel, Eigen::MatrixXd::Ones(kk, 1), sub_values);
      if (x.ok()) break;
    }
    if (!x.ok()) return x.status().WithContext(fmt::format("detail (Bickel): vertex {}", v));
    const int kk = static_cast<int>(keep.size());
    model.coefficients_.middleCols(3 * v, 3).setZero();
    for (int a = 0; a < kk; ++a) model.coefficients_.block(keep[a], 3 * v, 1, 3) = x->row(a);
    model.coefficients_.block(k, 3 * v, 1, 3) = x->row(kk);
  }
  return model;
}

Status BickelModel::Apply(const Eigen::Matrix3Xd& markers_mm, Eigen::Matrix3Xd* skin_mm) const {
  if (markers_mm.cols() != marker_count_ || !markers_mm.allFinite()) {
    return InvalidArgumentError(
        fmt::format("detail (Bickel): {} marker positions given ({} expected, all finite)",
                    markers_mm.cols(), marker_count_));
  }
  Eigen::Matrix3Xd large;
  deformer_.Deform(markers_mm, &large);
  const Eigen::VectorXd s = Strains(markers_mm);
  const int k = static_cast<int>(training_strains_.cols());
  const int v_count = static_cast<int>(large.cols());
  // diff(e, j) = s_e - s_je, once per frame; each vertex reads its own edges' rows.
  const Eigen::MatrixXd diff2 =
      (training_strains_.colwise() - s).array().square().matrix().transpose();  // k x E
  Eigen::Matrix3Xd local(3, v_count);
  Eigen::VectorXd h(k + 1);
  for (int v = 0; v < v_count; ++v) {
    h.head(k).setZero();
    for (int i = vertex_offsets_[v]; i < vertex_offsets_[v + 1]; ++i)
      h.head(k) += edge_alpha_[i] * diff2.col(edge_index_[i]);
    h.head(k) = h.head(k).cwiseSqrt();
    h[k] = 1.0;
    local.col(v) = coefficients_.middleCols(3 * v, 3).transpose() * h;
  }
  Eigen::Matrix<double, 9, Eigen::Dynamic> frames;
  tangent_.Compute(large, &frames);
  TangentFrames::FromLocal(frames, large, local, skin_mm);
  return Status::Ok();
}

Status BickelModel::ApplyFrames(const std::vector<Eigen::Matrix3Xd>& markers_mm,
                                std::vector<Eigen::Matrix3Xd>* skins_mm, int threads,
                                Progress* progress) const {
  const int frames = static_cast<int>(markers_mm.size());
  skins_mm->resize(frames);
  return ParallelFor(frames, threads, [&](int f) -> Status {
    Status status = Apply(markers_mm[f], &(*skins_mm)[f]);
    if (!status.ok()) return status.WithContext(fmt::format("frame {}", f));
    if (progress != nullptr) progress->Advance();
    return Status::Ok();
  });
}

size_t BickelModel::MemoryBytes() const {
  return sizeof(double) * (static_cast<size_t>(coefficients_.size()) + training_strains_.size() +
                           rest_length_mm_.size() + edge_alpha_.size()) +
         sizeof(int) * (edge_index_.size() + vertex_offsets_.size() + 2 * edges_.size());
}

}  // namespace facedyn::detail
