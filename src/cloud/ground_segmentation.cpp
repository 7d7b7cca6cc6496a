#include "hanzo/fusion/cloud/ground_segmentation.hpp"

#include <cmath>
#include <numeric>
#include <random>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <fmt/format.h>

namespace hanzo::fusion::cloud {
namespace {

constexpr size_t kMaxScoringPoints = 8000;  // hypotheses are scored on a random subset of this size

struct Plane {
  Eigen::Vector3d normal;
  double offset;
};

size_t count_inliers(const std::vector<Eigen::Vector3f>& positions, const std::vector<uint32_t>& subset, const Plane& plane,
                     double threshold) {
  size_t count = 0;
  for (uint32_t i : subset) count += std::abs(plane.normal.dot(positions[i].cast<double>()) + plane.offset) <= threshold;
  return count;
}

// Least-squares plane of `indices` (the direction of least spread), normal toward +z.
Plane refit(const std::vector<Eigen::Vector3f>& positions, const std::vector<uint32_t>& indices) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (uint32_t i : indices) mean += positions[i].cast<double>();
  mean /= static_cast<double>(indices.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (uint32_t i : indices) {
    const Eigen::Vector3d d = positions[i].cast<double>() - mean;
    scatter.noalias() += d * d.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(scatter);
  Eigen::Vector3d normal = solver.eigenvectors().col(0);
  if (normal.z() < 0.0) normal = -normal;
  return {normal, -normal.dot(mean)};
}

}  // namespace

GroundSegmentation segment_ground(const PointCloud& cloud, const GroundSegmentationConfig& config) {
  GroundSegmentation result;
  const auto& positions = cloud.positions;
  const auto all_obstacles = [&](std::string message) {
    result.message = std::move(message);
    result.obstacles.resize(cloud.size());
    std::iota(result.obstacles.begin(), result.obstacles.end(), 0u);
    return result;
  };
  if (cloud.size() < 3) return all_obstacles(fmt::format("{} points, a plane needs 3", cloud.size()));

  std::mt19937 random(config.seed);
  std::vector<uint32_t> subset(cloud.size());
  std::iota(subset.begin(), subset.end(), 0u);
  if (subset.size() > kMaxScoringPoints) {
    std::shuffle(subset.begin(), subset.end(), random);
    subset.resize(kMaxScoringPoints);
  }
  const double min_cos_tilt = std::cos(config.max_tilt_deg * M_PI / 180.0);
  std::uniform_int_distribution<size_t> pick(0, cloud.size() - 1);
  Plane best{Eigen::Vector3d::UnitZ(), 0.0};
  size_t best_count = 0;
  for (int iteration = 0; iteration < config.max_iterations; ++iteration) {
    const Eigen::Vector3d a = positions[pick(random)].cast<double>();
    const Eigen::Vector3d b = positions[pick(random)].cast<double>();
    const Eigen::Vector3d c = positions[pick(random)].cast<double>();
    Eigen::Vector3d normal = (b - a).cross(c - a);
    const double norm = normal.norm();
    if (norm < 1e-9) continue;  // collinear or repeated sample
    normal /= norm;
    if (normal.z() < 0.0) normal = -normal;
    if (normal.z() < min_cos_tilt) continue;
    const Plane plane{normal, -normal.dot(a)};
    const size_t count = count_inliers(positions, subset, plane, config.distance_threshold);
    if (count > best_count) {
      best_count = count;
      best = plane;
    }
  }
  const double fraction = static_cast<double>(best_count) / static_cast<double>(subset.size());
  if (best_count < 3 || fraction < config.min_inlier_fraction) {
    return all_obstacles(fmt::format("no plane within {} deg of level holds {:.0f}% of the points (best {:.1f}%)",
                                     config.max_tilt_deg, 100.0 * config.min_inlier_fraction, 100.0 * fraction));
  }

  const auto split = [&](const Plane& plane) {
    result.ground.clear();
    result.obstacles.clear();
    for (size_t i = 0; i < cloud.size(); ++i) {
      const bool on_plane = std::abs(plane.normal.dot(positions[i].cast<double>()) + plane.offset) <= config.distance_threshold;
      (on_plane ? result.ground : result.obstacles).push_back(static_cast<uint32_t>(i));
    }
  };
  split(best);
  const Plane refined = refit(positions, result.ground);
  if (refined.normal.z() >= min_cos_tilt) {
    best = refined;
    split(best);
  }
  result.found = true;
  result.normal = best.normal;
  result.offset = best.offset;
  return result;
}

}  // namespace hanzo::fusion::cloud
