// The registration costs' normal equations against numeric Jacobians. For one fixed
// correspondence, linearize() must add J^T W J, J^T W r and r^T W r where J is the central
// difference Jacobian of the residual r(delta) for T <- T Exp(delta) and W is held at the
// linearization point (as Gauss-Newton does): GICP's W = (C_t + R C_s R^T)^-1, ICP's W = I,
// point-to-plane's r = n . (T p - t).

#include <algorithm>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "registration_costs.hpp"  // src/lidar (internal)

namespace hanzo::fusion::lidar {
namespace {

struct Fixture {
  Eigen::Vector3d source_point{4.0, -2.5, 1.2};
  Eigen::Vector3f target_point{3.6f, -1.9f, 1.7f};
  SE3 T = SE3(SO3::exp(Eigen::Vector3d(0.2, -0.35, 0.9)), Eigen::Vector3d(0.3, 0.5, -0.2));
  cloud::KdTree tree{std::vector<Eigen::Vector3f>{target_point}};
  std::vector<uint32_t> previous{kNoCorrespondence};
  std::vector<Eigen::Vector3d> source{source_point};
  KernelSettings kernel{RobustKernel::kNone, 1.0};

  NearestNeighborMatcher matcher() { return {tree, nullptr, 1e6f, previous}; }

  // Residual of the source point at T Exp(delta) against the (float) target point.
  Eigen::Vector3d residual(const Vector6d& delta) const {
    return (T * SE3::exp(delta)) * source_point - target_point.cast<double>();
  }
  Jacobian3x6 numeric_jacobian() const {
    Jacobian3x6 J;
    constexpr double step = 1e-6;
    for (int k = 0; k < 6; ++k) {
      const Vector6d offset = Vector6d::Unit(k) * step;
      J.col(k) = (residual(offset) - residual(-offset)) / (2.0 * step);
    }
    return J;
  }
};

Eigen::Matrix3d spd(const Eigen::Vector3d& axis, double across, const Eigen::Vector3d& along) {
  const Eigen::Vector3d normal = axis.normalized();
  return Eigen::Matrix3d::Identity() - (1.0 - across) * normal * normal.transpose() + 0.1 * along * along.transpose();
}

void expect_equations(const NormalEquations& got, const Jacobian3x6& J, const Eigen::Matrix3d& W, const Eigen::Vector3d& r) {
  const Matrix6d hessian = J.transpose() * W * J;
  const Vector6d gradient = J.transpose() * W * r;
  EXPECT_EQ(got.correspondences, 1u);
  EXPECT_LT((got.hessian - hessian).norm(), 1e-6 * hessian.norm()) << got.hessian << "\nvs\n" << hessian;
  EXPECT_LT((got.gradient - gradient).norm(), 1e-6 * gradient.norm()) << got.gradient.transpose() << " vs " << gradient.transpose();
  EXPECT_NEAR(got.cost, r.dot(W * r), 1e-9 * r.squaredNorm());
}

TEST(RegistrationCosts, GicpNormalEquationsMatchTheNumericJacobian) {
  Fixture f;
  const std::vector<Eigen::Matrix3d> source_covariances{spd({0.2, 0.1, 1.0}, 1e-3, {0.5, 0.0, 0.3})};
  const std::vector<Eigen::Matrix3d> target_covariances{spd({1.0, 0.4, -0.2}, 1e-3, {0.0, 0.6, 0.1})};
  const GicpCost cost{f.source, source_covariances, f.matcher(), target_covariances, f.kernel};
  NormalEquations got;
  cost.linearize(0, PoseBlocks(f.T), got);
  const Eigen::Matrix3d R = f.T.rotation().matrix();
  const Eigen::Matrix3d W = (target_covariances[0] + R * source_covariances[0] * R.transpose()).inverse();
  expect_equations(got, f.numeric_jacobian(), W, f.residual(Vector6d::Zero()));
}

TEST(RegistrationCosts, PointToPointNormalEquationsMatchTheNumericJacobian) {
  Fixture f;
  const PointToPointCost cost{f.source, f.matcher(), f.kernel};
  NormalEquations got;
  cost.linearize(0, PoseBlocks(f.T), got);
  expect_equations(got, f.numeric_jacobian(), Eigen::Matrix3d::Identity(), f.residual(Vector6d::Zero()));
}

TEST(RegistrationCosts, PointToPlaneNormalEquationsMatchTheNumericJacobian) {
  Fixture f;
  const Eigen::Vector3f normal = Eigen::Vector3f(0.3f, -0.4f, 0.85f).normalized();
  const std::vector<Eigen::Vector3f> normals{normal};
  const PointToPlaneCost cost{f.source, f.matcher(), normals, f.kernel};
  NormalEquations got;
  cost.linearize(0, PoseBlocks(f.T), got);
  // r = n^T (T p - t): the 1-row Jacobian is n^T J and W = n n^T in the 3-row form.
  const Eigen::Vector3d n = normal.cast<double>();
  expect_equations(got, f.numeric_jacobian(), n * n.transpose(), f.residual(Vector6d::Zero()));
}

TEST(RegistrationCosts, RobustKernelsScaleTheNormalEquationsByTheirWeight) {
  Fixture f;
  f.kernel = {RobustKernel::kCauchy, 0.5};
  const PointToPointCost cost{f.source, f.matcher(), f.kernel};
  NormalEquations got;
  cost.linearize(0, PoseBlocks(f.T), got);
  const Eigen::Vector3d r = f.residual(Vector6d::Zero());
  const double weight = kernel_weight(RobustKernel::kCauchy, 0.5, r.norm());
  ASSERT_LT(weight, 0.5);  // the residual is beyond the kernel width
  expect_equations(got, f.numeric_jacobian(), weight * Eigen::Matrix3d::Identity(), r);
}

// The correspondence update through the target's neighbour lists must give the exact nearest
// neighbour, as brute force does, for queries that move a little (the lists settle them) and a
// lot (the tree search takes over), and refuse points beyond the correspondence distance.
TEST(RegistrationCosts, NeighbourListCorrespondencesAreTheExactNearestNeighbours) {
  std::mt19937 random(7);
  std::uniform_real_distribution<float> uniform(-5.0f, 5.0f);
  cloud::PointCloud target;
  for (int i = 0; i < 3000; ++i) target.positions.emplace_back(uniform(random), uniform(random), 0.05f * uniform(random));
  const cloud::KdTree tree(target.positions);
  cloud::NeighbourLists lists;
  cloud::estimate_local_geometry(target, tree, {}, &lists);
  ASSERT_EQ(lists.k, 10u);
  const auto brute_force = [&](const Eigen::Vector3f& query) {
    float best = std::numeric_limits<float>::max();
    for (const Eigen::Vector3f& point : target.positions) best = std::min(best, (point - query).squaredNorm());
    return best;
  };
  const float max_squared = 0.3f * 0.3f;
  std::normal_distribution<float> step(0.0f, 1.0f);
  int small_moves_from_a_correspondence = 0;  // where the lists settle most updates
  for (int trial = 0; trial < 2000; ++trial) {
    Eigen::Vector3f query(uniform(random), uniform(random), 0.02f * uniform(random));
    uint32_t previous = kNoCorrespondence;
    for (float motion : {0.0f, 0.001f, 0.002f, 0.02f, 0.2f, 1.0f}) {  // one query moving, as over Gauss-Newton iterations
      query += motion * Eigen::Vector3f(step(random), step(random), step(random));
      const uint32_t before = previous;
      uint32_t index = 0;
      float squared = 0.0f;
      const bool found = find_correspondence(tree, &lists, query.cast<double>(), max_squared, previous, &index, &squared);
      const float expected = brute_force(query);
      ASSERT_EQ(found, expected <= max_squared) << "trial " << trial << " motion " << motion;
      if (found) {
        EXPECT_FLOAT_EQ(squared, expected);
        EXPECT_EQ((target.positions[index] - query).squaredNorm(), expected);
        EXPECT_EQ(previous, index);
      } else {
        EXPECT_EQ(previous, kNoCorrespondence);
      }
      if (before != kNoCorrespondence && motion <= 0.002f) ++small_moves_from_a_correspondence;
    }
  }
  EXPECT_GT(small_moves_from_a_correspondence, 3500);
}

}  // namespace
}  // namespace hanzo::fusion::lidar
