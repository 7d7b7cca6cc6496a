#pragma once
// The KITTI odometry benchmark metric (Geiger et al., CVPR 2012; devkit evaluate_odometry.cpp):
// for every 10th frame and every segment length 100, 200, ..., 800 m of ground-truth path,
// the relative pose error E = (T_est_first^-1 T_est_last)^-1 (T_gt_first^-1 T_gt_last) is
// divided by the segment length; the benchmark reports the mean over all segments of the
// translational error (in %) and of the rotational error (here in deg per 100 m).

#include <cstddef>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::eval {

struct KittiOdometryConfig {
  std::vector<double> segment_lengths_m = {100, 200, 300, 400, 500, 600, 700, 800};
  std::size_t step_frames = 10;  ///< a segment starts at every step_frames-th frame
};

struct KittiSegmentLengthError {
  double length_m = 0.0;
  std::size_t segments = 0;
  double translation_error_percent = 0.0;
  double rotation_error_deg_per_100m = 0.0;
};

struct KittiOdometryResult {
  std::size_t segments = 0;                 ///< all segments of all lengths
  double translation_error_percent = 0.0;   ///< mean of t_err / length * 100
  double rotation_error_deg_per_100m = 0.0; ///< mean of r_err / length in deg per 100 m
  std::vector<KittiSegmentLengthError> per_length;  ///< lengths with at least one segment
};

/// Ground truth and estimate must be associated (same size). Fails when the ground truth is
/// shorter than the shortest segment length (no segment fits).
Result<KittiOdometryResult> compute_kitti_odometry_error(const io::Trajectory& ground_truth, const io::Trajectory& estimate,
                                                         const KittiOdometryConfig& config = {});

}  // namespace hanzo::fusion::eval
