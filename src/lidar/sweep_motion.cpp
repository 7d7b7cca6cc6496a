#include "hanzo/fusion/lidar/sweep_motion.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "hanzo/fusion/cloud/parallel.hpp"

namespace hanzo::fusion::lidar {

SweepMotion SweepMotion::constant_twist(const SE3::Tangent& twist_per_second, double reference_time) {
  SweepMotion motion;
  motion.times_ = {reference_time};
  motion.poses_ = {SE3()};
  motion.twists_ = {twist_per_second};
  return motion;
}

Result<SweepMotion> SweepMotion::from_samples(std::vector<double> times, const std::vector<SE3>& T_reference_sensor) {
  if (times.size() != T_reference_sensor.size()) {
    return Error(fmt::format("sweep motion: {} times but {} poses", times.size(), T_reference_sensor.size()));
  }
  if (times.size() < 2) return Error(fmt::format("sweep motion: {} samples (need at least 2)", times.size()));
  SweepMotion motion;
  for (std::size_t i = 0; i < times.size(); ++i) {
    if (!std::isfinite(times[i]) || !T_reference_sensor[i].matrix().allFinite()) {
      return Error(fmt::format("sweep motion: sample {} is not finite", i));
    }
    if (i > 0 && !(times[i] > times[i - 1])) {
      return Error(fmt::format("sweep motion: sample {} at {} s is not after sample {} at {} s", i, times[i], i - 1, times[i - 1]));
    }
  }
  motion.twists_.reserve(times.size());
  for (std::size_t i = 0; i + 1 < times.size(); ++i) {
    motion.twists_.push_back((T_reference_sensor[i].inverse() * T_reference_sensor[i + 1]).log() / (times[i + 1] - times[i]));
  }
  motion.twists_.push_back(motion.twists_.back());
  motion.times_ = std::move(times);
  motion.poses_ = T_reference_sensor;
  return motion;
}

SE3 SweepMotion::at(double time) const {
  if (times_.empty()) return SE3();
  // The sample at or before `time` (the first one for earlier times).
  const auto after = std::upper_bound(times_.begin(), times_.end(), time);
  const std::size_t i = after == times_.begin() ? 0 : static_cast<std::size_t>(after - times_.begin()) - 1;
  return poses_[i] * SE3::exp(twists_[i] * (time - times_[i]));
}

bool SweepMotion::is_identity() const {
  if (times_.empty()) return true;
  const bool still = std::all_of(twists_.begin(), twists_.end(), [](const SE3::Tangent& twist) { return twist.isZero(); });
  return still && poses_.front().log().isZero();
}

void deskew(cloud::PointCloud& scan, const SweepMotion& motion, int num_threads) {
  if (!scan.has_times() || motion.is_identity()) return;
  cloud::parallel_for(scan.size(), num_threads, [&](std::size_t begin, std::size_t end) {
    // Sweeps are sorted by time in blocks (firing columns): reuse the transform while the time repeats.
    float cached_time = std::numeric_limits<float>::quiet_NaN();
    Eigen::Matrix3f rotation = Eigen::Matrix3f::Identity();
    Eigen::Vector3f translation = Eigen::Vector3f::Zero();
    for (std::size_t i = begin; i < end; ++i) {
      if (scan.times[i] != cached_time) {
        cached_time = scan.times[i];
        const SE3 T_reference_sensor = motion.at(static_cast<double>(cached_time));
        rotation = T_reference_sensor.rotation().matrix().cast<float>();
        translation = T_reference_sensor.translation().cast<float>();
      }
      scan.positions[i] = rotation * scan.positions[i] + translation;
    }
  });
}

}  // namespace hanzo::fusion::lidar
