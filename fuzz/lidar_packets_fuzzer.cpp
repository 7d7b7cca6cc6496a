// Fuzz target: packet captures (drivers/pcap.hpp) and Velodyne packets (drivers/velodyne.hpp)
// on any bytes. The input is read as a capture (classic pcap or pcapng: refused or read to its
// end, never a crash), and again wrapped as the UDP payload of a one-record capture (so that a
// packet seed reaches the Ethernet / IPv4 / UDP parsing without a committed capture file);
// cut into data- and position-packet-sized pieces, it is fed to a VLP-16
// and an HDL-32E decoder, into Ouster packet sizes for a 16-beam decoder of each profile, and
// into Pandar40P packet sizes for a Hesai decoder on the packets' own clock: every point finite,
// every cloud's per-point arrays as long as its points, its time the earliest point's.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "hanzo/fusion/drivers/hesai.hpp"
#include "hanzo/fusion/drivers/ouster.hpp"
#include "hanzo/fusion/drivers/pcap.hpp"
#include "hanzo/fusion/drivers/velodyne.hpp"

namespace {

template <typename T>
void append(std::string& out, T value) {
  out.append(reinterpret_cast<const char*>(&value), sizeof(T));
}

// A classic little-endian pcap of one Ethernet / IPv4 / UDP frame to port 2368 carrying `payload`
// (lengths cut to 16 bits as a capture's would be).
std::string capture_of(const std::string& payload) {
  std::string frame(12, '\xff');
  frame += std::string("\x08\x00", 2);
  const auto total = static_cast<uint16_t>(std::min<std::size_t>(payload.size() + 28, 0xffff));
  const auto udp_length = static_cast<uint16_t>(std::min<std::size_t>(payload.size() + 8, 0xffff));
  const unsigned char ip[20] = {0x45, 0, static_cast<unsigned char>(total >> 8), static_cast<unsigned char>(total & 0xff), 0, 1, 0, 0, 64, 17, 0, 0,
                                192, 168, 1, 201, 255, 255, 255, 255};
  frame.append(reinterpret_cast<const char*>(ip), sizeof(ip));
  const unsigned char udp[8] = {0x09, 0x40, 0x09, 0x40, static_cast<unsigned char>(udp_length >> 8), static_cast<unsigned char>(udp_length & 0xff), 0, 0};
  frame.append(reinterpret_cast<const char*>(udp), sizeof(udp));
  frame += payload;
  std::string capture;
  for (const uint32_t word : {0xa1b2c3d4u, 0x00040002u, 0u, 0u, 65535u, 1u}) append(capture, word);
  for (const uint32_t word : {1700000000u, 0u, static_cast<uint32_t>(frame.size()), static_cast<uint32_t>(frame.size())}) append(capture, word);
  return capture + frame;
}

void read_capture(const std::string& bytes) {
  auto reader = hanzo::fusion::drivers::PcapReader::from_bytes(bytes);
  if (!reader) return;
  for (int count = 0; count < 100000; ++count) {
    auto datagram = reader->next();
    if (!datagram || !*datagram) break;
  }
}

// Clouds of a rotation decoder: points, finite, per-point arrays as long, time the earliest point's.
void check_rotations(const std::vector<hanzo::fusion::msgs::PointCloudMessage>& frames) {
  for (const hanzo::fusion::msgs::PointCloudMessage& frame : frames) {
    if (frame.points.empty() || frame.point_timestamps.size() != frame.points.size() || frame.ring_ids.size() != frame.points.size()) std::abort();
    if (frame.timestamp != *std::min_element(frame.point_timestamps.begin(), frame.point_timestamps.end())) std::abort();
    for (const Eigen::Vector3f& point : frame.points) {
      if (!point.allFinite()) std::abort();
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion;
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  read_capture(bytes);
  read_capture(capture_of(bytes));
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
    check_rotations(frames);
  }
  {
    drivers::HesaiCalibration calibration;
    for (int channel = 0; channel < drivers::kHesaiPandar40Channels; ++channel) {
      calibration.channels.push_back({(15.0 - channel) * M_PI / 180.0, (channel % 4 - 1.5) * M_PI / 180.0, -1e-6 * channel});
    }
    drivers::HesaiDecoderConfig config;
    config.time_source = drivers::HesaiTimeSource::kPacket;
    auto decoder = drivers::HesaiDecoder::create(calibration, config).value();
    std::vector<msgs::PointCloudMessage> frames;
    const std::size_t piece = size > 0 && data[0] % 2 == 0 ? 1262 : 1266;
    for (std::size_t offset = 0; offset < size; offset += piece) {
      decoder.add_packet(std::string_view(bytes).substr(offset, piece), Timestamp::from_nanoseconds(1'700'000'000'000'000'000LL), frames);
    }
    decoder.flush(frames);
    check_rotations(frames);
  }
  for (const char* profile : {"LEGACY", "RNG15_RFL8_NIR8", "RNG19_RFL8_SIG16_NIR16_DUAL"}) {
    drivers::OusterMetadata metadata;
    metadata.udp_profile_lidar = profile;
    if (std::string_view(profile) != "LEGACY") {  // the sample-block IMU packets with the profile packets
      metadata.udp_profile_imu = "ACCEL32_GYRO32_NMEA";
      metadata.imu_measurements_per_packet = 8;
    }
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
    const std::size_t piece = size > 0 && data[0] % 3 == 0 ? decoder.imu_packet_bytes() : decoder.lidar_packet_bytes();
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
