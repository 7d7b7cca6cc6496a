// Static alignment on real data: EuRoC V1_01's first seconds, the MAV standing with its rotors
// running (../shared/data/euroc_v101_micro), against OpenVINS's estimates at the first camera
// frame (groundtruth_openvins/V1_01_easy_ovcorrected.csv: orientation, gyro and accel bias).

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "hanzo/fusion/estimate/static_alignment.hpp"
#include "support/euroc_micro.hpp"

namespace hanzo::fusion::estimate {
namespace {

constexpr double kDegree = M_PI / 180.0;

using test_support::read_euroc_imu;

TEST(StaticAlignment, EurocMavStandingWithItsRotorsRunningMatchesOpenVins) {
  const std::string data = std::string(HANZO_DATA_DIR) + "/euroc_v101_micro";
  const std::vector<ImuSample> still = read_euroc_imu(data + "/mav0/imu0/data.csv", 0.0, 2.0);
  ASSERT_EQ(still.size(), 400u);
  // OpenVINS at 1403715273.262 s: q_world_imu (w, x, y, z), gyro bias, accel bias.
  const SO3 R_world_imu = SO3::from_quaternion_normalized(Eigen::Quaterniond(0.069433, -0.824237, -0.106942, -0.551702));
  const Eigen::Vector3d openvins_gyro_bias(-0.00224703, 0.0215352, 0.0770299);

  // Sample to sample the rotors' vibration looks like motion (0.8 m/s^2 std); over 50 ms means
  // it does not.
  StaticAlignmentConfig per_sample;
  per_sample.motion_window_s = 0.0;
  EXPECT_FALSE(align_static(still, ImuMounting{}, 0.0, per_sample));
  Result<StaticAlignment> aligned = align_static(still, ImuMounting{}, 0.0);
  ASSERT_TRUE(aligned) << aligned.error().message;

  const Eigen::Vector3d up_imu = aligned->R_world_body.inverse() * Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d openvins_up_imu = R_world_imu.inverse() * Eigen::Vector3d::UnitZ();
  const double gravity_error = std::acos(std::clamp(up_imu.dot(openvins_up_imu), -1.0, 1.0));
  const double gyro_bias_error = (aligned->gyro_bias - openvins_gyro_bias).norm() / openvins_gyro_bias.norm();
  std::printf("EuRoC V1_01 static alignment (2 s): gravity direction %.3f deg from OpenVINS's, gyro bias (%.5f %.5f %.5f) rad/s, %.1f %% off\n",
              gravity_error / kDegree, aligned->gyro_bias.x(), aligned->gyro_bias.y(), aligned->gyro_bias.z(), 100.0 * gyro_bias_error);
  EXPECT_LT(gyro_bias_error, 0.2);
  // 0.57 deg: OpenVINS's accel bias (0.066 m/s^2 along y) alone tilts the mean specific force by
  // 0.39 deg, and a still IMU cannot tell that bias from a tilt (with it removed: 0.21 deg).
  EXPECT_LT(gravity_error, 0.7 * kDegree);

  // Seconds 5-7, when the MAV takes off, are motion.
  const std::vector<ImuSample> flying = read_euroc_imu(data + "/mav0/imu0/data.csv", 5.0, 2.0);
  ASSERT_GT(flying.size(), 300u);
  Result<StaticAlignment> refused = align_static(flying, ImuMounting{}, 0.0);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("moving"), std::string::npos);
}

}  // namespace
}  // namespace hanzo::fusion::estimate
