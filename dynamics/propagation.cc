#include "dynamics/propagation.h"

#include <Eigen/Cholesky>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <utility>
#include <vector>

#include "core/check.h"

namespace facedyn::dynamics {

Status PropagationOptions::Check() const {
  if (!(constraint_weight > 0)) return InvalidArgumentError("constraint_weight must be > 0");
  if (!(regularisation > 0)) return InvalidArgumentError("regularisation must be > 0");
  return Status::Ok();
}

StatusOr<SamplePropagation> SamplePropagation::Build(const FaceRig& rig,
                                                     const PropagationOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  const Mesh& mesh = rig.neutral;
  const int vertex_count = mesh.vertex_count();
  const int sample_count = static_cast<int>(rig.skin_samples.size());
  if (sample_count == 0) return FailedPreconditionError("propagation: the rig has no skin samples");
  if (mesh.face_count() == 0)
    return FailedPreconditionError("propagation: the neutral has no faces");

  // Edge-length-weighted graph Laplacian, rows normalised: (L d)_v = d_v - sum_u w_vu d_u.
  std::vector<Eigen::Triplet<double>> edges;
  for (int f = 0; f < mesh.face_count(); ++f) {
    const int begin = mesh.face_offsets[f];
    const int size = mesh.FaceSize(f);
    for (int c = 0; c < size; ++c) {
      const int a = mesh.corner_vertices[begin + c];
      const int b = mesh.corner_vertices[begin + (c + 1) % size];
      const double length = (mesh.positions_mm.col(a) - mesh.positions_mm.col(b)).norm();
      const double w = 1.0 / std::max(length, 1e-6);
      // Each interior edge appears in two faces: the duplicate sums, uniformly for all edges
      // of a closed fan, and the row normalisation below removes the overall scale.
      edges.emplace_back(a, b, w);
      edges.emplace_back(b, a, w);
    }
  }
  Eigen::SparseMatrix<double> adjacency(vertex_count, vertex_count);
  adjacency.setFromTriplets(edges.begin(), edges.end());
  Eigen::VectorXd row_sum = Eigen::VectorXd::Zero(vertex_count);
  for (int k = 0; k < adjacency.outerSize(); ++k) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(adjacency, k); it; ++it) {
      row_sum[it.row()] += it.value();
    }
  }
  std::vector<Eigen::Triplet<double>> laplacian_entries;
  for (int v = 0; v < vertex_count; ++v) laplacian_entries.emplace_back(v, v, 1.0);
  for (int k = 0; k < adjacency.outerSize(); ++k) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(adjacency, k); it; ++it) {
      laplacian_entries.emplace_back(it.row(), it.col(), -it.value() / row_sum[it.row()]);
    }
  }
  Eigen::SparseMatrix<double> laplacian(vertex_count, vertex_count);
  laplacian.setFromTriplets(laplacian_entries.begin(), laplacian_entries.end());

  std::vector<Eigen::Triplet<double>> constraint_entries;
  for (int i = 0; i < sample_count; ++i) {
    const SurfacePoint& sample = rig.skin_samples[i];
    for (int k = 0; k < 3; ++k) {
      if (sample.weights[k] != 0.0) {
        constraint_entries.emplace_back(i, sample.vertices[k], sample.weights[k]);
      }
    }
  }
  Eigen::SparseMatrix<double> constraints(sample_count, vertex_count);
  constraints.setFromTriplets(constraint_entries.begin(), constraint_entries.end());

  Eigen::SparseMatrix<double> identity(vertex_count, vertex_count);
  identity.setIdentity();
  const Eigen::SparseMatrix<double> system =
      Eigen::SparseMatrix<double>(laplacian.transpose() * laplacian) +
      options.constraint_weight *
          Eigen::SparseMatrix<double>(constraints.transpose() * constraints) +
      options.regularisation * identity;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(system);
  if (solver.info() != Eigen::Success) {
    return InternalError("propagation: the Laplacian system could not be factorised");
  }
  const Eigen::MatrixXd rhs = options.constraint_weight * Eigen::MatrixXd(constraints.transpose());
  const Eigen::MatrixXd weights = solver.solve(rhs);
  if (solver.info() != Eigen::Success || !weights.allFinite()) {
    return InternalError("propagation: the Laplacian solve failed");
  }
  SamplePropagation propagation;
  propagation.weights_ = weights.cast<float>();
  propagation.weights_transposed_ = propagation.weights_.transpose();
  return propagation;
}

StatusOr<SamplePropagation> SamplePropagation::FromWeights(Eigen::MatrixXf weights,
                                                           std::string method) {
  if (weights.size() == 0) return InvalidArgumentError("propagation: empty weight matrix");
  if (!weights.allFinite()) return DataLossError("propagation: weight matrix is not finite");
  SamplePropagation propagation;
  propagation.method_ = std::move(method);
  propagation.weights_ = std::move(weights);
  propagation.weights_transposed_ = propagation.weights_.transpose();
  return propagation;
}

Status PropagationLearnOptions::Check() const {
  if (!(prior_weight > 0 && prior_weight <= 1e3))
    return InvalidArgumentError("prior_weight must be in (0, 1000]");
  return Status::Ok();
}

PropagationLearner::PropagationLearner(SamplePropagation prior,
                                       std::vector<SurfacePoint> samples,
                                       PropagationLearnOptions options)
    : prior_(std::move(prior)), samples_(std::move(samples)), options_(options) {
  FACEDYN_CHECK(static_cast<int>(samples_.size()) == prior_.sample_count(),
                "PropagationLearner: sample count differs from the prior's");
  sample_gram_ = Eigen::MatrixXd::Zero(prior_.sample_count(), prior_.sample_count());
  vertex_sample_ = Eigen::MatrixXd::Zero(prior_.vertex_count(), prior_.sample_count());
}

StatusOr<PropagationLearner> PropagationLearner::ForRig(const FaceRig& rig,
                                                        PropagationLearnOptions options) {
  FACEDYN_ASSIGN_OR_RETURN(SamplePropagation prior, SamplePropagation::Build(rig));
  return PropagationLearner(std::move(prior), rig.skin_samples, options);
}

Status PropagationLearner::Add(const PointCache& vertex_offsets, int first_frame, int last_frame) {
  if (vertex_offsets.vertex_count != prior_.vertex_count()) {
    return InvalidArgumentError("propagation: offsets have " +
                                std::to_string(vertex_offsets.vertex_count) +
                                " vertices, the rig " + std::to_string(prior_.vertex_count()));
  }
  if (first_frame < 0 || last_frame > vertex_offsets.frame_count() || first_frame > last_frame) {
    return InvalidArgumentError("propagation: frame range [" + std::to_string(first_frame) + ", " +
                                std::to_string(last_frame) + ") outside the take's " +
                                std::to_string(vertex_offsets.frame_count()) + " frames");
  }
  const int sample_count = prior_.sample_count();
  const int frames = last_frame - first_frame;
  if (frames == 0) return Status::Ok();
  // Columns are (frame, component): x, y and z share W.
  Eigen::MatrixXd sample_columns(sample_count, 3L * frames);
  Eigen::MatrixXd vertex_columns(prior_.vertex_count(), 3L * frames);
  for (int t = first_frame; t < last_frame; ++t) {
    const auto frame = vertex_offsets.Frame(t);
    const Eigen::Index column = 3L * (t - first_frame);
    vertex_columns.middleCols(column, 3) = frame.transpose().cast<double>();
    for (int i = 0; i < sample_count; ++i) {
      sample_columns.block(i, column, 1, 3) =
          samples_[i].Evaluate(frame).cast<double>().transpose();
    }
  }
  sample_gram_.selfadjointView<Eigen::Lower>().rankUpdate(sample_columns);
  vertex_sample_.noalias() += vertex_columns * sample_columns.transpose();
  frames_ += frames;
  return Status::Ok();
}

StatusOr<SamplePropagation> PropagationLearner::Fit() const {
  FACEDYN_RETURN_IF_ERROR(options_.Check());
  if (frames_ == 0) return FailedPreconditionError("propagation: no training frames to learn from");
  const int sample_count = prior_.sample_count();
  Eigen::MatrixXd gram = sample_gram_.selfadjointView<Eigen::Lower>();
  const double mu = options_.prior_weight * std::max(gram.trace() / sample_count, 1e-12);
  gram.diagonal().array() += mu;
  const Eigen::MatrixXd rhs = vertex_sample_ + mu * prior_.weights().cast<double>();
  // W (G + mu I) = rhs, with G + mu I symmetric positive definite: solve for W^T.
  const Eigen::LLT<Eigen::MatrixXd> llt(gram);
  if (llt.info() != Eigen::Success) return InternalError("propagation: learned system not SPD");
  const Eigen::MatrixXd weights = llt.solve(rhs.transpose()).transpose();
  if (!weights.allFinite()) return InternalError("propagation: learned solve is not finite");
  return SamplePropagation::FromWeights(weights.cast<float>(), "learned");
}

void SamplePropagation::Apply(const Eigen::Ref<const Eigen::Matrix3Xf>& sample_offsets,
                              Eigen::Ref<Eigen::Matrix3Xf> vertex_offsets) const {
  FACEDYN_CHECK(sample_offsets.cols() == sample_count() && vertex_offsets.cols() == vertex_count(),
                "SamplePropagation::Apply: wrong sizes");
  vertex_offsets.noalias() = sample_offsets * weights_transposed_;
}

}  // namespace facedyn::dynamics
