#include "physics/inertial_deflection.h"

#include <fmt/format.h>

#include <Eigen/CholmodSupport>
#include <Eigen/QR>
#include <Eigen/SparseCore>

namespace facedyn::physics {

StatusOr<Eigen::MatrixXd> MarkerInertialDeflectionBasis(const FaceRig& rig,
                                                        const InertialDeflectionOptions& options) {
  if (rig.markers.empty())
    return InvalidArgumentError("inertial deflection basis: the rig has no markers");
  TissueMaterial material;
  material.youngs_modulus_kpa = 1.0;  // shapes only: every column is normalised below
  auto model = SoftTissueModel::Create(rig, options.tissue, material);
  if (!model.ok()) return model.status().WithContext("inertial deflection basis");
  const Eigen::VectorXd neutral = Eigen::VectorXd::Zero(rig.blendshape_names.size());
  auto reference = (*model)->SetReference(neutral, 0.0, options.tissue.max_step_s);
  if (!reference.ok()) return reference.status().WithContext("inertial deflection basis");
  const Eigen::VectorXi one_group = Eigen::VectorXi::Zero((*model)->shell().tets.cols());
  auto parts = (*model)->SystemParts(one_group, 1);
  if (!parts.ok()) return parts.status().WithContext("inertial deflection basis");
  Eigen::SparseMatrix<double> stiffness = parts->stiffness_by_group[0];
  for (int i = 0; i < stiffness.rows(); ++i) stiffness.coeffRef(i, i) += parts->spring_dofs[i];
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> solver(stiffness);
  if (solver.info() != Eigen::Success) {
    return InternalError(
        "inertial deflection basis: the tissue's stiffness is not positive definite");
  }
  if (options.krylov_blocks < 1) {
    return InvalidArgumentError("inertial deflection basis: krylov_blocks must be >= 1");
  }
  const int loads = options.angular ? 6 : 3;
  const int columns = loads * options.krylov_blocks;
  Eigen::MatrixXd response(stiffness.rows(), columns);
  response.leftCols(loads) = solver.solve(parts->load_fields.leftCols(loads));
  for (int block = 1; block < options.krylov_blocks; ++block) {
    const Eigen::MatrixXd previous = response.middleCols((block - 1) * loads, loads);
    response.middleCols(block * loads, loads) =
        solver.solve(parts->mass_dofs.asDiagonal() * previous);
  }
  const int vertices = rig.neutral.vertex_count();
  const int markers = static_cast<int>(rig.markers.size());
  Eigen::MatrixXd basis(3 * markers, columns);
  for (int c = 0; c < columns; ++c) {
    Eigen::Matrix3Xd skin = Eigen::Matrix3Xd::Zero(3, vertices);
    for (int v = 0; v < vertices; ++v) {
      const int dof = parts->skin_dof[v];
      if (dof >= 0) skin.col(v) = response.block<3, 1>(dof, c);
    }
    for (int m = 0; m < markers; ++m)
      basis.block<3, 1>(3 * m, c) = rig.markers[m].point.Evaluate(skin);
    const double rms = std::sqrt(basis.col(c).squaredNorm() / markers);
    if (!(rms > 0) || !std::isfinite(rms)) {
      return InternalError(fmt::format("inertial deflection basis: load {} moves no marker", c));
    }
    basis.col(c) /= rms;
  }
  if (options.krylov_blocks > 1) {
    const Eigen::HouseholderQR<Eigen::MatrixXd> qr(basis);
    basis = qr.householderQ() * Eigen::MatrixXd::Identity(basis.rows(), columns) *
            std::sqrt(static_cast<double>(markers));
  }
  return basis;
}

}  // namespace facedyn::physics
