#include "hanzo/fusion/core/se2.hpp"

#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "support/numerical_jacobian.hpp"

namespace hanzo::fusion {
namespace {

using testing::numerical_jacobian;

void expect_near(const Eigen::MatrixXd& actual, const Eigen::MatrixXd& expected, double tolerance) {
  EXPECT_LE((actual - expected).cwiseAbs().maxCoeff(), tolerance) << "actual:\n" << actual << "\nexpected:\n" << expected;
}

TEST(SE2, ExpLogRoundTripIncludingSmallAngles) {
  for (const Eigen::Vector3d& tangent : {Eigen::Vector3d(1, 2, 0), Eigen::Vector3d(1, 2, 1e-9), Eigen::Vector3d(-3, 0.5, 0.7),
                                         Eigen::Vector3d(0.2, -4, -3.0), Eigen::Vector3d(0, 0, std::numbers::pi - 1e-6)}) {
    expect_near(SE2::exp(tangent).log(), tangent, 1e-9);
  }
}

TEST(SE2, ComposeMatchesMatricesAndWrapsAngles) {
  const SE2 a(3.0, {1.0, 2.0});
  const SE2 b(1.0, {-0.5, 0.3});
  expect_near((a * b).matrix(), a.matrix() * b.matrix(), 1e-14);
  EXPECT_NEAR((a * b).angle(), SE2::wrap_angle(4.0), 1e-15);
  EXPECT_LE(std::abs((a * b).angle()), std::numbers::pi);
  expect_near((a * a.inverse()).matrix(), Eigen::Matrix3d::Identity(), 1e-15);
  expect_near(a * Eigen::Vector2d(1, 1), (a.matrix() * Eigen::Vector3d(1, 1, 1)).head<2>(), 1e-14);
  EXPECT_DOUBLE_EQ(SE2::wrap_angle(std::numbers::pi), std::numbers::pi);
  EXPECT_DOUBLE_EQ(SE2::wrap_angle(-std::numbers::pi), std::numbers::pi);
}

TEST(SE2, AdjointAndJacobiansMatchFiniteDifferences) {
  const SE2 x(0.8, {1.0, -2.0});
  const SE2 y(-2.1, {0.4, 0.9});
  const Eigen::Vector3d xi(0.01, -0.02, 0.03);
  expect_near((x * SE2::exp(xi)).matrix(), (SE2::exp(x.adjoint() * xi) * x).matrix(), 1e-14);
  SE2::Jacobian j_inverse, j_this, j_other;
  x.inverse(&j_inverse);
  expect_near(j_inverse, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (x * (x * SE2::exp(d)).inverse()).log(); }), 1e-6);
  const SE2 z = x.compose(y, &j_this, &j_other);
  expect_near(j_this, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (z.inverse() * (x * SE2::exp(d) * y)).log(); }), 1e-6);
  expect_near(j_other, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (z.inverse() * (x * y * SE2::exp(d))).log(); }), 1e-6);
}

TEST(SE2, LeftRightExpAndLogJacobiansMatchFiniteDifferences) {
  for (const Eigen::Vector3d& tangent : {Eigen::Vector3d(1.0, -2.0, 0.0), Eigen::Vector3d(1.0, -2.0, 1e-7), Eigen::Vector3d(0.5, 0.3, -1.2),
                                         Eigen::Vector3d(-3.0, 1.0, 2.5), Eigen::Vector3d(2.0, 2.0, -3.0)}) {
    const SE2 x = SE2::exp(tangent);
    expect_near(SE2::right_jacobian(tangent),
                numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (x.inverse() * SE2::exp(tangent + d)).log(); }), 1e-6);
    expect_near(SE2::left_jacobian(tangent),
                numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (SE2::exp(tangent + d) * x.inverse()).log(); }), 1e-6);
    SE2::Jacobian j_exp, j_log;
    SE2::exp(tangent, &j_exp);
    expect_near(j_exp, SE2::right_jacobian(tangent), 0.0);
    x.log(&j_log);
    expect_near(j_log, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return (x * SE2::exp(d)).log(); }), 1e-6);
    expect_near(SE2::left_jacobian_inverse(tangent) * SE2::left_jacobian(tangent), Eigen::Matrix3d::Identity(), 1e-12);
  }
}

TEST(SE2, Interpolation) {
  const SE2 a(0.1, {0, 0});
  const SE2 b(1.1, {2, 1});
  expect_near(SE2::interpolate(a, b, 1.0).matrix(), b.matrix(), 1e-13);
  EXPECT_NEAR(SE2::interpolate(a, b, 0.5).angle(), 0.6, 1e-14);
}

}  // namespace
}  // namespace hanzo::fusion
