// Fuzz target: packet captures (drivers/pcap.hpp) and Velodyne packets (drivers/velodyne.hpp)
// on any bytes. The input is read as a capture (classic pcap or pcapng: refused or read to its
// end, never a crash) and, cut into data- and position-packet-sized pieces, fed to a VLP-16
// and an HDL-32E decoder, and into Ouster packet sizes for a 16-beam decoder of each profile:
// every point finite, every cloud's per-point arrays as long as its points, its time the
// earliest point's.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "hanzo/fusion/drivers/ouster.hpp"
#include "hanzo/fusion/drivers/pcap.hpp"
#include "hanzo/fusion/drivers/velodyne.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion;
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  if (auto reader = drivers::PcapReader::from_bytes(bytes)) {
    for (int count = 0; count < 100000; ++count) {
      auto datagram = reader->next();
      if (!datagram || !*datagram) break;
    }
  }
  for (const drivers::VelodyneModel model : {drivers::VelodyneModel::kVlp16, drivers::VelodyneModel::kHdl32e}) {
    drivers::VelodyneDecoderConfig config;
    config.model = model;
    auto decoder = drivers::VelodyneDecoder::create(drivers::nominal_velodyne_calibration(model), config).value();
    std::vector<msgs::PointCloudMessage> frames;
    const std::size_t piece = size > 0 && data[0] % 2 == 0 ? 1206 : 512;
    for (std::size_t offset = 0; offset < size; offset += piece) {
      decoder.add_packet(std::string_view(bytes).substr(offset, piece), Timestamp::from_nanoseconds(1'700'000'000'000'000'000LL), frames);
    }
    decoder.flush(frames);
    for (const msgs::PointCloudMessage& frame : frames) {
      if (frame.points.empty() || frame.point_timestamps.size() != frame.points.size() || frame.ring_ids.size() != frame.points.size()) std::abort();
      if (frame.timestamp != *std::min_element(frame.point_timestamps.begin(), frame.point_timestamps.end())) std::abort();
      for (const Eigen::Vector3f& point : frame.points) {
        if (!point.allFinite()) std::abort();
      }
    }
  }
  for (const char* profile : {"LEGACY", "RNG15_RFL8_NIR8"}) {
    drivers::OusterMetadata metadata;
    metadata.udp_profile_lidar = profile;
    metadata.pixels_per_column = 16;
    metadata.columns_per_frame = 64;
    metadata.column_window = {0, 63};
    for (int beam = 0; beam < 16; ++beam) {
      metadata.beam_altitude_deg.push_back(-15.0 + 2.0 * beam);
      metadata.beam_azimuth_deg.push_back(beam % 2 == 0 ? 3.0 : -3.0);
    }
    auto decoder = drivers::OusterDecoder::create(metadata).value();
    std::vector<drivers::OusterFrame> frames;
    std::vector<msgs::ImuMessage> imu;
    const std::size_t piece = size > 0 && data[0] % 3 == 0 ? 48 : decoder.lidar_packet_bytes();
    for (std::size_t offset = 0; offset < size; offset += piece) {
      decoder.add_packet(std::string_view(bytes).substr(offset, piece), Timestamp::from_nanoseconds(1'700'000'000'000'000'000LL), frames, imu);
    }
    decoder.flush(frames);
    for (const drivers::OusterFrame& frame : frames) {
      const msgs::PointCloudMessage& cloud = frame.cloud;
      if (cloud.points.empty() || cloud.point_timestamps.size() != cloud.points.size() || cloud.ring_ids.size() != cloud.points.size()) std::abort();
      for (const Eigen::Vector3f& point : cloud.points) {
        if (!point.allFinite()) std::abort();
      }
    }
    for (const msgs::ImuMessage& sample : imu) {
      if (!sample.linear_acceleration.allFinite() || !sample.angular_velocity.allFinite()) std::abort();
    }
  }
  return 0;
}
