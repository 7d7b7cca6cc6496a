#include "hanzo/fusion/estimate/radar_ego_velocity.hpp"

#include <cmath>
#include <random>

#include <Eigen/Dense>
#include <fmt/format.h>

namespace hanzo::fusion::estimate {
namespace {

struct Equation {
  Eigen::Vector3d direction;
  double radial_speed;
};

// Least squares on the given equations, x/y only when planar.
Eigen::Vector3d solve(const std::vector<Equation>& equations, const std::vector<size_t>& rows, bool planar) {
  const int unknowns = planar ? 2 : 3;
  Eigen::MatrixXd D(static_cast<Eigen::Index>(rows.size()), unknowns);
  Eigen::VectorXd b(static_cast<Eigen::Index>(rows.size()));
  for (size_t i = 0; i < rows.size(); ++i) {
    D.row(static_cast<Eigen::Index>(i)) = equations[rows[i]].direction.head(unknowns).transpose();
    b(static_cast<Eigen::Index>(i)) = -equations[rows[i]].radial_speed;
  }
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  velocity.head(unknowns) = D.colPivHouseholderQr().solve(b);
  return velocity;
}

}  // namespace

Result<RadarEgoVelocity> estimate_radar_ego_velocity(const std::vector<msgs::RadarTarget>& targets,
                                                     const RadarEgoVelocityConfig& config, uint64_t seed) {
  std::vector<Equation> equations;
  bool planar = true;
  for (const msgs::RadarTarget& target : targets) {
    if (target.range < config.min_range) continue;
    const double ce = std::cos(target.elevation);
    equations.push_back({Eigen::Vector3d(ce * std::cos(target.azimuth), ce * std::sin(target.azimuth), std::sin(target.elevation)),
                         target.radial_velocity});
    planar = planar && std::abs(target.elevation) <= config.elevation_planar;
  }
  const size_t sample_size = planar ? 2 : 3;
  if (equations.size() < std::max<size_t>(sample_size, static_cast<size_t>(config.min_inliers))) {
    return Error(fmt::format("radar ego-velocity: {} usable targets, need {}", equations.size(),
                             std::max<size_t>(sample_size, static_cast<size_t>(config.min_inliers))));
  }
  std::mt19937_64 random(seed);
  std::uniform_int_distribution<size_t> pick(0, equations.size() - 1);
  const auto inliers_of = [&](const Eigen::Vector3d& velocity) {
    std::vector<size_t> inliers;
    for (size_t i = 0; i < equations.size(); ++i) {
      if (std::abs(equations[i].direction.dot(velocity) + equations[i].radial_speed) <= config.inlier_threshold) inliers.push_back(i);
    }
    return inliers;
  };
  std::vector<size_t> best;
  for (int iteration = 0; iteration < config.iterations; ++iteration) {
    std::vector<size_t> sample;
    while (sample.size() < sample_size) {
      const size_t index = pick(random);
      if (std::find(sample.begin(), sample.end(), index) == sample.end()) sample.push_back(index);
    }
    std::vector<size_t> inliers = inliers_of(solve(equations, sample, planar));
    if (inliers.size() > best.size()) best = std::move(inliers);
  }
  if (static_cast<int>(best.size()) < config.min_inliers) {
    return Error(fmt::format("radar ego-velocity: no consensus ({} of {} targets agree, need {})", best.size(), equations.size(),
                             config.min_inliers));
  }
  // Refine on the consensus set, once more with the refined inliers.
  Eigen::Vector3d velocity = solve(equations, best, planar);
  best = inliers_of(velocity);
  velocity = solve(equations, best, planar);

  const int unknowns = planar ? 2 : 3;
  Eigen::MatrixXd D(static_cast<Eigen::Index>(best.size()), unknowns);
  double squared = 0.0;
  for (size_t i = 0; i < best.size(); ++i) {
    D.row(static_cast<Eigen::Index>(i)) = equations[best[i]].direction.head(unknowns).transpose();
    const double residual = equations[best[i]].direction.dot(velocity) + equations[best[i]].radial_speed;
    squared += residual * residual;
  }
  const double dof = std::max(1.0, static_cast<double>(best.size()) - unknowns);
  const double sigma = std::max(config.min_residual_sigma, std::sqrt(squared / dof));
  RadarEgoVelocity result;
  result.velocity_sensor = velocity;
  result.covariance.setZero();
  result.covariance.topLeftCorner(unknowns, unknowns) = sigma * sigma * (D.transpose() * D).inverse();
  if (planar) result.covariance(2, 2) = config.planar_z_variance;
  result.inliers = static_cast<int>(best.size());
  result.targets = static_cast<int>(equations.size());
  result.planar = planar;
  if (!result.covariance.allFinite()) return Error("radar ego-velocity: the target directions do not determine the velocity");
  return result;
}

}  // namespace hanzo::fusion::estimate
