#include <cstdio>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/convert.hpp"

int main(int argc, char** argv) {
  using namespace hanzo::fusion;
  if (argc != 2) return 2;
  const auto calibration = calib::load_calibration(argv[1]);
  if (!calibration) {
    std::fprintf(stderr, "%s\n", calibration.error().message.c_str());
    return 1;
  }
  msgs::ImuMessage imu;
  imu.timestamp = Timestamp::from_nanoseconds(1);
  const auto back = msgs::from_proto(msgs::to_proto(imu));
  const SE3 pose = SE3::exp(SE3::Tangent::Constant(0.1));
  std::printf("sensors=%zu imu_ok=%d angle=%.6f\n", calibration->sensors.size(), back.ok() ? 1 : 0, pose.rotation().angle());
  return back.ok() ? 0 : 1;
}
