#include "hanzo/fusion/core/so3.hpp"

#include <cmath>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "support/numerical_jacobian.hpp"

namespace hanzo::fusion {
namespace {

using testing::numerical_jacobian;
constexpr double kPi = std::numbers::pi;

// Rotation vectors covering the identity, generic angles and the neighbourhood of pi.
std::vector<Eigen::Vector3d> test_rotation_vectors() {
  std::vector<Eigen::Vector3d> vectors = {Eigen::Vector3d::Zero(),
                                          Eigen::Vector3d(1e-9, -2e-9, 3e-9),
                                          Eigen::Vector3d(1e-6, 0.0, -1e-6),
                                          Eigen::Vector3d(0.1, -0.2, 0.3),
                                          Eigen::Vector3d(1.0, 0.5, -0.7),
                                          Eigen::Vector3d(0.0, 0.0, kPi - 1e-6),
                                          Eigen::Vector3d(kPi - 1e-3, 0.0, 0.0),
                                          Eigen::Vector3d(1.0, 1.0, 1.0).normalized() * (kPi - 1e-9)};
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> uniform(-2.0, 2.0);
  for (int i = 0; i < 20; ++i) vectors.emplace_back(uniform(rng), uniform(rng), uniform(rng));
  return vectors;
}

void expect_near(const Eigen::MatrixXd& actual, const Eigen::MatrixXd& expected, double tolerance) {
  ASSERT_EQ(actual.rows(), expected.rows());
  ASSERT_EQ(actual.cols(), expected.cols());
  EXPECT_LE((actual - expected).cwiseAbs().maxCoeff(), tolerance) << "actual:\n" << actual << "\nexpected:\n" << expected;
}

TEST(SO3, ExpOfLogIsIdentityMap) {
  for (const Eigen::Vector3d& phi : test_rotation_vectors()) {
    const SO3 rotation = SO3::exp(phi);
    expect_near(SO3::exp(rotation.log()).matrix(), rotation.matrix(), 1e-12);
  }
}

TEST(SO3, LogOfExpRecoversVectorsWithAngleBelowPi) {
  for (const Eigen::Vector3d& phi : test_rotation_vectors()) {
    if (phi.norm() >= kPi) continue;
    expect_near(SO3::exp(phi).log(), phi, 1e-9);
  }
}

TEST(SO3, ExpMatchesEigenAngleAxis) {
  for (const Eigen::Vector3d& phi : test_rotation_vectors()) {
    if (phi.norm() < 1e-12) continue;
    const Eigen::Matrix3d expected = Eigen::AngleAxisd(phi.norm(), phi.normalized()).toRotationMatrix();
    expect_near(SO3::exp(phi).matrix(), expected, 1e-12);
  }
}

TEST(SO3, LogNearPiKeepsFullPrecision) {
  const Eigen::Vector3d axis = Eigen::Vector3d(0.3, -0.4, 0.5).normalized();
  for (double angle : {kPi, kPi - 1e-12, kPi - 1e-8, kPi - 1e-4}) {
    const SO3 rotation = SO3::from_axis_angle(axis, angle);
    const Eigen::Vector3d phi = rotation.log();
    EXPECT_NEAR(phi.norm(), angle, 1e-9);
    EXPECT_NEAR(std::abs(phi.normalized().dot(axis)), 1.0, 1e-9);
    expect_near(SO3::exp(phi).matrix(), rotation.matrix(), 1e-12);
  }
}

TEST(SO3, GroupAxioms) {
  const SO3 a = SO3::exp({0.1, 0.2, -0.3});
  const SO3 b = SO3::exp({-1.0, 0.4, 0.9});
  const SO3 c = SO3::exp({2.0, -0.1, 0.5});
  expect_near(((a * b) * c).matrix(), (a * (b * c)).matrix(), 1e-14);            // associativity
  expect_near((a * SO3::identity()).matrix(), a.matrix(), 0.0);                   // identity
  expect_near((a * a.inverse()).matrix(), Eigen::Matrix3d::Identity(), 1e-15);   // inverse
  expect_near((a * b).matrix(), a.matrix() * b.matrix(), 1e-14);                  // matches matrices
  const Eigen::Vector3d p(1.0, -2.0, 3.0);
  expect_near(a * p, a.matrix() * p, 1e-14);
  expect_near(a.inverse() * (a * p), p, 1e-14);
}

TEST(SO3, QuaternionWxyzRoundTripAndCanonicalSign) {
  const Eigen::Vector4d wxyz = Eigen::Vector4d(0.5, -0.5, 0.5, -0.5);
  const SO3 rotation = SO3::from_wxyz(wxyz);
  expect_near(rotation.wxyz(), wxyz, 0.0);
  expect_near(SO3::from_matrix(rotation.matrix()).wxyz(), wxyz, 1e-15);
  // -q is the same rotation; it is stored with w >= 0.
  const SO3 negated = SO3::from_wxyz(-wxyz);
  expect_near(negated.wxyz(), wxyz, 0.0);
  expect_near(negated.matrix(), rotation.matrix(), 0.0);
}

TEST(SO3, AdjointMovesTangentVectorsAcross) {
  const SO3 rotation = SO3::exp({0.3, -0.8, 0.2});
  const Eigen::Vector3d phi(0.05, 0.02, -0.04);
  expect_near((rotation * SO3::exp(phi)).matrix(), (SO3::exp(rotation.adjoint() * phi) * rotation).matrix(), 1e-14);
}

TEST(SO3, LeftAndRightJacobiansMatchFiniteDifferences) {
  for (const Eigen::Vector3d& phi : test_rotation_vectors()) {
    if (phi.norm() > kPi - 1e-3) continue;  // log is not smooth across pi
    const SO3 rotation = SO3::exp(phi);
    const auto right = numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (rotation.inverse() * SO3::exp(phi + d)).log(); });
    const auto left = numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (SO3::exp(phi + d) * rotation.inverse()).log(); });
    expect_near(SO3::right_jacobian(phi), right, 1e-6);
    expect_near(SO3::left_jacobian(phi), left, 1e-6);
    expect_near(SO3::right_jacobian_inverse(phi) * SO3::right_jacobian(phi), Eigen::Matrix3d::Identity(), 1e-9);
    expect_near(SO3::left_jacobian_inverse(phi) * SO3::left_jacobian(phi), Eigen::Matrix3d::Identity(), 1e-9);
  }
}

TEST(SO3, OperationJacobiansMatchFiniteDifferences) {
  for (const Eigen::Vector3d& phi : test_rotation_vectors()) {
    if (phi.norm() > kPi - 1e-3) continue;
    const SO3 x = SO3::exp(phi);
    const SO3 y = SO3::exp(Eigen::Vector3d(0.4, -0.3, 0.9));
    const Eigen::Vector3d p(0.7, -1.2, 2.5);

    SO3::Jacobian j_exp, j_log, j_inverse, j_this, j_other;
    SO3::exp(phi, &j_exp);
    expect_near(j_exp, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (x.inverse() * SO3::exp(phi + d)).log(); }), 1e-6);

    x.log(&j_log);
    expect_near(j_log, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (x * SO3::exp(d)).log(); }), 1e-6);

    const SO3 x_inverse = x.inverse(&j_inverse);
    expect_near(j_inverse, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) {
                  return (x_inverse.inverse() * (x * SO3::exp(d)).inverse()).log();
                }), 1e-6);

    const SO3 z = x.compose(y, &j_this, &j_other);
    expect_near(j_this, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (z.inverse() * (x * SO3::exp(d) * y)).log(); }), 1e-6);
    expect_near(j_other, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (z.inverse() * (x * y * SO3::exp(d))).log(); }), 1e-6);

    Eigen::Matrix3d j_rotation, j_point;
    x.act(p, &j_rotation, &j_point);
    expect_near(j_rotation, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return Eigen::Vector3d((x * SO3::exp(d)) * p); }), 1e-6);
    expect_near(j_point, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return Eigen::Vector3d(x * (p + d)); }), 1e-6);
  }
}

TEST(SO3, InterpolationFollowsTheGeodesic) {
  const SO3 a = SO3::exp({0.1, 0.2, 0.3});
  const SO3 b = SO3::exp({-0.5, 0.9, 0.1});
  expect_near(SO3::interpolate(a, b, 0.0).matrix(), a.matrix(), 1e-14);
  expect_near(SO3::interpolate(a, b, 1.0).matrix(), b.matrix(), 1e-14);
  const SO3 middle = SO3::interpolate(a, b, 0.5);
  EXPECT_NEAR((a.inverse() * middle).angle(), (middle.inverse() * b).angle(), 1e-12);
  EXPECT_NEAR(2.0 * (a.inverse() * middle).angle(), (a.inverse() * b).angle(), 1e-12);
  // Agrees with Eigen's slerp.
  const Eigen::Quaterniond slerp = a.quaternion().slerp(0.3, b.quaternion());
  expect_near(SO3::interpolate(a, b, 0.3).matrix(), slerp.toRotationMatrix(), 1e-12);
}

}  // namespace
}  // namespace hanzo::fusion
