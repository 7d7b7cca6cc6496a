// Ouster captures from the ouster-sdk's tests (../shared/data/drivers/ouster_sdk_pcaps): OS-1-32
// and OS-2-32 in the LEGACY packet format, OS-0-128 in RNG15_RFL8_NIR8, each with its metadata:
// the frame's range image hashes to the SDK's own digest (MD5 of the staggered H x W uint32
// image), the frame is complete, column times increase, every pixel with a range is a point at
// that range from its beam's origin; the OS-1-64's reduced legacy metadata and IMU packets; the
// newer metadata layout with the ACCEL32_GYRO32_NMEA IMU profile; the RNG19 single and dual
// profiles on packets rewritten from the RNG15 capture; undecoded profiles refused.
#include <algorithm>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <fmt/format.h>
#include <openssl/evp.h>

#include "hanzo/fusion/drivers/ouster.hpp"
#include "hanzo/fusion/drivers/pcap.hpp"

namespace hanzo::fusion::drivers {
namespace {

const std::string kOuster = std::string(HANZO_DATA_DIR) + "/drivers/ouster_sdk_pcaps/";

std::string md5_hex(const void* data, std::size_t size) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  EVP_Digest(data, size, digest, &length, EVP_md5(), nullptr);
  std::string hex;
  for (unsigned int i = 0; i < length; ++i) hex += fmt::format("{:02x}", digest[i]);
  return hex;
}

struct Decoded {
  std::vector<OusterFrame> frames;
  std::vector<msgs::ImuMessage> imu;
  OusterStatistics statistics;
};

Decoded decode(const std::string& capture, const std::string& metadata_file) {
  auto decoder = OusterDecoder::create(load_ouster_metadata(kOuster + metadata_file).value()).value();
  auto reader = PcapReader::open(kOuster + capture).value();
  Decoded decoded;
  while (auto datagram = reader.next().value()) decoder.add_packet(datagram->payload, datagram->time, decoded.frames, decoded.imu);
  decoder.flush(decoded.frames);
  decoded.statistics = decoder.statistics();
  return decoded;
}

}  // namespace

class OusterCapture : public ::testing::TestWithParam<const char*> {};

TEST_P(OusterCapture, RangeImageHashesToTheSdksDigestAndPointsLieAtTheirRanges) {
  const std::string stem = GetParam();
  const OusterMetadata metadata = load_ouster_metadata(kOuster + stem + ".json").value();
  const Decoded decoded = decode(stem + ".pcap", stem + ".json");
  EXPECT_EQ(decoded.statistics.malformed, 0u) << decoded.statistics.first_error;
  ASSERT_EQ(decoded.frames.size(), 1u);
  const OusterFrame& frame = decoded.frames.front();
  std::ifstream digest_file(kOuster + stem + "_digest.json");
  const nlohmann::json digest = nlohmann::json::parse(digest_file);
  EXPECT_EQ(std::to_string(frame.frame_id), digest["scans"][0]["FRAME_ID"].get<std::string>());
  EXPECT_EQ(md5_hex(frame.range_mm.data(), frame.range_mm.size() * sizeof(uint32_t)), digest["scans"][0]["RANGE"].get<std::string>());
  EXPECT_TRUE(frame.complete);
  EXPECT_EQ(frame.columns, metadata.columns_per_frame);
  const std::size_t returns = static_cast<std::size_t>(std::count_if(frame.range_mm.begin(), frame.range_mm.end(), [](uint32_t range) { return range > 0; }));
  ASSERT_EQ(frame.cloud.points.size(), returns);
  // Each point at its range from its beam's origin: the sensor-frame point moved back into the
  // lidar frame, less the beam origin (n from the lidar's axis along the encoder direction).
  const Eigen::Matrix3d rotation = metadata.lidar_to_sensor.topLeftCorner<3, 3>();
  const Eigen::Vector3d translation = metadata.lidar_to_sensor.topRightCorner<3, 1>() * 1e-3;
  std::vector<double> beam_ranges;
  for (const Eigen::Vector3f& point : frame.cloud.points) {
    const Eigen::Vector3d lidar = rotation.transpose() * (point.cast<double>() - translation);
    const double n = metadata.lidar_origin_to_beam_origin_mm * 1e-3;
    const Eigen::Vector2d horizontal = lidar.head<2>();
    const Eigen::Vector3d beam_origin = horizontal.norm() > n ? Eigen::Vector3d(n * horizontal.x() / horizontal.norm(), n * horizontal.y() / horizontal.norm(), 0.0)
                                                              : Eigen::Vector3d::Zero();
    beam_ranges.push_back((lidar - beam_origin).norm());
  }
  std::vector<double> ranges;
  for (const uint32_t range : frame.range_mm) {
    if (range > 0) ranges.push_back(range * 1e-3);
  }
  std::sort(beam_ranges.begin(), beam_ranges.end());
  std::sort(ranges.begin(), ranges.end());
  double worst = 0.0;
  for (std::size_t i = 0; i < ranges.size(); ++i) worst = std::max(worst, std::abs(beam_ranges[i] - ranges[i]));
  // The beam origin sits on a circle of radius n around the lidar axis at the encoder angle, not
  // quite the point's own direction: within n of the guess.
  EXPECT_LT(worst, metadata.lidar_origin_to_beam_origin_mm * 1e-3 + 1e-3);
  EXPECT_LT(ranges.back(), 1048.575);  // 20 bits of millimetres
  // Column times increase with the measurement id.
  const std::vector<Timestamp>& times = frame.cloud.point_timestamps;
  EXPECT_TRUE(std::is_sorted(times.begin(), times.end()));
  EXPECT_EQ(frame.cloud.timestamp, times.front());
  std::printf("%s: %zu points, %d columns, %.1f ms of columns, %llu IMU packets\n", stem.c_str(), frame.cloud.points.size(), frame.columns,
              (times.back() - times.front()).seconds() * 1e3, static_cast<unsigned long long>(decoded.statistics.imu_packets));
}

INSTANTIATE_TEST_SUITE_P(Sensors, OusterCapture, ::testing::Values("OS-1-32-G_v2.1.1_1024x10", "OS-2-32-U0_v2.0.0_1024x10", "OS-0-128-U1_v2.3.0_1024x10"),
                         [](const ::testing::TestParamInfo<const char*>& parameter) {
                           std::string name = parameter.param;
                           name.erase(std::remove_if(name.begin(), name.end(), [](char c) { return !std::isalnum(static_cast<unsigned char>(c)); }),
                                      name.end());
                           return name;
                         });

// The OS-1-64's reduced legacy metadata (angles and mode only) with its IMU packets: one complete
// frame and 11 IMU samples of a sensor at rest (|a| = g).
TEST(Ouster, ReducedLegacyMetadataAndImuPackets) {
  const Decoded decoded = decode("OS-1-64_1024x10_fw20.pcap", "OS-1-64_sensor_config_reduced.json");
  EXPECT_EQ(decoded.statistics.malformed, 0u) << decoded.statistics.first_error;
  ASSERT_EQ(decoded.frames.size(), 1u);
  EXPECT_TRUE(decoded.frames[0].complete);
  ASSERT_EQ(decoded.imu.size(), 11u);
  for (const msgs::ImuMessage& sample : decoded.imu) {
    EXPECT_NEAR(sample.linear_acceleration.norm(), 9.81, 0.5);
    EXPECT_LT(sample.angular_velocity.norm(), 0.1);
  }
  EXPECT_TRUE(std::is_sorted(decoded.imu.begin(), decoded.imu.end(), [](const auto& a, const auto& b) { return a.timestamp < b.timestamp; }));
}

// The zone-monitoring OS-0-128's newer metadata with the ACCEL32_GYRO32_NMEA IMU profile: its
// capture's 8 IMU packets give 64 samples of a sensor at rest, about 1.56 ms apart; the zone
// packet is counted; undecoded profiles are refused by name.
TEST(Ouster, NewerMetadataAndTheAccel32Gyro32NmeaImuProfile) {
  const auto metadata = load_ouster_metadata(kOuster + "imu_zm_no_lidar_0.json");
  ASSERT_TRUE(metadata.ok()) << metadata.error().message;
  EXPECT_EQ(metadata->pixels_per_column, 128);
  EXPECT_EQ(metadata->columns_per_frame, 2048);
  EXPECT_EQ(metadata->udp_profile_lidar, "RNG19_RFL8_SIG16_NIR16_ZONE16");
  EXPECT_EQ(metadata->udp_profile_imu, "ACCEL32_GYRO32_NMEA");
  EXPECT_EQ(metadata->imu_measurements_per_packet, 8);
  const Decoded decoded = decode("imu_zm_no_lidar.pcap", "imu_zm_no_lidar_0.json");
  EXPECT_EQ(decoded.statistics.malformed, 0u) << decoded.statistics.first_error;
  EXPECT_EQ(decoded.statistics.imu_packets, 8u);
  EXPECT_EQ(decoded.statistics.zone_packets, 1u);
  EXPECT_TRUE(decoded.frames.empty());
  ASSERT_EQ(decoded.imu.size(), 64u);
  for (std::size_t i = 0; i < decoded.imu.size(); ++i) {
    EXPECT_NEAR(decoded.imu[i].linear_acceleration.norm(), 9.81, 0.5) << i;  // m/s^2
    EXPECT_LT(decoded.imu[i].angular_velocity.norm(), 0.1) << i;             // rad/s
    if (i > 0) {
      EXPECT_NEAR((decoded.imu[i].timestamp - decoded.imu[i - 1].timestamp).seconds(), 1.5625e-3, 0.05e-3) << i;
    }
  }

  OusterMetadata other = *metadata;
  other.udp_profile_lidar = "RNG15_RFL8_WIN8";
  ASSERT_FALSE(OusterDecoder::create(other).ok());
  EXPECT_NE(OusterDecoder::create(other).error().message.find("RNG15_RFL8_WIN8"), std::string::npos);
  other = *metadata;
  other.udp_profile_imu = "ACCEL64";
  ASSERT_FALSE(OusterDecoder::create(other).ok());
  EXPECT_NE(OusterDecoder::create(other).error().message.find("IMU profile ACCEL64"), std::string::npos);
  other = *metadata;
  other.imu_measurements_per_packet = 0;
  EXPECT_FALSE(OusterDecoder::create(other).ok());
  EXPECT_FALSE(parse_ouster_metadata("{\"lidar_mode\": \"1024x10\"}").ok());
  EXPECT_FALSE(parse_ouster_metadata("not json").ok());
  // Packets of another size are counted and skipped.
  auto legacy = OusterDecoder::create(load_ouster_metadata(kOuster + "OS-1-32-G_v2.1.1_1024x10.json").value()).value();
  std::vector<OusterFrame> frames;
  std::vector<msgs::ImuMessage> imu;
  legacy.add_packet(std::string(100, '\0'), Timestamp::from_nanoseconds(1), frames, imu);
  EXPECT_EQ(legacy.statistics().malformed, 1u);
  EXPECT_NE(legacy.statistics().first_error.find("6464"), std::string::npos) << legacy.statistics().first_error;
}

// The OS-0-128's RNG15_RFL8_NIR8 packets written again in the RNG19_RFL8_SIG16_NIR16 and
// RNG19_RFL8_SIG16_NIR16_DUAL layouts (the same ranges; a second return 1.5 m beyond the first on
// every 7th pixel) decode to the same range image and points, plus the second returns.
TEST(Ouster, Rng19SingleAndDualProfilesDecodeTheSameReturns) {
  const OusterMetadata rng15 = load_ouster_metadata(kOuster + "OS-0-128-U1_v2.3.0_1024x10.json").value();
  const Decoded original = decode("OS-0-128-U1_v2.3.0_1024x10.pcap", "OS-0-128-U1_v2.3.0_1024x10.json");
  ASSERT_EQ(original.frames.size(), 1u);
  const auto beams = static_cast<std::size_t>(rng15.pixels_per_column), columns = static_cast<std::size_t>(rng15.columns_per_packet);
  for (const bool dual : {false, true}) {
    OusterMetadata metadata = rng15;
    metadata.udp_profile_lidar = dual ? "RNG19_RFL8_SIG16_NIR16_DUAL" : "RNG19_RFL8_SIG16_NIR16";
    const std::size_t pixel_bytes = dual ? 16 : 12;
    auto decoder = OusterDecoder::create(metadata).value();
    auto reader = PcapReader::open(kOuster + "OS-0-128-U1_v2.3.0_1024x10.pcap").value();
    std::vector<OusterFrame> frames;
    std::vector<msgs::ImuMessage> imu;
    std::size_t seconds = 0;
    while (auto datagram = reader.next().value()) {
      const std::string& in = datagram->payload;
      if (in.size() != 32 + columns * (12 + 4 * beams) + 32) {
        decoder.add_packet(in, datagram->time, frames, imu);  // the IMU packets as they are
        continue;
      }
      std::string out = in.substr(0, 32);
      for (std::size_t column = 0; column < columns; ++column) {
        const std::size_t at = 32 + column * (12 + 4 * beams);
        out += in.substr(at, 12);
        for (std::size_t beam = 0; beam < beams; ++beam) {
          const auto* pixel = reinterpret_cast<const uint8_t*>(in.data() + at + 12 + 4 * beam);
          const uint32_t range_mm = static_cast<uint32_t>((pixel[0] | (pixel[1] << 8)) & 0x7FFF) * 8;
          std::string written(pixel_bytes, '\0');
          std::memcpy(written.data(), &range_mm, 4);  // 19 bits, nothing above
          if (dual) {
            written[3] = static_cast<char>(pixel[2]);
            const bool second = range_mm > 0 && (column * beams + beam) % 7 == 0;
            const uint32_t second_mm = second ? range_mm + 1500 : range_mm;
            seconds += second ? 1 : 0;
            std::memcpy(written.data() + 4, &second_mm, 3);
            written[7] = static_cast<char>(pixel[2]);
          } else {
            written[4] = static_cast<char>(pixel[2]);
          }
          out += written;
        }
      }
      out += in.substr(in.size() - 32);
      ASSERT_EQ(out.size(), decoder.lidar_packet_bytes());
      decoder.add_packet(out, datagram->time, frames, imu);
    }
    decoder.flush(frames);
    EXPECT_EQ(decoder.statistics().malformed, 0u) << decoder.statistics().first_error;
    ASSERT_EQ(frames.size(), 1u) << metadata.udp_profile_lidar;
    EXPECT_EQ(frames[0].range_mm, original.frames[0].range_mm);
    EXPECT_EQ(frames[0].cloud.points.size(), original.frames[0].cloud.points.size() + seconds);
    EXPECT_EQ(frames[0].cloud.intensities.size(), frames[0].cloud.points.size());
    EXPECT_EQ(frames[0].cloud.points[0], original.frames[0].cloud.points[0]);
    EXPECT_EQ(frames[0].cloud.intensities[0], original.frames[0].cloud.intensities[0]);
    if (dual) {
      EXPECT_GT(seconds, 1000u);
    }
  }
}

}  // namespace hanzo::fusion::drivers
