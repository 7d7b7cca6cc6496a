#pragma once
// Helpers shared by the Estimator's source files. Private to the pipeline module.

#include <Eigen/Core>

#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::pipeline {

// Gyro-bias uncertainty of a start without static alignment (moving), rad/s.
constexpr double kUnalignedGyroBiasSigma = 0.05;

// Default GNSS position noise per fix type when a message has no covariance (1 sigma, m).
inline Eigen::Matrix3d default_gnss_covariance(msgs::GnssFixType fix) {
  double horizontal = 2.5;
  double vertical = 5.0;
  switch (fix) {
    case msgs::GnssFixType::kFix2d: horizontal = 5.0; vertical = 50.0; break;
    case msgs::GnssFixType::kRtkFloat: horizontal = 0.5; vertical = 1.0; break;
    case msgs::GnssFixType::kRtkFixed: horizontal = 0.02; vertical = 0.05; break;
    default: break;
  }
  return Eigen::Vector3d(horizontal * horizontal, horizontal * horizontal, vertical * vertical).asDiagonal();
}

}  // namespace hanzo::fusion::pipeline
