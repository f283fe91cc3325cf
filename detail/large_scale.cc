#include "detail/large_scale.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <string>

namespace facedyn::detail {

Status LaplacianDeformerOptions::Check() const {
  if (!(marker_weight > 0 && std::isfinite(marker_weight))) {
    return InvalidArgumentError(
        fmt::format("LaplacianDeformerOptions.marker_weight must be > 0, got {}", marker_weight));
  }
  return Status::Ok();
}

StatusOr<LaplacianDeformer> LaplacianDeformer::Create(const Mesh& neutral,
                                                      const std::vector<SurfacePoint>& markers,
                                                      const LaplacianDeformerOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  FACEDYN_RETURN_IF_ERROR(neutral.Validate("detail neutral mesh"));
  const int v_count = neutral.vertex_count();
  if (markers.empty()) return InvalidArgumentError("detail: no markers to deform the mesh with");
  for (size_t m = 0; m < markers.size(); ++m) {
    for (int k = 0; k < 3; ++k) {
      const int v = markers[m].vertices[k];
      if (v < 0 || v >= v_count) {
        return InvalidArgumentError(fmt::format(
            "detail: marker {} refers to vertex {}, the mesh has {} vertices", m, v, v_count));
      }
    }
  }
  const Eigen::Matrix3Xd& x0 = neutral.positions_mm;
  const Eigen::Matrix3Xi tris = neutral.Triangles();

  // Clamped cotangent stiffness: cot < 0 (obtuse angles) would make L indefinite on poor
  // triangles; clamping at 0 keeps every off-diagonal weight non-positive.
  std::vector<Eigen::Triplet<double>> l_entries;
  l_entries.reserve(static_cast<size_t>(tris.cols()) * 12);
  Eigen::VectorXd area = Eigen::VectorXd::Zero(v_count);
  for (int t = 0; t < tris.cols(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const int i = tris(k, t), j = tris((k + 1) % 3, t), o = tris((k + 2) % 3, t);
      const Eigen::Vector3d a = x0.col(i) - x0.col(o), b = x0.col(j) - x0.col(o);
      const double cross = a.cross(b).norm();
      const double cot = cross > 1e-12 ? std::clamp(a.dot(b) / cross, 0.0, 1e3) : 0.0;
      const double w = 0.5 * cot;
      l_entries.emplace_back(i, j, -w);
      l_entries.emplace_back(j, i, -w);
      l_entries.emplace_back(i, i, w);
      l_entries.emplace_back(j, j, w);
    }
    const double tri_area = 0.5 * (x0.col(tris(1, t)) - x0.col(tris(0, t)))
                                      .cross(x0.col(tris(2, t)) - x0.col(tris(0, t)))
                                      .norm();
    for (int k = 0; k < 3; ++k) area[tris(k, t)] += tri_area / 3.0;
  }
  const double mean_area = area.sum() / std::max(1, v_count);
  Eigen::SparseMatrix<double> l(v_count, v_count);
  l.setFromTriplets(l_entries.begin(), l_entries.end());
  Eigen::VectorXd inv_area(v_count);
  for (int v = 0; v < v_count; ++v) inv_area[v] = 1.0 / std::max(area[v], 1e-6 * mean_area);
  const Eigen::SparseMatrix<double> q =
      Eigen::SparseMatrix<double>(l.transpose()) * inv_area.asDiagonal() * l;

  LaplacianDeformer deformer;
  deformer.neutral_mm_ = x0;
  deformer.markers_ = markers;
  deformer.weight_ = options.marker_weight * q.diagonal().mean();
  deformer.neutral_markers_mm_.resize(3, static_cast<int>(markers.size()));
  std::vector<Eigen::Triplet<double>> c_entries;
  for (size_t m = 0; m < markers.size(); ++m) {
    deformer.neutral_markers_mm_.col(static_cast<int>(m)) = markers[m].Evaluate(x0);
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) {
        c_entries.emplace_back(markers[m].vertices[a], markers[m].vertices[b],
                               deformer.weight_ * markers[m].weights[a] * markers[m].weights[b]);
      }
    }
  }
  Eigen::SparseMatrix<double> ctc(v_count, v_count);
  ctc.setFromTriplets(c_entries.begin(), c_entries.end());
  const Eigen::SparseMatrix<double> system = q + ctc;
  deformer.solver_ = std::make_shared<Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>>(system);
  if (deformer.solver_->info() != Eigen::Success) {
    return FailedPreconditionError(fmt::format(
        "detail: the large-scale system ({} vertices, {} markers) is singular: every connected "
        "part of the mesh needs a marker",
        v_count, markers.size()));
  }
  // Marker response: column m is the displacement field of a unit residual at marker m.
  Eigen::MatrixXd unit = Eigen::MatrixXd::Zero(v_count, static_cast<int>(markers.size()));
  for (size_t m = 0; m < markers.size(); ++m) {
    for (int k = 0; k < 3; ++k)
      unit(markers[m].vertices[k], static_cast<int>(m)) += deformer.weight_ * markers[m].weights[k];
  }
  deformer.response_ = deformer.solver_->solve(unit);
  return deformer;
}

void LaplacianDeformer::Deform(const Eigen::Matrix3Xd& markers_mm,
                               Eigen::Matrix3Xd* skin_mm) const {
  FACEDYN_CHECK(markers_mm.cols() == marker_count(), "LaplacianDeformer::Deform: marker count");
  // d^T = r K^T  (3 x V).
  skin_mm->noalias() = (markers_mm - neutral_markers_mm_) * response_.transpose();
  *skin_mm += neutral_mm_;
}

void LaplacianDeformer::DeformBySolve(const Eigen::Matrix3Xd& markers_mm,
                                      Eigen::Matrix3Xd* skin_mm) const {
  FACEDYN_CHECK(markers_mm.cols() == marker_count(), "LaplacianDeformer::Deform: marker count");
  const int v_count = vertex_count();
  // rhs = w C^T (p - C x0), V x 3 (one column per coordinate).
  Eigen::MatrixX3d rhs = Eigen::MatrixX3d::Zero(v_count, 3);
  for (int m = 0; m < marker_count(); ++m) {
    const Eigen::Vector3d r = weight_ * (markers_mm.col(m) - neutral_markers_mm_.col(m));
    for (int k = 0; k < 3; ++k)
      rhs.row(markers_[m].vertices[k]) += markers_[m].weights[k] * r.transpose();
  }
  const Eigen::MatrixX3d d = solver_->solve(rhs);
  *skin_mm = neutral_mm_ + d.transpose();
}

TangentFrames::TangentFrames(const Mesh& neutral) : triangles_(neutral.Triangles()) {
  const int v_count = neutral.vertex_count();
  reference_neighbour_.assign(v_count, -1);
  const Eigen::Matrix3Xd normals = VertexNormals(neutral, neutral.positions_mm);
  std::vector<double> best(v_count, -1.0);
  for (int t = 0; t < triangles_.cols(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const int v = triangles_(k, t);
      for (int o = 1; o <= 2; ++o) {
        const int u = triangles_((k + o) % 3, t);
        const Eigen::Vector3d e = neutral.positions_mm.col(u) - neutral.positions_mm.col(v);
        const double n = e.norm();
        if (n <= 0) continue;
        // How far the edge is from the normal: 1 = in the tangent plane.
        const double tangential = (e - e.dot(normals.col(v)) * normals.col(v)).norm() / n;
        if (tangential > best[v]) {
          best[v] = tangential;
          reference_neighbour_[v] = u;
        }
      }
    }
  }
}

void TangentFrames::Compute(const Eigen::Matrix3Xd& positions_mm,
                            Eigen::Matrix<double, 9, Eigen::Dynamic>* frames) const {
  const int v_count = static_cast<int>(positions_mm.cols());
  FACEDYN_CHECK(v_count == static_cast<int>(reference_neighbour_.size()),
                "TangentFrames: vertex count");
  Eigen::Matrix3Xd normals = Eigen::Matrix3Xd::Zero(3, v_count);
  for (int t = 0; t < triangles_.cols(); ++t) {
    const Eigen::Vector3d a = positions_mm.col(triangles_(0, t));
    // The cross product's length is twice the area: area weighting for free.
    const Eigen::Vector3d n =
        (positions_mm.col(triangles_(1, t)) - a).cross(positions_mm.col(triangles_(2, t)) - a);
    for (int k = 0; k < 3; ++k) normals.col(triangles_(k, t)) += n;
  }
  frames->resize(9, v_count);
  for (int v = 0; v < v_count; ++v) {
    Eigen::Map<Eigen::Matrix3d> r(frames->col(v).data());
    const int u = reference_neighbour_[v];
    const double norm = normals.col(v).norm();
    if (u < 0 || norm <= 0) {
      r.setIdentity();
      continue;
    }
    const Eigen::Vector3d n = normals.col(v) / norm;
    Eigen::Vector3d t = positions_mm.col(u) - positions_mm.col(v);
    t -= t.dot(n) * n;
    const double t_norm = t.norm();
    if (t_norm <= 1e-12) {
      // Degenerate (the edge turned along the normal): any tangent keeps the frame orthonormal.
      t = n.unitOrthogonal();
    } else {
      t /= t_norm;
    }
    r.col(0) = t;
    r.col(1) = n.cross(t);
    r.col(2) = n;
  }
}

void TangentFrames::ToLocal(const Eigen::Matrix<double, 9, Eigen::Dynamic>& frames,
                            const Eigen::Matrix3Xd& base_mm, const Eigen::Matrix3Xd& x_mm,
                            Eigen::Matrix3Xd* local_mm) {
  local_mm->resize(3, base_mm.cols());
  for (int v = 0; v < base_mm.cols(); ++v) {
    const Eigen::Map<const Eigen::Matrix3d> r(frames.col(v).data());
    local_mm->col(v) = r.transpose() * (x_mm.col(v) - base_mm.col(v));
  }
}

void TangentFrames::FromLocal(const Eigen::Matrix<double, 9, Eigen::Dynamic>& frames,
                              const Eigen::Matrix3Xd& base_mm, const Eigen::Matrix3Xd& local_mm,
                              Eigen::Matrix3Xd* x_mm) {
  x_mm->resize(3, base_mm.cols());
  for (int v = 0; v < base_mm.cols(); ++v) {
    const Eigen::Map<const Eigen::Matrix3d> r(frames.col(v).data());
    x_mm->col(v) = base_mm.col(v) + r * local_mm.col(v);
  }
}

}  // namespace facedyn::detail
