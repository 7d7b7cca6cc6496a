// Hesai Pandar40P on a real capture (../shared/data/drivers/hesai_pandar40p_velocity_report:
// 200 packets, about two rotations at 20 Hz, the unit's angle and firetime corrections). No
// reference decode ships with it, so the test checks what the packets themselves fix: every
// packet decodes; blocks fire 55.56 us apart across packets by the sensor's own clock (the
// firing model of the Pandar40P manual); the rotation in between is whole (40 rings, 360
// degrees in 0.4-degree steps, 50 ms long); the unit's corrections reach the points; the
// capture's clock stands in for the sensor's unsynchronized one; bad input is refused.
#include <algorithm>
#include <cmath>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "hanzo/fusion/drivers/hesai.hpp"
#include "hanzo/fusion/drivers/pcap.hpp"

namespace hanzo::fusion::drivers {
namespace {

const std::string kFolder = std::string(HANZO_DATA_DIR) + "/drivers/hesai_pandar40p_velocity_report/";

HesaiCalibration unit_calibration() {
  return load_hesai_calibration(kFolder + "calib/Pandar40P_Angle_Correction_File.csv", kFolder + "calib/Pandar40P_Firetime_Correction_File.csv")
      .value();
}

std::vector<UdpDatagram> capture() {
  std::vector<UdpDatagram> datagrams;
  PcapReader reader = PcapReader::open(kFolder + "lidar_20Hz.pcapng").value();
  while (std::optional<UdpDatagram> datagram = reader.next().value()) datagrams.push_back(std::move(*datagram));
  return datagrams;
}

std::vector<msgs::PointCloudMessage> decode(const std::vector<UdpDatagram>& datagrams, HesaiDecoder& decoder) {
  std::vector<msgs::PointCloudMessage> frames;
  for (const UdpDatagram& datagram : datagrams) decoder.add_packet(datagram.payload, datagram.time, frames);
  decoder.flush(frames);
  return frames;
}

TEST(Hesai, CalibrationFilesOfTheUnitAreReadAndBadOnesRefusedByName) {
  const HesaiCalibration calibration = unit_calibration();
  ASSERT_EQ(calibration.channels.size(), 40U);
  EXPECT_NEAR(calibration.channels[0].elevation, 15.21 * M_PI / 180.0, 1e-12);
  EXPECT_NEAR(calibration.channels[0].azimuth_offset, -1.042 * M_PI / 180.0, 1e-12);
  EXPECT_NEAR(calibration.channels[0].firetime, -42.22e-6, 1e-15);
  EXPECT_NEAR(calibration.channels[3].firetime, -3.62e-6, 1e-15);
  const HesaiCalibration angles_only = load_hesai_calibration(kFolder + "calib/Pandar40P_Angle_Correction_File.csv", "").value();
  EXPECT_EQ(angles_only.channels[0].firetime, 0.0);
  const auto missing = load_hesai_calibration(kFolder + "calib/none.csv", "");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("none.csv"), std::string::npos);
  // The firetime file given as the angle file: two columns where three are expected.
  const auto swapped = load_hesai_calibration(kFolder + "calib/Pandar40P_Firetime_Correction_File.csv", "");
  ASSERT_FALSE(swapped.ok());
  EXPECT_NE(swapped.error().message.find("Pandar40P_Firetime_Correction_File.csv:2"), std::string::npos) << swapped.error().message;
}

TEST(Hesai, RealCaptureDecodesIntoWholeRotationsFiredOnTheManualsSchedule) {
  const std::vector<UdpDatagram> datagrams = capture();
  ASSERT_EQ(datagrams.size(), 200U);
  HesaiDecoderConfig config;
  config.time_source = HesaiTimeSource::kPacket;
  HesaiDecoder decoder = HesaiDecoder::create(unit_calibration(), config).value();
  const std::vector<msgs::PointCloudMessage> frames = decode(datagrams, decoder);
  const HesaiStatistics& statistics = decoder.statistics();
  EXPECT_EQ(statistics.packets, 200U);
  EXPECT_EQ(statistics.malformed, 0U) << statistics.first_error;
  EXPECT_EQ(statistics.capture_clock_packets, 0U);
  // 2000 blocks at 0.4 degrees: a partial rotation, a whole one, a partial one.
  ASSERT_EQ(frames.size(), 3U);
  const msgs::PointCloudMessage& whole = frames[1];
  std::set<uint32_t> rings(whole.ring_ids.begin(), whole.ring_ids.end());
  EXPECT_EQ(rings.size(), 40U);
  EXPECT_EQ(*rings.rbegin(), 39U);
  // Azimuths (of the points' directions) cover the circle: no gap wider than 2 degrees.
  std::vector<double> azimuths;
  for (const Eigen::Vector3f& point : whole.points) azimuths.push_back(std::atan2(point.y(), point.x()) * 180.0 / M_PI + 180.0);
  std::sort(azimuths.begin(), azimuths.end());
  double widest = 360.0 - azimuths.back() + azimuths.front();
  for (std::size_t i = 1; i < azimuths.size(); ++i) widest = std::max(widest, azimuths[i] - azimuths[i - 1]);
  EXPECT_LT(widest, 2.0);
  EXPECT_GT(whole.points.size(), 20000U);
  EXPECT_LE(whole.points.size(), 900U * 40U);
  // One rotation at 20 Hz by the sensor's clock: 50 ms from its first firing to its last.
  const auto [earliest, latest] = std::minmax_element(whole.point_timestamps.begin(), whole.point_timestamps.end());
  EXPECT_NEAR((*latest - *earliest).seconds(), 0.05, 0.001);
  EXPECT_EQ(whole.timestamp, *earliest);
  // The unit's firetimes reach the points: in a block, channel 4 fires 38.6 us after channel 1
  // (-3.62 us and -42.22 us from the block's time).
  const HesaiCalibration calibration = unit_calibration();
  const auto ring_of = [&](int channel) {
    return static_cast<uint32_t>(std::count_if(calibration.channels.begin(), calibration.channels.end(), [&](const HesaiChannel& other) {
      return other.elevation < calibration.channels[static_cast<std::size_t>(channel)].elevation;
    }));
  };
  int pairs = 0;
  for (std::size_t i = 0; i + 3 < whole.points.size(); ++i) {
    if (whole.ring_ids[i] != ring_of(0)) continue;
    for (std::size_t j = i + 1; j <= i + 3; ++j) {
      if (whole.ring_ids[j] != ring_of(3)) continue;
      EXPECT_NEAR((whole.point_timestamps[j] - whole.point_timestamps[i]).seconds(), 38.6e-6, 1e-8);
      ++pairs;
    }
  }
  EXPECT_GT(pairs, 100);
  // Packets follow each other by ten block periods on the sensor's clock (the times of every
  // packet's first channel-1 return, where present, step by 555.6 us).
  std::vector<Timestamp> ring_39_times;  // the highest channel (channel 1: elevation 15.21 degrees)
  for (const msgs::PointCloudMessage& frame : frames) {
    for (std::size_t i = 0; i < frame.points.size(); ++i) {
      if (frame.ring_ids[i] == 39) ring_39_times.push_back(frame.point_timestamps[i]);
    }
  }
  ASSERT_GT(ring_39_times.size(), 1000U);
  int on_schedule = 0, steps = 0;
  for (std::size_t i = 1; i < ring_39_times.size(); ++i) {
    const double step = (ring_39_times[i] - ring_39_times[i - 1]).seconds() / 55.56e-6;
    ++steps;
    if (std::abs(step - std::round(step)) < 0.05 && std::round(step) >= 1) ++on_schedule;
  }
  EXPECT_GT(on_schedule, steps * 99 / 100) << "channel 1's returns lie on the 55.56 us block grid across packets";
}

TEST(Hesai, TheCaptureClockStandsInForAnUnsynchronizedSensorAndBadPacketsAreCounted) {
  const std::vector<UdpDatagram> datagrams = capture();
  HesaiDecoder decoder = HesaiDecoder::create(unit_calibration()).value();
  const std::vector<msgs::PointCloudMessage> frames = decode(datagrams, decoder);
  // The unit's clock was not synchronized (its date is years before the capture's).
  EXPECT_EQ(decoder.statistics().capture_clock_packets, 200U);
  ASSERT_EQ(frames.size(), 3U);
  EXPECT_NEAR((frames[1].timestamp - datagrams.front().time).seconds(), 0.0, 0.2);

  HesaiDecoder bad = HesaiDecoder::create(unit_calibration()).value();
  std::vector<msgs::PointCloudMessage> none;
  bad.add_packet(std::string(1206, '\0'), datagrams.front().time, none);
  std::string flipped = datagrams.front().payload;
  flipped[124] = 0;  // block 1's flag
  bad.add_packet(flipped, datagrams.front().time, none);
  EXPECT_EQ(bad.statistics().malformed, 2U);
  EXPECT_NE(bad.statistics().first_error.find("1206 bytes"), std::string::npos);
  EXPECT_EQ(bad.statistics().packets, 0U);
  HesaiCalibration short_calibration = unit_calibration();
  short_calibration.channels.pop_back();
  EXPECT_FALSE(HesaiDecoder::create(short_calibration).ok());
}

}  // namespace
}  // namespace hanzo::fusion::drivers
