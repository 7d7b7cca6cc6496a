#pragma once
// Map frames: the frame of a sensor's own map (a LiDAR odometry's local map) estimated with the
// navigation state, so that the sensor's poses in that map constrain the state without fixing
// the map's pose in the world (LIO-SAM and FAST-LIO fix it at their first scan; here its roll
// and pitch against gravity, and against GNSS its position and heading, stay estimated).
//
// A map frame is anchored to the body pose at the moment it is created: its pose in the world is
// T_world_map = T_world_anchor * T_anchor_map, where T_anchor_map is fixed (the sensor's mounting
// times the inverse of its first pose in its map) and T_world_anchor is a stochastic clone of the
// body pose then (Roumeliotis and Burdick 2002): the clone starts with the pose's error and its
// correlations with the rest of the state (the accelerometer bias among them, which is why a map
// built at a start tilted by the bias can be levelled once turns separate the two), and later
// updates correct it. Its error is (position world [m], orientation anchor frame [rad]),
// x_true = (p + dp, R Exp(dtheta)), as the body pose's in NavigationState.
//
// MapPoseModel: a pose of the sensor in the map, z = T_map_sensor, predicted as
// h = T_world_map^-1 * T_world_body * T_body_sensor; residual (position in the map frame [m],
// rotation sensor frame [rad]) = (z_p - h_p, Log(h_R^T z_R)); Jacobians d h / d dx with respect to
// the state's error (6 x kErrorStateDimension) and the anchor's (6 x 6), checked numerically in
// tests/estimate/map_frame_test.cpp.

#include <string_view>

#include <Eigen/Core>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/estimate/navigation_state.hpp"

namespace hanzo::fusion::estimate {

struct MapFrameAnchor {
  SE3 T_world_anchor;  ///< the body pose the frame is attached to (estimated)
  SE3 T_anchor_map;    ///< fixed
  SE3 T_world_map() const { return T_world_anchor * T_anchor_map; }
  /// x (+) dx with dx = (position world, orientation anchor frame).
  MapFrameAnchor plus(const Eigen::Matrix<double, 6, 1>& delta) const;
};

class MapPoseModel {
 public:
  using Vector6 = Eigen::Matrix<double, 6, 1>;
  using Matrix6 = Eigen::Matrix<double, 6, 6>;
  using StateJacobian = Eigen::Matrix<double, 6, kErrorStateDimension>;

  /// frame: the filter's index of the map frame; covariance over the residual (position map
  /// frame, rotation sensor frame).
  MapPoseModel(int frame, const SE3& T_map_sensor, const Matrix6& covariance, const SE3& T_body_sensor)
      : frame_(frame), measured_(T_map_sensor), covariance_(covariance), T_body_sensor_(T_body_sensor) {}

  std::string_view name() const { return "map_pose"; }
  int frame() const { return frame_; }
  const Matrix6& covariance() const { return covariance_; }
  /// z (-) h(state, anchor); the Jacobians of h when given.
  Vector6 residual(const NavigationState& state, const MapFrameAnchor& anchor, StateJacobian* H_state, Matrix6* H_anchor) const;

 private:
  int frame_;
  SE3 measured_;
  Matrix6 covariance_;
  SE3 T_body_sensor_;
};

}  // namespace hanzo::fusion::estimate
