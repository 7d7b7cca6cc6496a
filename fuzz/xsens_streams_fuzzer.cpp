// Fuzz target: the Xsens MTData2 decoder (drivers/xsens.hpp) on any bytes. Never a crash; every
// IMU message it emits is finite with a unit orientation, every fix in range with a positive
// covariance; and the bytes fed in pieces (sizes from the input itself) give exactly the messages
// and counts that the whole input gives.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>
#include <vector>

#include "hanzo/fusion/drivers/xsens.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  drivers::XsensDecoder whole;
  std::vector<msgs::ImuMessage> imu;
  std::vector<msgs::GnssMessage> fixes;
  whole.feed(bytes, imu, fixes);
  for (const msgs::ImuMessage& sample : imu) {
    if (!sample.linear_acceleration.allFinite() || !sample.angular_velocity.allFinite()) std::abort();
    if (sample.orientation && !(std::abs(sample.orientation->norm() - 1.0) < 1e-9)) std::abort();
  }
  for (const msgs::GnssMessage& fix : fixes) {
    if (!(std::abs(fix.latitude) <= 90.0 && std::abs(fix.longitude) <= 180.0 && std::isfinite(fix.altitude))) std::abort();
    if (!fix.position_covariance || !((*fix.position_covariance).diagonal().array() >= 0.0).all()) std::abort();
  }
  drivers::XsensDecoder pieces;
  std::vector<msgs::ImuMessage> piece_imu;
  std::vector<msgs::GnssMessage> piece_fixes;
  for (std::size_t offset = 0; offset < size;) {
    const std::size_t length = 1 + data[offset] % 17;
    pieces.feed(bytes.substr(offset, length), piece_imu, piece_fixes);
    offset += length;
  }
  const drivers::XsensStatistics &a = whole.statistics(), &b = pieces.statistics();
  if (piece_imu.size() != imu.size() || piece_fixes.size() != fixes.size() || a.messages != b.messages || a.skipped_bytes != b.skipped_bytes ||
      a.checksum_errors != b.checksum_errors || a.malformed != b.malformed || whole.pending_bytes() != pieces.pending_bytes()) {
    std::abort();
  }
  for (std::size_t i = 0; i < imu.size(); ++i) {
    if (imu[i].timestamp != piece_imu[i].timestamp || imu[i].linear_acceleration != piece_imu[i].linear_acceleration) std::abort();
  }
  return 0;
}
