#pragma once
// Radar ego-velocity: the sensor's own velocity from the Doppler speeds of one scan's targets
// (Kellner et al., "Instantaneous ego-motion estimation using Doppler radar", ITSC 2013).
// A static target in unit direction d (sensor frame, from azimuth and elevation) has radial
// speed v_r = -d . v_sensor (positive = moving away), so each target gives one linear
// equation. Moving targets (people, cars) are outliers: RANSAC over 3-target (2 for planar
// radars) samples picks the largest consensus set, then least squares on its inliers gives the
// velocity and its covariance sigma^2 (D^T D)^-1 with sigma from the inlier residuals.
//
// A radar whose targets all lie within +-elevation_planar of the horizon measures only x and y:
// the z component is then reported with variance planar_z_variance (unconstrained).
// Fails (naming why) with fewer targets than needed or fewer inliers than min_inliers.

#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::estimate {

struct RadarEgoVelocityConfig {
  double min_range = 0.5;             // m: closer targets are ignored (bumper clutter)
  int min_inliers = 5;
  int iterations = 60;                // RANSAC samples
  double inlier_threshold = 0.2;      // m/s, |d . v + v_r|
  double elevation_planar = 0.035;    // rad (2 degrees)
  double planar_z_variance = 1e4;     // (m/s)^2
  double min_residual_sigma = 0.05;   // m/s, floor of the estimated Doppler noise
};

struct RadarEgoVelocity {
  Eigen::Vector3d velocity_sensor = Eigen::Vector3d::Zero();  // m/s, sensor axes
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();   // (m/s)^2
  int inliers = 0;
  int targets = 0;
  bool planar = false;
};

/// Deterministic: the RANSAC samples come from a generator seeded with `seed`.
Result<RadarEgoVelocity> estimate_radar_ego_velocity(const std::vector<msgs::RadarTarget>& targets,
                                                     const RadarEgoVelocityConfig& config = {}, uint64_t seed = 1);

}  // namespace hanzo::fusion::estimate
