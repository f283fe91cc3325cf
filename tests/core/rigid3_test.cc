// Rigid3 against independent Eigen references (Eigen::Isometry3d, plain 4x4 matrices).
#include "core/rigid3.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <random>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A random rigid transform with a uniformly distributed rotation and translation in
// [-100, 100] mm, from a seeded generator so failures reproduce.
Rigid3 RandomRigid(std::mt19937* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-100.0, 100.0);
  Eigen::Quaterniond q(normal(*rng), normal(*rng), normal(*rng), normal(*rng));
  return Rigid3(q, Eigen::Vector3d(uniform(*rng), uniform(*rng), uniform(*rng)));
}

// The reference: the same transform as an Eigen isometry built from a rotation matrix.
Eigen::Isometry3d ToIsometry(const Rigid3& t) {
  Eigen::Isometry3d iso = Eigen::Isometry3d::Identity();
  iso.linear() = t.rotation().toRotationMatrix();
  iso.translation() = t.translation();
  return iso;
}

TEST(Rigid3Construct, NormalisesTheQuaternion) {
  const Rigid3 t(Eigen::Quaterniond(2.0, 0.0, 0.0, 0.0), Eigen::Vector3d(1, 2, 3));
  EXPECT_NEAR(t.rotation().norm(), 1.0, 1e-15);
  EXPECT_EIGEN_NEAR(t.RotationMatrix(), Eigen::Matrix3d::Identity(), 1e-15);
  EXPECT_EIGEN_NEAR(t.translation(), Eigen::Vector3d(1, 2, 3), 0.0);
}

TEST(Rigid3Compose, MatchesMatrixProduct) {
  std::mt19937 rng(1234);
  for (int i = 0; i < 50; ++i) {
    const Rigid3 a_from_b = RandomRigid(&rng);
    const Rigid3 b_from_c = RandomRigid(&rng);
    const Eigen::Matrix4d expected = a_from_b.ToMatrix4() * b_from_c.ToMatrix4();
    EXPECT_EIGEN_NEAR((a_from_b * b_from_c).ToMatrix4(), expected, 1e-10);
    const Eigen::Isometry3d iso = ToIsometry(a_from_b) * ToIsometry(b_from_c);
    EXPECT_EIGEN_NEAR((a_from_b * b_from_c).ToMatrix4(), iso.matrix(), 1e-10);
  }
}

TEST(Rigid3Compose, IsAssociative) {
  std::mt19937 rng(77);
  const Rigid3 a = RandomRigid(&rng), b = RandomRigid(&rng), c = RandomRigid(&rng);
  EXPECT_TRUE(((a * b) * c).IsApprox(a * (b * c), 1e-12));
}

TEST(Rigid3Inverse, InverseTimesSelfIsIdentity) {
  std::mt19937 rng(42);
  for (int i = 0; i < 50; ++i) {
    const Rigid3 t = RandomRigid(&rng);
    EXPECT_EIGEN_NEAR((t.Inverse() * t).ToMatrix4(), Eigen::Matrix4d::Identity(), 1e-12);
    EXPECT_EIGEN_NEAR((t * t.Inverse()).ToMatrix4(), Eigen::Matrix4d::Identity(), 1e-12);
    EXPECT_EIGEN_NEAR(t.Inverse().ToMatrix4(), t.ToMatrix4().inverse().eval(), 1e-10);
    EXPECT_EIGEN_NEAR(t.Inverse().ToMatrix4(), ToIsometry(t).inverse().matrix(), 1e-10);
  }
}

TEST(Rigid3ApplyPoint, MatchesHomogeneousMatrix) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(-50.0, 50.0);
  for (int i = 0; i < 50; ++i) {
    const Rigid3 t = RandomRigid(&rng);
    const Eigen::Vector3d p(uniform(rng), uniform(rng), uniform(rng));
    const Eigen::Vector4d expected = t.ToMatrix4() * p.homogeneous();
    EXPECT_EIGEN_NEAR(t * p, expected.head<3>(), 1e-10);
    EXPECT_EIGEN_NEAR(t * p, ToIsometry(t) * p, 1e-10);
    // A direction ignores the translation.
    EXPECT_EIGEN_NEAR(t.RotateVector(p), (t.RotationMatrix() * p).eval(), 1e-10);
  }
}

TEST(Rigid3ApplyPoint, KnownRotationAboutZ) {
  // 90 degrees about +Z maps +X to +Y (right-handed), then translates.
  const Rigid3 t =
      Rigid3::FromAxisAngle(Eigen::Vector3d::UnitZ(), kPi / 2, Eigen::Vector3d(0, 0, 5));
  EXPECT_EIGEN_NEAR(t * Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, 1, 5), 1e-12);
  EXPECT_EIGEN_NEAR(t * Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(-1, 0, 5), 1e-12);
}

TEST(Rigid3Apply, BlockMatchesPerColumn) {
  std::mt19937 rng(99);
  const Rigid3 t = RandomRigid(&rng);
  const Eigen::Matrix3Xd points = Eigen::Matrix3Xd::Random(3, 17) * 40.0;
  const Eigen::Matrix3Xd moved = t.Apply(points);
  ASSERT_EQ(moved.cols(), 17);
  Eigen::Matrix4Xd homogeneous(4, 17);
  homogeneous << points, Eigen::RowVectorXd::Ones(17);
  const Eigen::Matrix4Xd expected = t.ToMatrix4() * homogeneous;
  EXPECT_EIGEN_NEAR(moved, expected.topRows<3>(), 1e-10);
  for (int i = 0; i < 17; ++i)
    EXPECT_EIGEN_NEAR(moved.col(i), t * Eigen::Vector3d(points.col(i)), 1e-12);
}

TEST(Rigid3Apply, EmptyBlock) {
  const Rigid3 t = Rigid3::FromTranslation(Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(t.Apply(Eigen::Matrix3Xd(3, 0)).cols(), 0);
}

TEST(Rigid3Matrix4, RoundTrip) {
  std::mt19937 rng(5);
  for (int i = 0; i < 50; ++i) {
    const Rigid3 t = RandomRigid(&rng);
    const Eigen::Matrix4d m = t.ToMatrix4();
    EXPECT_EIGEN_NEAR(m.row(3), Eigen::RowVector4d(0, 0, 0, 1), 0.0);
    ASSERT_TRUE(Rigid3::IsRigidMatrix(m));
    const Rigid3 back = Rigid3::FromMatrix4(m);
    EXPECT_TRUE(back.IsApprox(t, 1e-12));
    EXPECT_EIGEN_NEAR(back.ToMatrix4(), m, 1e-12);
  }
}

TEST(Rigid3Matrix4, FromEigenIsometry) {
  const Eigen::Isometry3d iso = Eigen::Translation3d(3, -4, 5) *
                                Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized());
  const Rigid3 t = Rigid3::FromMatrix4(iso.matrix());
  EXPECT_EIGEN_NEAR(t.translation(), Eigen::Vector3d(3, -4, 5), 1e-12);
  EXPECT_NEAR(t.AngleRad(), 0.7, 1e-12);
  EXPECT_EIGEN_NEAR(t * Eigen::Vector3d(1, 1, 1), iso * Eigen::Vector3d(1, 1, 1), 1e-12);
}

TEST(Rigid3IsRigidMatrix, AcceptsRotationsWithinTolerance) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = Eigen::AngleAxisd(1.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  m.topRightCorner<3, 1>() << 100, 200, -300;
  EXPECT_TRUE(Rigid3::IsRigidMatrix(m));
  m(0, 0) += 1e-9;
  EXPECT_TRUE(Rigid3::IsRigidMatrix(m));
}

TEST(Rigid3IsRigidMatrix, RejectsScaled) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() *= 1.01;
  EXPECT_FALSE(Rigid3::IsRigidMatrix(m));
  // Uniform scale of one axis.
  m = Eigen::Matrix4d::Identity();
  m(2, 2) = 2.0;
  EXPECT_FALSE(Rigid3::IsRigidMatrix(m));
}

TEST(Rigid3IsRigidMatrix, RejectsSheared) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m(0, 1) = 0.1;
  EXPECT_FALSE(Rigid3::IsRigidMatrix(m));
}

TEST(Rigid3IsRigidMatrix, RejectsReflection) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m(0, 0) = -1.0;  // orthonormal, det -1
  EXPECT_FALSE(Rigid3::IsRigidMatrix(m));
}

TEST(Rigid3IsRigidMatrix, RejectsBadBottomRow) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m(3, 0) = 0.5;
  EXPECT_FALSE(Rigid3::IsRigidMatrix(m));
  m = Eigen::Matrix4d::Identity();
  m(3, 3) = 2.0;
  EXPECT_FALSE(Rigid3::IsRigidMatrix(m));
}

TEST(Rigid3IsRigidMatrix, RejectsNonFinite) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m(1, 3) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(Rigid3::IsRigidMatrix(m));
  m = Eigen::Matrix4d::Identity();
  m(0, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(Rigid3::IsRigidMatrix(m));
  m = Eigen::Matrix4d::Identity();
  m(2, 3) = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(Rigid3::IsRigidMatrix(m));
}

TEST(Rigid3AngleRad, KnownRotations) {
  EXPECT_DOUBLE_EQ(Rigid3::Identity().AngleRad(), 0.0);
  EXPECT_DOUBLE_EQ(Rigid3::FromTranslation(Eigen::Vector3d(5, 6, 7)).AngleRad(), 0.0);
  for (double angle : {1e-8, 0.01, 0.5, kPi / 2, 2.0, 3.0}) {
    const Rigid3 t = Rigid3::FromAxisAngle(Eigen::Vector3d(1, -2, 0.5), angle);
    EXPECT_NEAR(t.AngleRad(), angle, 1e-12) << "angle " << angle;
    // Reference: Eigen's angle-axis of the rotation matrix.
    EXPECT_NEAR(t.AngleRad(), Eigen::AngleAxisd(t.RotationMatrix()).angle(), 1e-9);
  }
}

TEST(Rigid3AngleRad, NegativeAngleIsReportedPositive) {
  const Rigid3 t = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), -0.8);
  EXPECT_NEAR(t.AngleRad(), 0.8, 1e-12);
}

TEST(Rigid3AngleRad, NearPi) {
  for (double angle : {kPi - 1e-3, kPi - 1e-7, kPi}) {
    const Rigid3 t = Rigid3::FromAxisAngle(Eigen::Vector3d(0, 1, 1), angle);
    EXPECT_NEAR(t.AngleRad(), angle, 1e-12) << "angle " << angle;
  }
  // Beyond pi the shorter rotation is reported: 3pi/2 about +Z is pi/2 about -Z.
  EXPECT_NEAR(Rigid3::FromAxisAngle(Eigen::Vector3d::UnitZ(), 1.5 * kPi).AngleRad(), kPi / 2,
              1e-12);
  // q and -q give the same angle.
  const Rigid3 flipped(Eigen::Quaterniond(-std::cos(1.4), 0, 0, -std::sin(1.4)),
                       Eigen::Vector3d::Zero());
  EXPECT_NEAR(flipped.AngleRad(), 2.8, 1e-12);
}

TEST(Rigid3AngleRad, OfRelativeTransform) {
  std::mt19937 rng(11);
  const Rigid3 a = RandomRigid(&rng);
  const Rigid3 delta =
      Rigid3::FromAxisAngle(Eigen::Vector3d(3, 1, -1), 0.25, Eigen::Vector3d(1, 1, 1));
  EXPECT_NEAR((a.Inverse() * (a * delta)).AngleRad(), 0.25, 1e-10);
}

TEST(Rigid3Interpolate, EndPoints) {
  std::mt19937 rng(3);
  const Rigid3 a = RandomRigid(&rng);
  const Rigid3 b = RandomRigid(&rng);
  EXPECT_TRUE(Rigid3::Interpolate(a, b, 0.0).IsApprox(a, 1e-12));
  EXPECT_TRUE(Rigid3::Interpolate(a, b, 1.0).IsApprox(b, 1e-12));
}

TEST(Rigid3Interpolate, MidpointHalvesTheAngleAndTranslation) {
  const Eigen::Vector3d axis = Eigen::Vector3d(1, 2, -1).normalized();
  const Rigid3 a(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 0));
  const Rigid3 b = Rigid3::FromAxisAngle(axis, 1.2, Eigen::Vector3d(10, -20, 30));
  const Rigid3 mid = Rigid3::Interpolate(a, b, 0.5);
  EXPECT_NEAR(mid.AngleRad(), 0.6, 1e-12);
  EXPECT_TRUE(mid.IsApprox(Rigid3::FromAxisAngle(axis, 0.6, Eigen::Vector3d(5, -10, 15)), 1e-12));
  // The relative rotation from a to mid equals that from mid to b.
  EXPECT_NEAR((a.Inverse() * mid).AngleRad(), (mid.Inverse() * b).AngleRad(), 1e-12);
}

TEST(Rigid3Interpolate, TranslationIsLinear) {
  std::mt19937 rng(21);
  const Rigid3 a = RandomRigid(&rng);
  const Rigid3 b = RandomRigid(&rng);
  for (double t : {0.1, 0.25, 0.5, 0.9}) {
    const Eigen::Vector3d expected = a.translation() + t * (b.translation() - a.translation());
    EXPECT_EIGEN_NEAR(Rigid3::Interpolate(a, b, t).translation(), expected, 1e-10);
  }
}

TEST(Rigid3Interpolate, RotationAngleGrowsLinearly) {
  const Eigen::Vector3d axis = Eigen::Vector3d::UnitY();
  const Rigid3 a = Rigid3::FromAxisAngle(axis, 0.2);
  const Rigid3 b = Rigid3::FromAxisAngle(axis, 1.8);
  for (double t : {0.0, 0.3, 0.5, 0.7, 1.0}) {
    const Rigid3 expected = Rigid3::FromAxisAngle(axis, 0.2 + t * 1.6);
    EXPECT_TRUE(Rigid3::Interpolate(a, b, t).IsApprox(expected, 1e-12)) << "t = " << t;
  }
}

TEST(Rigid3Interpolate, TakesShorterArcWhenQuaternionsDisagreeInSign) {
  // a: +170 degrees about Z; b: -170 degrees about Z. The short way between them passes
  // through 180 degrees (20 degrees of travel), not through 0 (340 degrees).
  const Rigid3 a = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitZ(), 170.0 * kPi / 180.0);
  const Rigid3 b = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitZ(), -170.0 * kPi / 180.0);
  ASSERT_LT(a.rotation().dot(b.rotation()), 0.0) << "the test needs quaternions of opposite sign";
  const Rigid3 mid = Rigid3::Interpolate(a, b, 0.5);
  EXPECT_NEAR(mid.AngleRad(), kPi, 1e-9);
  EXPECT_NEAR((a.Inverse() * mid).AngleRad(), 10.0 * kPi / 180.0, 1e-9);
  EXPECT_NEAR((mid.Inverse() * b).AngleRad(), 10.0 * kPi / 180.0, 1e-9);

  // Same rotation, written with a negated quaternion: interpolation must not swing around.
  const Rigid3 c = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), 0.4);
  const Rigid3 c_negated(Eigen::Quaterniond(-c.rotation().coeffs()), Eigen::Vector3d::Zero());
  const Rigid3 d = Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), 0.6);
  ASSERT_LT(c_negated.rotation().dot(d.rotation()), 0.0);
  EXPECT_TRUE(Rigid3::Interpolate(c_negated, d, 0.5)
                  .IsApprox(Rigid3::FromAxisAngle(Eigen::Vector3d::UnitX(), 0.5), 1e-12));
}

TEST(Rigid3IsApprox, TreatsNegatedQuaternionAsSameRotation) {
  const Rigid3 t = Rigid3::FromAxisAngle(Eigen::Vector3d(1, 1, 0), 0.9, Eigen::Vector3d(1, 2, 3));
  const Rigid3 negated(Eigen::Quaterniond(-t.rotation().coeffs()), t.translation());
  EXPECT_TRUE(t.IsApprox(negated));
  EXPECT_FALSE(t.IsApprox(
      Rigid3::FromAxisAngle(Eigen::Vector3d(1, 1, 0), 0.9 + 1e-4, Eigen::Vector3d(1, 2, 3))));
  EXPECT_FALSE(t.IsApprox(Rigid3(t.rotation(), t.translation() + Eigen::Vector3d(0, 0, 1e-3))));
}

TEST(Rigid3Random, LongProductsStayRigid) {
  std::mt19937 rng(2024);
  Rigid3 product;
  Eigen::Matrix4d reference = Eigen::Matrix4d::Identity();
  for (int i = 0; i < 200; ++i) {
    const Rigid3 step = RandomRigid(&rng);
    product = product * step;
    reference = reference * step.ToMatrix4();
  }
  EXPECT_NEAR(product.rotation().norm(), 1.0, 1e-14);
  EXPECT_TRUE(Rigid3::IsRigidMatrix(product.ToMatrix4(), 1e-12));
  // Translations grow to ~1e3 mm; compare relative to that scale.
  EXPECT_EIGEN_NEAR(product.ToMatrix4(), reference, 1e-8 * (1.0 + reference.norm()));
}

}  // namespace
}  // namespace facedyn
