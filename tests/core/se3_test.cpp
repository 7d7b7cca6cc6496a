#include "hanzo/fusion/core/se3.hpp"

#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "support/numerical_jacobian.hpp"

namespace hanzo::fusion {
namespace {

using testing::numerical_jacobian;
using Vector6d = SE3::Tangent;

std::vector<Vector6d> test_twists() {
  std::vector<Vector6d> twists;
  const double pi = std::numbers::pi;
  for (const auto& [rho, phi] : std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>{
           {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()},
           {Eigen::Vector3d(1.0, 2.0, 3.0), Eigen::Vector3d::Zero()},
           {Eigen::Vector3d(1.0, 2.0, 3.0), Eigen::Vector3d(1e-7, -1e-7, 2e-7)},
           {Eigen::Vector3d(0.5, -1.0, 0.2), Eigen::Vector3d(5e-5, 1e-5, -3e-5)},
           {Eigen::Vector3d(-3.0, 0.5, 1.0), Eigen::Vector3d(0.3, -0.2, 0.7)},
           {Eigen::Vector3d(2.0, 0.0, -1.0), Eigen::Vector3d(0.0, 0.0, pi - 1e-3)}}) {
    Vector6d xi;
    xi << rho, phi;
    twists.push_back(xi);
  }
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(-1.5, 1.5);
  for (int i = 0; i < 20; ++i) {
    Vector6d xi;
    for (int k = 0; k < 6; ++k) xi[k] = uniform(rng) * (k < 3 ? 3.0 : 1.0);
    twists.push_back(xi);
  }
  return twists;
}

void expect_near(const Eigen::MatrixXd& actual, const Eigen::MatrixXd& expected, double tolerance) {
  EXPECT_LE((actual - expected).cwiseAbs().maxCoeff(), tolerance) << "actual:\n" << actual << "\nexpected:\n" << expected;
}

Eigen::Matrix4d hat(const Vector6d& xi) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Zero();
  m.topLeftCorner<3, 3>() = SO3::hat(xi.tail<3>());
  m.topRightCorner<3, 1>() = xi.head<3>();
  return m;
}

TEST(SE3, ExpMatchesMatrixExponentialSeries) {
  for (const Vector6d& xi : test_twists()) {
    // exp of the 4x4 twist matrix by scaling and squaring of a Taylor series.
    const Eigen::Matrix4d a = hat(xi) / 1024.0;
    Eigen::Matrix4d term = Eigen::Matrix4d::Identity();
    Eigen::Matrix4d sum = Eigen::Matrix4d::Identity();
    for (int k = 1; k < 20; ++k) {
      term = term * a / k;
      sum += term;
    }
    for (int k = 0; k < 10; ++k) sum = sum * sum;
    expect_near(SE3::exp(xi).matrix(), sum, 1e-9);
  }
}

TEST(SE3, ExpLogRoundTrip) {
  for (const Vector6d& xi : test_twists()) {
    expect_near(SE3::exp(xi).log(), xi, 1e-9);
    const SE3 pose = SE3::exp(xi);
    expect_near(SE3::exp(pose.log()).matrix(), pose.matrix(), 1e-12);
  }
}

TEST(SE3, GroupAxiomsAndAction) {
  const SE3 a = SE3::exp((Vector6d() << 1, 2, 3, 0.1, 0.2, 0.3).finished());
  const SE3 b = SE3::exp((Vector6d() << -1, 0.5, 2, -0.4, 0.1, 0.9).finished());
  const SE3 c = SE3::exp((Vector6d() << 0.3, -2, 1, 1.0, -0.5, 0.2).finished());
  expect_near(((a * b) * c).matrix(), (a * (b * c)).matrix(), 1e-13);
  expect_near((a * a.inverse()).matrix(), Eigen::Matrix4d::Identity(), 1e-14);
  expect_near((a * b).matrix(), a.matrix() * b.matrix(), 1e-13);
  const Eigen::Vector3d p(0.5, -0.7, 2.0);
  expect_near(a * p, (a.matrix() * p.homogeneous()).head<3>(), 1e-14);
  expect_near(SE3::from_matrix(a.matrix()).matrix(), a.matrix(), 1e-15);
}

TEST(SE3, AdjointMovesTwistsAcross) {
  const SE3 pose = SE3::exp((Vector6d() << 1, -2, 0.5, 0.3, -0.6, 0.2).finished());
  const Vector6d xi = (Vector6d() << 0.01, 0.02, -0.03, 0.004, -0.002, 0.003).finished();
  expect_near((pose * SE3::exp(xi)).matrix(), (SE3::exp(pose.adjoint() * xi) * pose).matrix(), 1e-13);
}

TEST(SE3, LeftAndRightJacobiansMatchFiniteDifferences) {
  for (const Vector6d& xi : test_twists()) {
    if (xi.tail<3>().norm() > std::numbers::pi - 1e-2) continue;
    const SE3 pose = SE3::exp(xi);
    const auto right = numerical_jacobian<6, 6>([&](const Vector6d& d) { return (pose.inverse() * SE3::exp(xi + d)).log(); });
    const auto left = numerical_jacobian<6, 6>([&](const Vector6d& d) { return (SE3::exp(xi + d) * pose.inverse()).log(); });
    expect_near(SE3::right_jacobian(xi), right, 1e-6);
    expect_near(SE3::left_jacobian(xi), left, 1e-6);
    expect_near(SE3::left_jacobian_inverse(xi) * SE3::left_jacobian(xi), SE3::Jacobian::Identity(), 1e-9);
    expect_near(SE3::right_jacobian_inverse(xi) * SE3::right_jacobian(xi), SE3::Jacobian::Identity(), 1e-9);
  }
}

TEST(SE3, OperationJacobiansMatchFiniteDifferences) {
  const SE3 y = SE3::exp((Vector6d() << 0.2, -0.4, 1.0, 0.5, 0.1, -0.8).finished());
  const Eigen::Vector3d p(1.5, -0.5, 0.25);
  for (const Vector6d& xi : test_twists()) {
    if (xi.tail<3>().norm() > std::numbers::pi - 1e-2) continue;
    const SE3 x = SE3::exp(xi);
    SE3::Jacobian j_exp, j_log, j_inverse, j_this, j_other;
    SE3::exp(xi, &j_exp);
    expect_near(j_exp, numerical_jacobian<6, 6>([&](const Vector6d& d) { return (x.inverse() * SE3::exp(xi + d)).log(); }), 1e-6);
    x.log(&j_log);
    expect_near(j_log, numerical_jacobian<6, 6>([&](const Vector6d& d) { return (x * SE3::exp(d)).log(); }), 1e-6);
    x.inverse(&j_inverse);
    expect_near(j_inverse, numerical_jacobian<6, 6>([&](const Vector6d& d) { return (x * (x * SE3::exp(d)).inverse()).log(); }), 1e-6);
    const SE3 z = x.compose(y, &j_this, &j_other);
    expect_near(j_this, numerical_jacobian<6, 6>([&](const Vector6d& d) { return (z.inverse() * (x * SE3::exp(d) * y)).log(); }), 1e-6);
    expect_near(j_other, numerical_jacobian<6, 6>([&](const Vector6d& d) { return (z.inverse() * (x * y * SE3::exp(d))).log(); }), 1e-6);
    Eigen::Matrix<double, 3, 6> j_pose;
    Eigen::Matrix3d j_point;
    x.act(p, &j_pose, &j_point);
    expect_near(j_pose, numerical_jacobian<6, 3>([&](const Vector6d& d) { return Eigen::Vector3d((x * SE3::exp(d)) * p); }), 1e-6);
    expect_near(j_point, numerical_jacobian<3, 3>([&](const Eigen::Vector3d& d) { return Eigen::Vector3d(x * (p + d)); }), 1e-6);
  }
}

TEST(SE3, InterpolationEndpointsAndConstantTwist) {
  const SE3 a = SE3::exp((Vector6d() << 1, 2, 3, 0.1, 0.2, 0.3).finished());
  const SE3 b = SE3::exp((Vector6d() << 2, 1, -1, -0.3, 0.5, 0.2).finished());
  expect_near(SE3::interpolate(a, b, 0.0).matrix(), a.matrix(), 1e-13);
  expect_near(SE3::interpolate(a, b, 1.0).matrix(), b.matrix(), 1e-12);
  const SE3 quarter = SE3::interpolate(a, b, 0.25);
  const SE3 half = SE3::interpolate(a, b, 0.5);
  // Equal steps along a screw motion: a -> quarter is the same relative motion as quarter -> half.
  expect_near((a.inverse() * quarter).matrix(), (quarter.inverse() * half).matrix(), 1e-12);
}

}  // namespace
}  // namespace hanzo::fusion
