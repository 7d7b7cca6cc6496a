#pragma once
// Starting the visual-inertial odometry while the platform moves (MsckfOdometry, when the
// static alignment finds motion): the initial tilt from the IMU and, with a stereo rig, the
// initial velocity from the stereo points of two consecutive frames.
//
// Frames: "body" is the IMU (the MSCKF's body); the world is gravity-aligned (z up), heading 0.

#include <cstdint>
#include <map>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/so3.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"
#include "hanzo/fusion/vision/feature_observation.hpp"
#include "hanzo/fusion/vision/msckf.hpp"

namespace hanzo::fusion::pipeline {

/// Roll and pitch (heading 0) of the body at the last sample, from the mean specific force of
/// all samples, each rotated into the last sample's frame by the integrated gyro: it points up
/// but for the mean acceleration over the span (a tilt error of about |mean acceleration| / g
/// rad: 0.6 degrees for 0.1 m/s^2). Needs at least two samples in time order.
SO3 tilt_from_moving_imu(const std::vector<estimate::ImuSample>& samples);

/// The rotation of the body at `to` into the body at `from` (R_from_to) by integrating the gyro
/// samples between the two times (trapezoidal; the samples must cover the span).
SO3 gyro_rotation(const std::vector<estimate::ImuSample>& samples, Timestamp from, Timestamp to);

/// Stereo points in the body frame, by feature id: each feature seen by both cameras of the rig
/// (camera 0 and 1) triangulated as the closest point of the two rays; points behind either
/// camera or farther than max_depth_m are left out.
std::map<uint64_t, Eigen::Vector3d> triangulate_stereo(const std::vector<vision::FeatureObservation>& observations,
                                                       const std::vector<vision::MsckfCamera>& cameras, double max_depth_m = 6.0);

/// The body's velocity in its own frame at the later of two frames, from their stereo points:
/// the body moved by the median (per axis) of p_previous - R_previous_current p_current over the
/// features in both, divided by dt. None with fewer than min_points shared points.
std::optional<Eigen::Vector3d> stereo_velocity(const std::map<uint64_t, Eigen::Vector3d>& previous_points,
                                               const std::map<uint64_t, Eigen::Vector3d>& current_points, const SO3& R_previous_current,
                                               double dt, int min_points = 10);

}  // namespace hanzo::fusion::pipeline
