#include "hanzo/fusion/eval/kitti_odometry.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace hanzo::fusion::eval {
namespace {

// The devkit's rotationError: acos of 0.5 (trace(R) - 1), clamped to [-1, 1].
double devkit_rotation_error(const io::PoseMatrix& error) {
  const double d = 0.5 * (error(0, 0) + error(1, 1) + error(2, 2) - 1.0);
  return std::acos(std::clamp(d, -1.0, 1.0));
}

}  // namespace

Result<KittiOdometryResult> compute_kitti_odometry_error(const io::Trajectory& ground_truth, const io::Trajectory& estimate,
                                                         const KittiOdometryConfig& config) {
  if (ground_truth.size() != estimate.size()) {
    return Error(fmt::format("KITTI metric needs associated trajectories (same number of poses): {} vs {}",
                             ground_truth.size(), estimate.size()));
  }
  if (config.step_frames == 0) return Error("KITTI metric: step_frames must be at least 1");
  const std::size_t n = ground_truth.size();
  std::vector<double> distance(n, 0.0);  // travelled ground-truth distance at each frame
  for (std::size_t i = 1; i < n; ++i) distance[i] = distance[i - 1] + (ground_truth.position(i) - ground_truth.position(i - 1)).norm();

  KittiOdometryResult result;
  double translation_sum = 0.0;
  double rotation_sum = 0.0;
  for (double length : config.segment_lengths_m) {
    KittiSegmentLengthError per_length;
    per_length.length_m = length;
    double length_translation_sum = 0.0;
    double length_rotation_sum = 0.0;
    for (std::size_t first = 0; first < n; first += config.step_frames) {
      // The first frame more than `length` metres of path further on.
      const auto it = std::upper_bound(distance.begin() + static_cast<std::ptrdiff_t>(first), distance.end(),
                                       distance[first] + length);
      if (it == distance.end()) continue;
      const auto last = static_cast<std::size_t>(it - distance.begin());
      const io::PoseMatrix gt_motion = ground_truth.poses[first].inverse() * ground_truth.poses[last];
      const io::PoseMatrix estimate_motion = estimate.poses[first].inverse() * estimate.poses[last];
      const io::PoseMatrix error = estimate_motion.inverse() * gt_motion;
      length_translation_sum += error.block<3, 1>(0, 3).norm() / length;
      length_rotation_sum += devkit_rotation_error(error) / length;
      ++per_length.segments;
    }
    if (per_length.segments == 0) continue;
    translation_sum += length_translation_sum;
    rotation_sum += length_rotation_sum;
    result.segments += per_length.segments;
    const auto count = static_cast<double>(per_length.segments);
    per_length.translation_error_percent = 100.0 * length_translation_sum / count;
    per_length.rotation_error_deg_per_100m = 100.0 * 180.0 / M_PI * length_rotation_sum / count;
    result.per_length.push_back(per_length);
  }
  if (result.segments == 0) {
    return Error(fmt::format("KITTI metric: the ground truth path ({:.1f} m) is shorter than every segment length",
                             distance.back()));
  }
  const auto count = static_cast<double>(result.segments);
  result.translation_error_percent = 100.0 * translation_sum / count;
  result.rotation_error_deg_per_100m = 100.0 * 180.0 / M_PI * rotation_sum / count;
  return result;
}

}  // namespace hanzo::fusion::eval
