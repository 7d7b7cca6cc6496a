#pragma once
// Readers for ../shared/data/euroc_v101_micro (EuRoC V1_01's first 95 stereo frames, its whole
// IMU and OpenVINS's ground truth) shared by the tests that use it.

#include <algorithm>
#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"

namespace hanzo::fusion::test_support {

inline std::string euroc_micro_dir() { return std::string(HANZO_DATA_DIR) + "/euroc_v101_micro"; }

/// EuRoC imu0/data.csv (timestamp [ns], w_x, w_y, w_z [rad/s], a_x, a_y, a_z [m/s^2]): the samples
/// from first_seconds after the first one, for `seconds`.
inline std::vector<estimate::ImuSample> read_euroc_imu(const std::string& path, double first_seconds, double seconds) {
  std::ifstream file(path);
  std::vector<estimate::ImuSample> samples;
  std::string line;
  int64_t start_ns = -1;
  while (std::getline(file, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream fields(line);
    int64_t ns = 0;
    estimate::ImuSample sample;
    fields >> ns >> sample.angular_velocity.x() >> sample.angular_velocity.y() >> sample.angular_velocity.z() >> sample.linear_acceleration.x() >>
        sample.linear_acceleration.y() >> sample.linear_acceleration.z();
    if (start_ns < 0) start_ns = ns;
    const double t = static_cast<double>(ns - start_ns) * 1e-9;
    if (t < first_seconds) continue;
    if (t >= first_seconds + seconds) break;
    sample.timestamp = Timestamp::from_nanoseconds(ns);
    samples.push_back(sample);
  }
  return samples;
}

/// One row of OpenVINS's groundtruth_openvins/V1_01_easy_ovcorrected.csv (at camera times).
struct OpenVinsState {
  Timestamp timestamp;
  SE3 T_world_imu;
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero();
};

inline std::vector<OpenVinsState> read_openvins_ground_truth(const std::string& path) {
  std::ifstream file(path);
  std::vector<OpenVinsState> states;
  std::string line;
  while (std::getline(file, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream fields(line);
    int64_t ns = 0;
    Eigen::Vector3d p;
    double qw, qx, qy, qz;
    OpenVinsState state;
    fields >> ns >> p.x() >> p.y() >> p.z() >> qw >> qx >> qy >> qz >> state.velocity.x() >> state.velocity.y() >> state.velocity.z() >>
        state.gyro_bias.x() >> state.gyro_bias.y() >> state.gyro_bias.z() >> state.accel_bias.x() >> state.accel_bias.y() >> state.accel_bias.z();
    state.timestamp = Timestamp::from_nanoseconds(ns);
    state.T_world_imu = SE3(SO3::from_quaternion_normalized(Eigen::Quaterniond(qw, qx, qy, qz)), p);
    states.push_back(state);
  }
  return states;
}

}  // namespace hanzo::fusion::test_support
