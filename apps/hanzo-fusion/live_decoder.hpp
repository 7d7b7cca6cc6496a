#pragma once
// The driver of a configured live sensor (fusion.sensors.<name>.driver): its decoder, fed the
// bytes its source receives, gives standard messages (LiDAR rotations, IMU samples, GNSS fixes).

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/drivers/byte_source.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::app {

struct LiveDecoderCounts {
  uint64_t malformed = 0;  ///< packets, sentences or frames left out
  std::string first_error;
};

class LiveDecoder {
 public:
  virtual ~LiveDecoder() = default;
  /// Decodes what arrived; the messages completed by it are appended.
  virtual void decode(const drivers::ReceivedBytes& received, std::vector<msgs::SensorMessage>& messages) = 0;
  /// The end of the stream: what is still held (a partial rotation, the last epoch).
  virtual void flush(std::vector<msgs::SensorMessage>& messages) = 0;
  virtual LiveDecoderCounts counts() const = 0;
};

/// The decoder of `sensor.driver` (its calibration, metadata or model loaded); fails naming the
/// sensor and what is missing or unreadable.
Result<std::unique_ptr<LiveDecoder>> make_live_decoder(const config::SensorConfig& sensor);

}  // namespace hanzo::fusion::app
