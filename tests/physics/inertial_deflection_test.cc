// The tissue model's deflection shapes at the markers (physics/inertial_deflection.h), checked
// against the model's own quasistatic response to gravity (computed by SoftTissueModel::Create,
// a separate path) and for the Krylov blocks' algebra.

#include "physics/inertial_deflection.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "tests/physics/shell_rig.h"

namespace facedyn::physics {
namespace {

// The shell patch with a marker on every 5th skin vertex.
FaceRig ShellWithMarkers() {
  FaceRig rig = MakeShellRig();
  for (int v = 0; v < rig.vertex_count(); v += 5) {
    Marker marker;
    marker.name = "m" + std::to_string(v);
    marker.point.vertices = {v, v, v};
    marker.point.weights = Eigen::Vector3d(1, 0, 0);
    rig.markers.push_back(marker);
  }
  return rig;
}

Eigen::VectorXd AtMarkers(const FaceRig& rig, const Eigen::Matrix3Xd& skin) {
  Eigen::VectorXd out(3 * rig.markers.size());
  for (size_t m = 0; m < rig.markers.size(); ++m) {
    out.segment<3>(3 * m) = rig.markers[m].point.Evaluate(skin);
  }
  return out;
}

// A uniform acceleration of the flesh along a skull axis is what tilting gravity does to it:
// each static column must point the way the model's quasistatic skin moves when gravity in the
// skull frame changes along that axis.
TEST(MarkerInertialDeflectionBasis, MatchesTheModelsQuasistaticGravityResponse) {
  const FaceRig rig = ShellWithMarkers();
  InertialDeflectionOptions options;
  options.angular = false;
  const auto basis = MarkerInertialDeflectionBasis(rig, options);
  ASSERT_TRUE(basis.ok()) << basis.status().ToString();
  ASSERT_EQ(basis->rows(), 3 * static_cast<Eigen::Index>(rig.markers.size()));
  ASSERT_EQ(basis->cols(), 3);
  auto model = SoftTissueModel::Create(rig, TissueOptions());
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  ASSERT_TRUE((*model)->SetReference(Eigen::VectorXd::Zero(1), 0.0, 1.0 / 128).ok());
  TissueForcing upright;
  upright.weights = Eigen::VectorXd::Zero(1);
  const Eigen::VectorXd rest = AtMarkers(rig, (*model)->QuasistaticSkin(upright));
  for (int tilt = 0; tilt < 2; ++tilt) {
    // Tilting the skull about z (then about x) changes gravity in the skull frame along x and
    // y (then y and z); the quasistatic change must lie in the basis's span, and the column
    // along which gravity did not change must not be used.
    const Eigen::Vector3d axis_of_rotation =
        tilt == 0 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
    TissueForcing tilted = upright;
    tilted.kinematics.world_from_skull =
        Rigid3::FromAxisAngle(axis_of_rotation, 0.3, Eigen::Vector3d::Zero());
    const Eigen::Vector3d dg = tilted.kinematics.GravityInSkull() - kGravityInWorld;
    const Eigen::VectorXd moved = AtMarkers(rig, (*model)->QuasistaticSkin(tilted)) - rest;
    // The basis is linear in the load: the change is basis * (a coefficient per column).
    const Eigen::VectorXd scales =
        basis->colPivHouseholderQr().solve(moved);  // mm per normalised column
    const Eigen::VectorXd residual = *basis * scales - moved;
    EXPECT_LT(residual.norm(), 1e-6 * moved.norm()) << "tilt " << tilt;
    for (int c = 0; c < 3; ++c) {
      if (std::abs(dg[c]) < 1e-9 * dg.norm()) {
        EXPECT_LT(std::abs(scales[c]), 1e-6 * scales.norm()) << "column " << c;
      }
    }
  }
}

TEST(MarkerInertialDeflectionBasis, KrylovBlocksAreOrthonormalAndKeepTheStaticShapes) {
  const FaceRig rig = ShellWithMarkers();
  InertialDeflectionOptions options;
  options.angular = false;
  const auto static_basis = MarkerInertialDeflectionBasis(rig, options);
  options.krylov_blocks = 2;
  const auto ritz = MarkerInertialDeflectionBasis(rig, options);
  ASSERT_TRUE(static_basis.ok() && ritz.ok());
  ASSERT_EQ(ritz->cols(), 6);
  const double markers = static_cast<double>(rig.markers.size());
  // Orthonormal over the markers, scaled to unit RMS per column.
  EXPECT_LT((ritz->transpose() * *ritz - markers * Eigen::MatrixXd::Identity(6, 6)).norm(),
            1e-8 * markers);
  // The static shapes lie in the Ritz span.
  const Eigen::MatrixXd projected = *ritz * (ritz->transpose() * *static_basis) / markers;
  EXPECT_LT((projected - *static_basis).norm(), 1e-8 * static_basis->norm());
  // ... and the second block adds a direction the static ones do not have.
  const Eigen::MatrixXd back = *static_basis * static_basis->colPivHouseholderQr().solve(*ritz);
  EXPECT_GT((back - *ritz).norm(), 1e-3 * ritz->norm());
  // Unit RMS per column with angular loads too.
  options.angular = true;
  options.krylov_blocks = 1;
  const auto six = MarkerInertialDeflectionBasis(rig, options);
  ASSERT_TRUE(six.ok());
  ASSERT_EQ(six->cols(), 6);
  for (int c = 0; c < 6; ++c) EXPECT_NEAR(six->col(c).squaredNorm() / markers, 1.0, 1e-9);
}

TEST(MarkerInertialDeflectionBasis, BadInputIsNamed) {
  FaceRig rig = MakeShellRig();
  auto no_markers = MarkerInertialDeflectionBasis(rig, InertialDeflectionOptions());
  EXPECT_EQ(no_markers.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(no_markers.status().message().find("no markers"), std::string::npos);
  rig = ShellWithMarkers();
  InertialDeflectionOptions options;
  options.krylov_blocks = 0;
  auto blocks = MarkerInertialDeflectionBasis(rig, options);
  EXPECT_EQ(blocks.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(blocks.status().message().find("krylov_blocks"), std::string::npos);
}

}  // namespace
}  // namespace facedyn::physics
