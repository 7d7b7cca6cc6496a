#pragma once
// LidarInertialFactors: the Session's keyframe graph as a LiDAR-inertial problem (a 3D LiDAR and
// an IMU, as LIO-SAM's factor graph): between two keyframes an IMU preintegration factor and a
// bias random walk (imu_keyframe_chain.hpp) and the LiDAR odometry's relative motion, from its
// scan-to-map registrations, with the registrations' own covariance. The filter's relative
// motion (which fused the same IMU and LiDAR) stays only as a weak anchor (its covariance x
// odometry_covariance_scale), so the graph re-estimates the trajectory, the velocities and the
// IMU biases from the measurements; gravity in the IMU factors levels it.
//
// Variables (graph/keys.hpp): X(k) = T_world_body of keyframe k (the KeyframeGraph's), V(k)
// world velocity (m/s), B(k) the IMU's biases in body axes.
//
// The LiDAR factor: keyframe k (at an IMU sample's time) takes the registered sweep nearest in
// time, at most max_sweep_offset_s away; the body's motion between the keyframe and the sweep's
// middle comes from the IMU and the keyframe's velocity (held fixed), so T_odometry_keyframe =
// T_odometry_body(sweep) T_keyframe_sweep^-1. Between consecutive keyframes with sweeps of the
// same LiDAR map: T_a_b = T_odometry_a^-1 T_odometry_b, covariance Ad(T_a_b^-1) C_a Ad^T + C_b,
// each C the sweep's registration covariance (right perturbation, moved into the keyframe's
// body frame) plus position_sigma_floor^2 / rotation_sigma_floor^2. A keyframe without a sweep
// nearby or after the LiDAR map started again gets no LiDAR factor (the filter's relative
// motion then links it at full weight).

#include <cstdint>
#include <deque>
#include <optional>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/graph/factor_graph.hpp"
#include "hanzo/fusion/graph/imu_preintegration.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "imu_keyframe_chain.hpp"

namespace hanzo::fusion::pipeline {

struct LidarInertialFactorsConfig {
  ImuChainPriors priors;               ///< V and B of the first keyframe of a chain
  /// Added to each sweep's registration covariance (whose own treats thousands of points as
  /// independent): the error of one scan-to-map registration. Scan-to-map LiDAR odometry drifts
  /// by about 0.1-0.2 degrees per 100 m (KITTI odometry), 2-3e-4 rad over a keyframe's 10 m at
  /// city speed. On three simulated drives (IMU + LiDAR, optimized APE SE3-aligned) 0.005 m /
  /// 0.0002 rad gave 0.030 / 0.038 / 0.023 m, 0.02 m / 0.002 rad 0.056 / 0.118 / 0.026 m, the
  /// filter's relative motion instead 0.047 / 0.057 / 0.034 m (bench/RESULTS.md).
  double position_sigma_floor = 0.005;   ///< m
  double rotation_sigma_floor = 0.0002;  ///< rad
  double max_sweep_offset_s = 0.1;     ///< a keyframe's sweep is at most this far from it in time
  /// Where the IMU and the LiDAR link two keyframes the filter's relative motion stays with its
  /// covariance times this (standard deviations x10): as in visual_inertial_factors.hpp.
  double odometry_covariance_scale = 100.0;
};

class LidarInertialFactors {
 public:
  struct KeyframeFactors {
    graph::GraphUpdate update;
    bool imu_factor = false;    ///< the IMU links the keyframe to the previous one
    bool lidar_factor = false;  ///< the LiDAR odometry's relative motion does
  };
  /// T_body_lidar: the LiDAR's calibration; imu, random walks: as ImuKeyframeChain's.
  LidarInertialFactors(const SE3& T_body_lidar, const graph::ImuPreintegrationConfig& imu, double accel_bias_random_walk,
                       double gyro_bias_random_walk, LidarInertialFactorsConfig config = {});

  /// A body-origin IMU sample (body axes, body clock).
  void add_imu(const estimate::ImuSample& sample) { chain_.add_imu(sample); }
  /// A registered sweep: the middle of the sweep (body clock), the LiDAR's pose in the odometry's
  /// map and the registration's covariance (right perturbation, LiDAR frame); map_started: the
  /// sweep started a new map (the odometry's first scan). Older or repeated times are ignored.
  void add_sweep(Timestamp time, const SE3& T_odometry_lidar, const Eigen::Matrix<double, 6, 6>& covariance, bool map_started);
  /// The factors of a new keyframe (its pose and velocity in the graph's world) and its V, B
  /// values, given the graph's estimate of the earlier ones; bias_body: the filter's IMU biases
  /// (body axes) for the first keyframe of a chain.
  KeyframeFactors keyframe(const msgs::Keyframe& keyframe, const graph::ImuBias& bias_body, const graph::Values& estimate);
  /// The graph was replaced, or the last keyframe's factors were not added: the next keyframe
  /// starts new IMU and LiDAR chains.
  void restart();
  const LidarInertialFactorsConfig& config() const { return config_; }

 private:
  struct Sweep {
    Timestamp time;
    SE3 T_odometry_body;
    Eigen::Matrix<double, 6, 6> covariance;  // right perturbation, body frame, floors included
    uint64_t map;
  };
  struct Anchor {
    uint64_t keyframe;
    uint64_t map;
    SE3 T_odometry_keyframe;
    Eigen::Matrix<double, 6, 6> covariance;
  };
  // The registered sweep nearest to `time` (at most max_sweep_offset_s away), or nullptr.
  const Sweep* sweep_near(Timestamp time) const;

  SE3 T_body_lidar_;
  LidarInertialFactorsConfig config_;
  ImuKeyframeChain chain_;
  std::deque<Sweep> sweeps_;        // the last seconds'
  uint64_t map_ = 0;                // counts the LiDAR maps started
  std::optional<Anchor> previous_;  // the last keyframe with a sweep
};

}  // namespace hanzo::fusion::pipeline
