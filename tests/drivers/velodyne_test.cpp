// Velodyne packets from real captures (../shared/data/drivers/velodyne_veloview: a VLP-16 at
// 20 Hz and an HDL-32E with GPS position packets) against VeloView's expected decodes: the same
// rotations, points per rotation and point coordinates (within 1 mm) and intensities; the
// calibration files of both formats agree; broken packets and captures are counted, not fatal.
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "hanzo/fusion/drivers/pcap.hpp"
#include "hanzo/fusion/drivers/velodyne.hpp"

namespace hanzo::fusion::drivers {
namespace {

const std::string kVeloView = std::string(HANZO_DATA_DIR) + "/drivers/velodyne_veloview/";
const std::string kRosCalibrations = std::string(HANZO_DATA_DIR) + "/drivers/velodyne_ros_drivers_calib/";

struct ExpectedPoint {
  int index;
  double x, y, z, intensity;
};
struct ExpectedDecode {
  int frames = 0;
  std::map<int, int> points;  // per frame
  int point_frame = -1;
  std::vector<ExpectedPoint> samples;
};

// VeloView's TestReader file: frame_count, frame / point_count pairs, point_values of one frame.
ExpectedDecode read_expected(const std::string& name) {
  ExpectedDecode expected;
  std::ifstream file(kVeloView + "expected/" + name);
  std::string word;
  int frame = -1;
  while (file >> word) {
    if (word == "frame_count") {
      file >> expected.frames;
    } else if (word == "frame") {
      file >> frame;
    } else if (word == "point_count") {
      file >> expected.points[frame];
    } else if (word == "point_values") {
      ExpectedPoint point{};
      int dual = 0;
      file >> point.index >> point.x >> point.y >> point.z >> point.intensity >> dual;
      expected.point_frame = frame;
      expected.samples.push_back(point);
    }
  }
  return expected;
}

std::vector<msgs::PointCloudMessage> decode(const std::string& capture, const std::string& calibration, VelodyneModel model, VelodyneStatistics* stats = nullptr) {
  VelodyneDecoderConfig config;
  config.model = model;
  auto decoder = VelodyneDecoder::create(load_velodyne_calibration(calibration).value(), config).value();
  auto reader = PcapReader::open(capture).value();
  std::vector<msgs::PointCloudMessage> frames;
  while (true) {
    Result<std::optional<UdpDatagram>> datagram = reader.next();
    EXPECT_TRUE(datagram.ok());
    if (!datagram || !*datagram) break;
    decoder.add_packet((*datagram)->payload, (*datagram)->time, frames);
  }
  decoder.flush(frames);
  if (stats != nullptr) *stats = decoder.statistics();
  EXPECT_EQ(reader.statistics().truncated, 0u);
  return frames;
}

void expect_veloview_decode(const std::vector<msgs::PointCloudMessage>& frames, const ExpectedDecode& expected) {
  ASSERT_EQ(static_cast<int>(frames.size()), expected.frames);
  for (const auto& [frame, points] : expected.points) EXPECT_EQ(static_cast<int>(frames[static_cast<std::size_t>(frame)].points.size()), points) << "frame " << frame;
  const msgs::PointCloudMessage& frame = frames[static_cast<std::size_t>(expected.point_frame)];
  for (const ExpectedPoint& point : expected.samples) {
    const Eigen::Vector3f& ours = frame.points[static_cast<std::size_t>(point.index)];
    // VeloView's axes: y toward azimuth 0, x to its right; ours: x toward azimuth 0, y left.
    EXPECT_NEAR(ours.x(), point.y, 1e-3) << "point " << point.index;
    EXPECT_NEAR(ours.y(), -point.x, 1e-3) << "point " << point.index;
    EXPECT_NEAR(ours.z(), point.z, 1e-3) << "point " << point.index;
    EXPECT_NEAR(frame.intensities[static_cast<std::size_t>(point.index)] * 255.0F, point.intensity, 1e-3) << "point " << point.index;
  }
  for (const msgs::PointCloudMessage& cloud : frames) {
    ASSERT_EQ(cloud.point_timestamps.size(), cloud.points.size());
    ASSERT_EQ(cloud.ring_ids.size(), cloud.points.size());
    EXPECT_EQ(cloud.timestamp, *std::min_element(cloud.point_timestamps.begin(), cloud.point_timestamps.end()));
  }
}

}  // namespace

TEST(Velodyne, Vlp16CaptureDecodesAsVeloViewDecodesIt) {
  VelodyneStatistics statistics;
  const auto frames = decode(kVeloView + "vlp-16-test-90deg-1-50-frames.pcap", kVeloView + "calib/VLP-16.xml", VelodyneModel::kVlp16, &statistics);
  expect_veloview_decode(frames, read_expected("vlp-16.test"));
  EXPECT_EQ(statistics.packets, 1902u);
  EXPECT_EQ(statistics.position_packets, 367u);
  EXPECT_EQ(statistics.malformed, 0u) << statistics.first_error;
  // A full rotation at 20 Hz spans 50 ms; the rings are the 16 lasers by elevation.
  const msgs::PointCloudMessage& rotation = frames[16];
  const auto [first, last] = std::minmax_element(rotation.point_timestamps.begin(), rotation.point_timestamps.end());
  EXPECT_NEAR((*last - *first).seconds(), 0.05, 0.003);
  EXPECT_EQ(*std::max_element(rotation.ring_ids.begin(), rotation.ring_ids.end()), 15u);
}

TEST(Velodyne, Hdl32eCaptureDecodesAsVeloViewDecodesIt) {
  VelodyneStatistics statistics;
  const auto frames = decode(kVeloView + "monterey-first-100-packets.pcap", kVeloView + "calib/HDL-32.xml", VelodyneModel::kHdl32e, &statistics);
  expect_veloview_decode(frames, read_expected("monterey.test"));
  EXPECT_EQ(statistics.position_packets, 299u);  // VeloView's TestPositionReader count
  EXPECT_EQ(statistics.malformed, 0u) << statistics.first_error;
}

// The same lasers from Velodyne's db.xml and the ROS driver's YAML (degrees and cm vs radians and m).
TEST(Velodyne, CalibrationFilesOfBothFormatsAgree) {
  const auto xml = load_velodyne_calibration(kRosCalibrations + "db_xml/32db.xml");
  const auto yaml = load_velodyne_calibration(kRosCalibrations + "32db.yaml");
  ASSERT_TRUE(xml.ok()) << xml.error().message;
  ASSERT_TRUE(yaml.ok()) << yaml.error().message;
  ASSERT_EQ(xml->lasers.size(), 32u);
  ASSERT_EQ(yaml->lasers.size(), 32u);
  for (std::size_t laser = 0; laser < 32; ++laser) {
    EXPECT_NEAR(xml->lasers[laser].vertical_angle, yaml->lasers[laser].vertical_angle, 1e-6) << laser;
    EXPECT_NEAR(xml->lasers[laser].rotational_correction, yaml->lasers[laser].rotational_correction, 1e-6) << laser;
  }
  EXPECT_NEAR(xml->distance_resolution, yaml->distance_resolution, 1e-9);
  for (const char* file : {"VLP16db.yaml", "VLS128.yaml", "VeloView-VLP-32C.yaml", "64e_s2.1-sztaki.yaml", "db_xml/64e_s2.1-sztaki.xml"}) {
    const auto calibration = load_velodyne_calibration(kRosCalibrations + file);
    ASSERT_TRUE(calibration.ok()) << file << ": " << calibration.error().message;
    EXPECT_GE(calibration->lasers.size(), 16u) << file;
  }
  const auto vlp16 = load_velodyne_calibration(kRosCalibrations + "VLP16db.yaml").value();
  const auto veloview_vlp16 = load_velodyne_calibration(kVeloView + "calib/VLP-16.xml").value();
  ASSERT_EQ(veloview_vlp16.lasers.size(), 16u);
  for (std::size_t laser = 0; laser < 16; ++laser) EXPECT_NEAR(vlp16.lasers[laser].vertical_angle, veloview_vlp16.lasers[laser].vertical_angle, 1e-6);
  EXPECT_FALSE(load_velodyne_calibration(kVeloView + "expected/vlp-16.test").ok());
  // The nominal calibrations are the data sheets' elevations (as these units' files have them).
  const VelodyneCalibration nominal_vlp16 = nominal_velodyne_calibration(VelodyneModel::kVlp16);
  for (std::size_t laser = 0; laser < 16; ++laser) EXPECT_NEAR(nominal_vlp16.lasers[laser].vertical_angle, vlp16.lasers[laser].vertical_angle, 1e-6);
  const VelodyneCalibration nominal_hdl32 = nominal_velodyne_calibration(VelodyneModel::kHdl32e);
  const VelodyneCalibration hdl32 = load_velodyne_calibration(kVeloView + "calib/HDL-32.xml").value();
  for (std::size_t laser = 0; laser < 32; ++laser) EXPECT_NEAR(nominal_hdl32.lasers[laser].vertical_angle, hdl32.lasers[laser].vertical_angle, 1e-4) << laser;
  EXPECT_FALSE(VelodyneDecoder::create(vlp16, {.model = VelodyneModel::kHdl32e}).ok());  // 16 lasers for a 32-laser model
}

// HDL-64E two-point distance corrections: on for every laser of the 64E's files in both formats
// (with the same values), off for a 32-laser db.xml that carries the fields; a return decodes to
// the two-point model's point (x from the x-interpolated correction, y and z from the y one).
TEST(Velodyne, Hdl64eTwoPointCorrections) {
  const auto xml = load_velodyne_calibration(kRosCalibrations + "db_xml/64e_s2.1-sztaki.xml").value();
  const auto yaml = load_velodyne_calibration(kRosCalibrations + "64e_s2.1-sztaki.yaml").value();
  ASSERT_EQ(xml.lasers.size(), 64u);
  ASSERT_EQ(yaml.lasers.size(), 64u);
  for (std::size_t laser = 0; laser < 64; ++laser) {
    EXPECT_TRUE(xml.lasers[laser].two_point_correction) << laser;
    EXPECT_TRUE(yaml.lasers[laser].two_point_correction) << laser;
    EXPECT_NEAR(xml.lasers[laser].distance_correction_x, yaml.lasers[laser].distance_correction_x, 1e-6) << laser;
    EXPECT_NEAR(xml.lasers[laser].distance_correction_y, yaml.lasers[laser].distance_correction_y, 1e-6) << laser;
  }
  EXPECT_GT(xml.lasers[0].distance_correction_x, 1.0);  // 155.00304 cm in the file
  const VelodyneCalibration hdl32 = load_velodyne_calibration(kRosCalibrations + "db_xml/32db.xml").value();
  for (const VelodyneLaser& laser : hdl32.lasers) EXPECT_FALSE(laser.two_point_correction);

  VelodyneCalibration calibration = nominal_velodyne_calibration(VelodyneModel::kHdl64e);
  VelodyneLaser& laser = calibration.lasers[0];
  laser = {.vertical_angle = -0.1, .rotational_correction = 0.02, .distance_correction = 1.5, .vertical_offset = 0.2, .horizontal_offset = 0.025,
           .two_point_correction = true, .distance_correction_x = 1.45, .distance_correction_y = 1.40};
  // One return of laser 0 (the first block's first channel) at 5 m raw, azimuth 30 degrees.
  std::string packet(1206, '\0');
  for (int block = 0; block < 12; ++block) {
    const uint16_t flag = block % 2 == 0 ? 0xEEFF : 0xDDFF;
    const uint16_t azimuth = static_cast<uint16_t>(3000 + (block / 2) * 10);
    std::memcpy(&packet[static_cast<std::size_t>(block * 100)], &flag, 2);
    std::memcpy(&packet[static_cast<std::size_t>(block * 100 + 2)], &azimuth, 2);
  }
  const uint16_t raw = 2500;  // 2 mm units
  std::memcpy(&packet[4], &raw, 2);
  packet[6] = 100;
  packet[1204] = 0x37;
  const auto decode = [&](const VelodyneCalibration& with) {
    auto decoder = VelodyneDecoder::create(with, {.model = VelodyneModel::kHdl64e}).value();
    std::vector<msgs::PointCloudMessage> frames;
    decoder.add_packet(packet, Timestamp::from_seconds(1700000000.0), frames);
    decoder.flush(frames);
    EXPECT_EQ(frames.size(), 1u);
    EXPECT_EQ(frames.empty() ? 0u : frames[0].points.size(), 1u);
    return frames.empty() || frames[0].points.empty() ? Eigen::Vector3d::Zero().eval() : frames[0].points[0].cast<double>().eval();
  };
  // The model by hand: the sensor's own axes (y' toward azimuth 0), then (x, y, z) = (y', -x', z).
  const double b = 30.0 * std::numbers::pi / 180.0 - laser.rotational_correction;
  const auto sensor_xy = [&](double d) {
    const double xy = d * std::cos(laser.vertical_angle) - laser.vertical_offset * std::sin(laser.vertical_angle);
    return Eigen::Vector2d(xy * std::sin(b) - laser.horizontal_offset * std::cos(b), xy * std::cos(b) + laser.horizontal_offset * std::sin(b));
  };
  const Eigen::Vector2d uncorrected = sensor_xy(5.0 + laser.distance_correction);
  const double d_x = 5.0 + 1.45 + (1.5 - 1.45) * (std::abs(uncorrected.x()) - 2.4) / 22.64;
  const double d_y = 5.0 + 1.40 + (1.5 - 1.40) * (std::abs(uncorrected.y()) - 1.93) / 23.11;
  const Eigen::Vector3d expected(sensor_xy(d_y).y(), -sensor_xy(d_x).x(),
                                 d_y * std::sin(laser.vertical_angle) + laser.vertical_offset * std::cos(laser.vertical_angle));
  const Eigen::Vector3d corrected = decode(calibration);
  EXPECT_LT((corrected - expected).norm(), 1e-5) << corrected.transpose() << " vs " << expected.transpose();
  laser.two_point_correction = false;
  const Eigen::Vector3d plain = decode(calibration);
  EXPECT_GT((plain - corrected).norm(), 0.05);  // 6-10 cm shorter at this range
  EXPECT_NEAR(plain.norm(), corrected.norm() + (plain - corrected).norm(), 0.01);  // along the ray
}

// Packets of the wrong size, a broken block flag and an azimuth out of range are counted and
// skipped; the next good packet decodes; a capture cut short ends with what it holds.
TEST(Velodyne, BrokenPacketsAndCapturesAreCountedNotFatal) {
  auto reader = PcapReader::open(kVeloView + "vlp-16-test-90deg-1-50-frames.pcap").value();
  std::string good;
  Timestamp time;
  while (good.size() != 1206) {
    auto datagram = reader.next().value();
    ASSERT_TRUE(datagram);
    good = datagram->payload;
    time = datagram->time;
  }
  auto decoder = VelodyneDecoder::create(load_velodyne_calibration(kVeloView + "calib/VLP-16.xml").value(), {}).value();
  std::vector<msgs::PointCloudMessage> frames;
  decoder.add_packet(good.substr(0, 1000), time, frames);
  std::string bad_flag = good;
  bad_flag[300] = 0x12;  // block 3's flag
  decoder.add_packet(bad_flag, time, frames);
  std::string bad_azimuth = good;
  bad_azimuth[2] = static_cast<char>(0xff);
  bad_azimuth[3] = static_cast<char>(0xff);
  decoder.add_packet(bad_azimuth, time, frames);
  EXPECT_EQ(decoder.statistics().malformed, 3u);
  EXPECT_EQ(decoder.statistics().packets, 0u);
  decoder.add_packet(good, time, frames);
  decoder.flush(frames);
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_GT(frames[0].points.size(), 300u);

  // The capture cut in its 101st record: 100 datagrams, the cut one counted.
  const std::string bytes = [] {
    std::ifstream file(kVeloView + "vlp-16-test-90deg-1-50-frames.pcap", std::ios::binary);
    std::ostringstream text;
    text << file.rdbuf();
    return text.str();
  }();
  const std::filesystem::path cut = std::filesystem::temp_directory_path() / "hanzo_cut_capture.pcap";
  std::size_t offset = 24;  // past the file header, then 100 records
  for (int record = 0; record < 100; ++record) {
    uint32_t length = 0;
    std::memcpy(&length, bytes.data() + offset + 8, 4);
    offset += 16 + length;
  }
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, offset + 100);
  auto cut_reader = PcapReader::open(cut.string()).value();
  int datagrams = 0;
  while (true) {
    auto datagram = cut_reader.next();
    ASSERT_TRUE(datagram.ok()) << datagram.error().message;
    if (!*datagram) break;
    ++datagrams;
  }
  EXPECT_EQ(datagrams, 100);
  EXPECT_EQ(cut_reader.statistics().truncated, 1u);
  std::ofstream(cut, std::ios::binary) << "not a capture at all, just some text";
  const auto not_capture = PcapReader::open(cut.string());
  ASSERT_FALSE(not_capture.ok());
  EXPECT_NE(not_capture.error().message.find("not a packet capture"), std::string::npos);
  std::filesystem::remove(cut);
}

}  // namespace hanzo::fusion::drivers
