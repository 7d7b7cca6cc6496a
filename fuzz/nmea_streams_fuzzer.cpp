// Fuzz target: the NMEA-0183 decoder (drivers/nmea.hpp) on any bytes. Never a crash; every fix
// it emits has a latitude and longitude in range, finite values and a positive covariance; and
// the bytes fed in pieces (sizes from the input itself) give exactly the fixes and counts that
// the whole input gives.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>
#include <vector>

#include "hanzo/fusion/drivers/nmea.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  auto whole = drivers::NmeaDecoder::create().value();
  std::vector<msgs::GnssMessage> fixes;
  whole.feed(bytes, fixes);
  whole.flush(fixes);
  for (const msgs::GnssMessage& fix : fixes) {
    if (!(std::abs(fix.latitude) <= 90.0 && std::abs(fix.longitude) <= 180.0 && std::isfinite(fix.altitude))) std::abort();
    if (!fix.position_covariance || !((*fix.position_covariance).diagonal().array() > 0.0).all()) std::abort();
  }
  auto pieces = drivers::NmeaDecoder::create().value();
  std::vector<msgs::GnssMessage> piece_fixes;
  for (std::size_t offset = 0; offset < size;) {
    const std::size_t length = 1 + data[offset] % 17;
    pieces.feed(bytes.substr(offset, length), piece_fixes);
    offset += length;
  }
  pieces.flush(piece_fixes);
  if (piece_fixes.size() != fixes.size() || pieces.statistics().sentences != whole.statistics().sentences ||
      pieces.statistics().skipped_bytes != whole.statistics().skipped_bytes || pieces.statistics().malformed != whole.statistics().malformed) {
    std::abort();
  }
  for (std::size_t i = 0; i < fixes.size(); ++i) {
    if (fixes[i].timestamp != piece_fixes[i].timestamp || fixes[i].latitude != piece_fixes[i].latitude) std::abort();
  }
  return 0;
}
