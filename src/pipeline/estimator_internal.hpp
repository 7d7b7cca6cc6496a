#pragma once
// Helpers shared by the Estimator's source files. Private to the pipeline module.

#include <algorithm>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/time.hpp"

#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::pipeline {

// Keeps the elements of a time-ordered buffer no older than `seconds` before `now`.
template <typename T, typename TimeOf>
void keep_recent(std::vector<T>& buffer, Timestamp now, double seconds, TimeOf time_of) {
  const auto old = std::find_if(buffer.begin(), buffer.end(), [&](const T& item) { return (now - time_of(item)).seconds() <= seconds; });
  buffer.erase(buffer.begin(), old);
}

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
