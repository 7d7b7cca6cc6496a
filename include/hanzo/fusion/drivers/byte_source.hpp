#pragma once
// Live byte sources for the drivers: UDP sockets (LiDAR packets), TCP streams (NMEA from a
// receiver's or gpsd's raw port) and serial ports or pseudo-terminals (GNSS receivers, IMUs),
// named by URL:
//   udp://:2368              every address of this machine, port 2368
//   udp://192.168.1.77:2368  one local address (a multi-homed computer)
//   tcp://10.0.0.5:2947      connect to a TCP server
//   serial:///dev/ttyUSB0?baud=115200   raw 8N1 at that speed (default 115200)
// read() waits at most its timeout and returns the bytes that came (a UDP datagram each; for
// streams whatever arrived), with the machine's clock at arrival. A source is used from one
// thread at a time.
//
// Failures: parse_source_url names what is wrong with a URL; open_source names the address and
// the system's reason (port in use, no such device, connection refused); read() fails when the
// stream ended (peer closed, device gone).
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"

namespace hanzo::fusion::drivers {

struct SourceAddress {
  enum class Kind { kUdp, kTcp, kSerial };
  Kind kind = Kind::kUdp;
  std::string host;    ///< udp: local address ("" = any); tcp: the server
  uint16_t port = 0;   ///< udp, tcp
  std::string device;  ///< serial: the device path
  int baud = 115200;   ///< serial
  std::string url;     ///< as given
};

Result<SourceAddress> parse_source_url(std::string_view url);

struct ReceivedBytes {
  std::string bytes;
  Timestamp time;               ///< the machine's clock when they arrived
  uint16_t destination_port = 0;  ///< udp: the port they came to
};

class ByteSource {
 public:
  virtual ~ByteSource() = default;
  /// Bytes that arrived within `timeout`; none when nothing came.
  virtual Result<std::optional<ReceivedBytes>> read(std::chrono::milliseconds timeout) = 0;
  virtual const SourceAddress& address() const = 0;
};

/// Binds, connects or opens the address.
Result<std::unique_ptr<ByteSource>> open_source(const SourceAddress& address);

}  // namespace hanzo::fusion::drivers
