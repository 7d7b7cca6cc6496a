#include <cstdio>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/crypto/file_encryption.hpp"
#include "hanzo/fusion/msgs/convert.hpp"
#include "hanzo/fusion/privacy/privacy_filter.hpp"

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
  const crypto::EncryptionKey key = crypto::EncryptionKey::generate();
  const auto opened = crypto::decrypt(crypto::encrypt("sealed", key), {key});
  const bool crypto_ok = opened.ok() && *opened == "sealed" && privacy::parse_redaction("blur").ok();
  std::printf("sensors=%zu imu_ok=%d crypto_ok=%d angle=%.6f\n", calibration->sensors.size(), back.ok() ? 1 : 0, crypto_ok ? 1 : 0,
              pose.rotation().angle());
  return back.ok() && crypto_ok ? 0 : 1;
}
