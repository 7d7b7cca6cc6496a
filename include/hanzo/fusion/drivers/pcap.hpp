#pragma once
// Packet captures (libpcap's classic format and pcapng) read as the UDP datagrams that sensors
// send: the recorded stream of a LiDAR (Velodyne, Ouster, Hesai) or any UDP device, replayable
// at its recorded times.
//
// Formats: classic pcap in either byte order with micro- or nanosecond times; pcapng (section
// header, interface descriptions with their time resolution, enhanced and simple packet
// blocks; other blocks skipped). Link layers: Ethernet (with 802.1Q VLAN tags), Linux cooked
// capture (SLL), raw IPv4, BSD loopback. IPv4 only; fragmented datagrams (large LiDAR packets
// over a 1500-byte MTU) are reassembled.
//
// Failures: open() fails for a missing file or one that is neither format. next() fails for a
// record whose length runs past the end or is absurd (the file is corrupt from there); a
// datagram whose headers are cut short is counted (truncated) and skipped; non-UDP packets are
// counted (other_packets).

#include <array>
#include <cstdint>
#include <istream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"

namespace hanzo::fusion::drivers {

struct UdpDatagram {
  Timestamp time;  ///< the capture's time of the (last fragment of the) packet
  std::array<uint8_t, 4> source_address{}, destination_address{};
  uint16_t source_port = 0, destination_port = 0;
  std::string payload;
};

struct PcapStatistics {
  uint64_t records = 0;        ///< packets read from the file
  uint64_t datagrams = 0;      ///< UDP datagrams returned
  uint64_t other_packets = 0;  ///< not IPv4 UDP (ARP, TCP, IPv6, ...)
  uint64_t truncated = 0;      ///< headers or payload cut short (capture's snap length, corruption)
  uint64_t fragments = 0;      ///< IPv4 fragments read (reassembled into datagrams)
  uint64_t incomplete = 0;     ///< fragmented datagrams never completed
};

class PcapReader {
 public:
  static Result<PcapReader> open(const std::string& path);
  /// A capture held in memory (`name` in error messages).
  static Result<PcapReader> from_bytes(std::string bytes, const std::string& name = "capture");

  /// The next UDP datagram in file order; none at the end of the file.
  Result<std::optional<UdpDatagram>> next();
  const PcapStatistics& statistics() const { return statistics_; }
  bool pcapng() const { return pcapng_; }

 private:
  struct Record {
    Timestamp time;
    uint32_t link_type = 0;
    std::string data;
  };
  struct Interface {
    uint32_t link_type = 1;
    double seconds_per_unit = 1e-6;
  };
  struct Fragments {
    std::map<uint32_t, std::string> pieces;  // by byte offset
    std::optional<uint32_t> total;           // known once the last fragment arrived
    std::array<uint8_t, 4> source{}, destination{};
  };
  PcapReader() = default;
  static Result<PcapReader> start(PcapReader reader);
  Result<std::optional<Record>> next_record();
  Result<std::optional<Record>> next_classic_record();
  Result<std::optional<Record>> next_pcapng_record();
  /// The UDP datagram in a captured frame, after fragment reassembly; none otherwise.
  std::optional<UdpDatagram> datagram_of(const Record& record);

  std::string path_;
  std::unique_ptr<std::istream> file_;
  uint64_t offset_ = 0;
  bool pcapng_ = false;
  bool swapped_ = false;  // the file's byte order is not this machine's (classic) / the section's
  double classic_seconds_per_unit_ = 1e-6;
  uint32_t classic_link_type_ = 1;
  std::vector<Interface> interfaces_;
  std::map<std::tuple<uint32_t, uint32_t, uint16_t>, Fragments> fragments_;  // (source, destination, id)
  PcapStatistics statistics_;
};

}  // namespace hanzo::fusion::drivers
