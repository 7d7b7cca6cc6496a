#pragma once
// The IMU's part of a keyframe graph over keyframe states X(k) = T_world_body, V(k) (world
// velocity, m/s) and B(k) (the IMU's biases in body axes): between consecutive keyframes of a
// chain an IMU preintegration factor (Forster et al., T-RO 2017; graph/imu_preintegration.hpp)
// and a bias random walk; the first keyframe of a chain gets priors on V and B. A keyframe whose
// interval the IMU does not cover (no samples, two samples more than 0.1 s apart) starts a new
// chain. Shared by the visual-inertial and the LiDAR-inertial keyframe factors.
//
// Samples: the body origin's specific force and angular velocity in body axes on the body clock
// (BodyImu converts an IMU's messages through its calibration).

#include <deque>
#include <optional>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"
#include "hanzo/fusion/graph/factor_graph.hpp"
#include "hanzo/fusion/graph/imu_preintegration.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::pipeline {

/// An IMU's messages as the body origin's motion in body axes on the body clock:
/// f_body = R f_imu - dw/dt x p - w x (w x p), w = R w_imu, p the IMU's lever arm (body axes;
/// dw/dt from the previous message), t_body = t_imu + time_offset.
class BodyImu {
 public:
  BodyImu(const SE3& T_body_imu, Duration time_offset) : T_body_imu_(T_body_imu), time_offset_(time_offset) {}
  /// None for a message with non-finite readings.
  std::optional<estimate::ImuSample> convert(const msgs::ImuMessage& imu);
  const SE3& T_body_imu() const { return T_body_imu_; }

 private:
  SE3 T_body_imu_;
  Duration time_offset_;
  std::optional<std::pair<Timestamp, Eigen::Vector3d>> previous_rate_;
};

/// The preintegration noise (frontend.covariance's process noise at the IMU's rate) and the
/// bias random walks of a configuration's IMU sensor.
struct ImuChainNoise {
  graph::ImuPreintegrationConfig preintegration;
  double accel_bias_random_walk = 0.0;  ///< m/s^2/sqrt(s)
  double gyro_bias_random_walk = 0.0;   ///< rad/s/sqrt(s)
};
ImuChainNoise imu_chain_noise(const config::FusionConfig& config, const config::SensorConfig& imu);

struct ImuChainPriors {
  double velocity_sigma = 0.5;      ///< m/s, V of a chain's first keyframe
  double accel_bias_sigma = 0.1;    ///< m/s^2, B of a chain's first keyframe
  double gyro_bias_sigma = 0.01;    ///< rad/s
};

class ImuKeyframeChain {
 public:
  /// imu: noise and gravity of the preintegration; random walks as the spec's
  /// accel_bias_random_walk (m/s^2/sqrt(s)) and gyro_bias_random_walk (rad/s/sqrt(s)).
  ImuKeyframeChain(const graph::ImuPreintegrationConfig& imu, double accel_bias_random_walk, double gyro_bias_random_walk,
                   ImuChainPriors priors = {});

  /// A body-origin sample (older or repeated samples are ignored). Samples from the chain's
  /// last keyframe on are kept (at most 30 s when no keyframe comes).
  void add_imu(const estimate::ImuSample& sample);
  /// The samples over [from, to] integrated from `bias`; none when they do not cover it.
  std::optional<graph::ImuPreintegration> preintegrate(Timestamp from, Timestamp to, const graph::ImuBias& bias) const;
  /// T_keyframe_at: the body at `time` (before or after the keyframe) in the keyframe's body
  /// frame, integrated from the keyframe's pose and velocity with `bias` (eq. 38, or solved
  /// backwards for an earlier time); none when the IMU does not cover the interval.
  std::optional<SE3> body_motion(const msgs::Keyframe& keyframe, const graph::ImuBias& bias, Timestamp time) const;

  struct Link {
    bool imu_factor = false;           ///< an IMU factor joins the keyframe to the chain's last
    Eigen::Vector3d velocity = Eigen::Vector3d::Zero();  ///< predicted by the IMU, else the keyframe's
    graph::ImuBias bias;               ///< the chain's bias estimate (else bias_body)
  };
  /// The IMU factor and bias random walk from the chain's last keyframe to `keyframe` (its pose
  /// and velocity in the graph's world), appended to `out`, when the keyframe follows that one
  /// and the IMU covers the interval; the IMU starts from the graph's estimate of V, B there.
  Link link(const msgs::Keyframe& keyframe, const graph::ImuBias& bias_body, const graph::Values& estimate, graph::GraphUpdate& out) const;
  /// V(k) and B(k) with their initial values (priors too when the keyframe starts a chain);
  /// the keyframe becomes the chain's last.
  void close(const msgs::Keyframe& keyframe, const Eigen::Vector3d& velocity, const Link& link, graph::GraphUpdate& out);
  /// The next keyframe starts a new chain.
  void restart() { previous_.reset(); }
  const graph::ImuPreintegrationConfig& config() const { return imu_; }

 private:
  struct Anchor {
    uint64_t id;
    Timestamp time;
  };
  graph::ImuPreintegrationConfig imu_;
  double accel_bias_random_walk_;
  double gyro_bias_random_walk_;
  ImuChainPriors priors_;
  std::deque<estimate::ImuSample> samples_;
  std::optional<Anchor> previous_;
};

}  // namespace hanzo::fusion::pipeline
