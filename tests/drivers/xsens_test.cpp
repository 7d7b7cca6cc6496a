// Xsens MTData2 against the golden decodes of real MTi-G-710 streams
// (../shared/data/drivers/imu_xsens_mti_g710: the same 13 outputs in Float32, FP12.20 and
// FP16.32): every packet of every message equal to the reference decode; bytes split anywhere
// decode the same; the ImuMessages and GNSS fixes made of them; corrupted frames counted and
// skipped.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <initializer_list>
#include <fstream>
#include <map>
#include <span>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/drivers/xsens.hpp"

namespace hanzo::fusion::drivers {
namespace {

const std::string kData = std::string(HANZO_DATA_DIR) + "/drivers/imu_xsens_mti_g710/testdata/";

std::string read_file(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  std::ostringstream text;
  text << file.rdbuf();
  return text.str();
}

// output.golden: one block per message ("Name(format):" then indented values, "X:1.5" or "1.5"),
// as name -> {key -> text}; a value without a key has the key "".
using GoldenMessage = std::map<std::string, std::map<std::string, std::string>>;

std::vector<GoldenMessage> read_golden(const std::string& path) {
  std::vector<GoldenMessage> messages(1);
  std::ifstream file(path);
  std::string line, name;
  while (std::getline(file, line)) {
    if (line.empty()) {
      if (!messages.back().empty()) messages.emplace_back();
      continue;
    }
    if (line[0] != ' ') {
      name = line.substr(0, std::min(line.find('('), line.find(':')));
      continue;
    }
    const std::string value = line.substr(2);
    const std::size_t colon = value.find(':');
    const bool keyed = colon != std::string::npos && name != "UTCTime";
    messages.back()[name][keyed ? value.substr(0, colon) : ""] = keyed ? value.substr(colon + 1) : value;
  }
  if (messages.back().empty()) messages.pop_back();
  return messages;
}

void expect_near(double value, const std::string& golden, const std::string& what) {
  const double expected = std::stod(golden);
  EXPECT_NEAR(value, expected, 1e-12 * std::max(1.0, std::abs(expected))) << what;
}

void expect_vector(const std::optional<Eigen::Vector3d>& value, const GoldenMessage& golden, const std::string& name) {
  const auto found = golden.find(name);
  ASSERT_EQ(value.has_value(), found != golden.end()) << name;
  if (!value) return;
  for (int i = 0; i < 3; ++i) expect_near((*value)(i), found->second.at(std::string(1, char('X' + i))), name);
}

std::vector<XsensMtData2> decode_file(const std::string& folder, std::size_t chunk, XsensDecoder& decoder, std::vector<msgs::ImuMessage>& imu,
                                      std::vector<msgs::GnssMessage>& gnss) {
  const std::string bytes = read_file(kData + folder + "/output.bin");
  std::vector<XsensMtData2> decoded;
  for (std::size_t at = 0; at < bytes.size(); at += chunk) decoder.feed(std::string_view(bytes).substr(at, chunk), imu, gnss, &decoded);
  return decoded;
}

TEST(Xsens, EveryPacketOfThreeNumberFormatsEqualsTheReferenceDecode) {
  for (const std::string folder : {"1", "2", "3"}) {
    SCOPED_TRACE("testdata/" + folder);
    const std::vector<GoldenMessage> golden = read_golden(kData + folder + "/output.golden");
    ASSERT_EQ(golden.size(), 100U);
    XsensDecoder decoder;
    std::vector<msgs::ImuMessage> imu;
    std::vector<msgs::GnssMessage> gnss;
    const std::vector<XsensMtData2> decoded = decode_file(folder, 4096, decoder, imu, gnss);
    ASSERT_EQ(decoded.size(), golden.size());
    const XsensStatistics& statistics = decoder.statistics();
    EXPECT_EQ(statistics.checksum_errors, 0U);
    EXPECT_EQ(statistics.malformed, 0U);
    EXPECT_EQ(statistics.skipped_bytes, 0U);
    EXPECT_EQ(statistics.unknown_packets, 0U);
    EXPECT_EQ(decoder.pending_bytes(), 0U);
    for (std::size_t i = 0; i < decoded.size(); ++i) {
      SCOPED_TRACE(fmt::format("message {}", i));
      const XsensMtData2& message = decoded[i];
      const GoldenMessage& expected = golden[i];
      EXPECT_EQ(std::to_string(message.packet_counter.value()), expected.at("PacketCounter").at(""));
      EXPECT_EQ(std::to_string(message.sample_time_fine.value()), expected.at("SampleTimeFine").at(""));
      // "2019-01-20T13:47:24.1219Z": date, time and fraction of the second.
      int year = 0, month = 0, day = 0, hour = 0, minute = 0, second = 0;
      char fraction[16] = {'0', 0};  // "...:25Z": a whole second
      ASSERT_GE(std::sscanf(expected.at("UTCTime").at("").c_str(), "%d-%d-%dT%d:%d:%d.%15[0-9]Z", &year, &month, &day, &hour, &minute, &second,
                            fraction),
                6);
      const XsensUtcTime& utc = message.utc.value();
      EXPECT_EQ(std::tuple(int(utc.year), int(utc.month), int(utc.day), int(utc.hour), int(utc.minute), int(utc.second)),
                std::tuple(year, month, day, hour, minute, second));
      EXPECT_NEAR(utc.nanoseconds * 1e-9, std::stod(std::string("0.") + fraction), 1e-12);
      for (const char* status : {"StatusWord", "StatusByte"}) {
        if (expected.contains(status)) {
          EXPECT_EQ(message.status.value(), std::stoul(expected.at(status).at(""), nullptr, 2));
        }
      }
      expect_vector(message.acceleration, expected, "Acceleration");
      expect_vector(message.delta_v, expected, "DeltaV");
      expect_vector(message.rate_of_turn, expected, "RateOfTurn");
      expect_vector(message.euler_degrees, expected, "EulerAngles");
      expect_vector(message.velocity, expected, "VelocityXYZ");
      ASSERT_EQ(message.delta_q.has_value(), expected.contains("DeltaQ"));
      if (message.delta_q) {
        const std::map<std::string, std::string>& q = expected.at("DeltaQ");
        expect_near(message.delta_q->w(), q.at("Q0"), "Q0");
        expect_near(message.delta_q->x(), q.at("Q1"), "Q1");
        expect_near(message.delta_q->y(), q.at("Q2"), "Q2");
        expect_near(message.delta_q->z(), q.at("Q3"), "Q3");
      }
      ASSERT_EQ(message.lat_lon.has_value(), expected.contains("LatLon"));
      if (message.lat_lon) {
        expect_near(message.lat_lon->x(), expected.at("LatLon").at("Lat"), "Lat");
        expect_near(message.lat_lon->y(), expected.at("LatLon").at("Lon"), "Lon");
        expect_near(message.altitude_ellipsoid.value(), expected.at("AltitudeEllipsoid").at(""), "AltitudeEllipsoid");
      }
      ASSERT_EQ(message.gnss_pvt.has_value(), expected.contains("GNSSPVTData"));
      if (message.gnss_pvt) {
        const std::map<std::string, std::string>& pvt = expected.at("GNSSPVTData");
        const XsensGnssPvt& ours = *message.gnss_pvt;
        const std::vector<std::pair<std::string, int64_t>> fields = {
            {"ITOW", ours.itow},       {"Year", ours.year},         {"Month", ours.month},       {"Day", ours.day},
            {"Hour", ours.hour},       {"Min", ours.minute},        {"Sec", ours.second},        {"Valid", ours.valid},
            {"TAcc", ours.time_accuracy}, {"Nano", ours.nano},      {"FixType", ours.fix_type},  {"Flags", ours.flags},
            {"NumSV", ours.satellites}, {"Lon", ours.longitude},    {"Lat", ours.latitude},      {"Height", ours.height},
            {"HMSL", ours.height_msl}, {"HAcc", ours.horizontal_accuracy}, {"VAcc", ours.vertical_accuracy},
            {"VelN", ours.velocity_north}, {"VelE", ours.velocity_east}, {"VelD", ours.velocity_down}, {"GSpeed", ours.ground_speed},
            {"HeadMot", ours.heading_of_motion}, {"SAcc", ours.speed_accuracy}, {"HeadAcc", ours.heading_accuracy},
            {"HeadVeh", ours.heading_of_vehicle}, {"GDOP", ours.gdop}, {"PDOP", ours.pdop}, {"TDOP", ours.tdop},
            {"VDOP", ours.vdop}, {"HDOP", ours.hdop}, {"NDOP", ours.ndop}, {"EDOP", ours.edop}};
        for (const auto& [key, value] : fields) EXPECT_EQ(std::to_string(value), pvt.at(key)) << key;
      }
    }
  }
}

TEST(Xsens, ImuMessagesAndFixesOfTheStreamSplitAnywhere) {
  for (const std::string folder : {"1", "2", "3"}) {
    SCOPED_TRACE("testdata/" + folder);
    XsensDecoder whole_decoder;
    std::vector<msgs::ImuMessage> imu;
    std::vector<msgs::GnssMessage> gnss;
    decode_file(folder, 1 << 20, whole_decoder, imu, gnss);
    // 96 inertial messages at 100 Hz, 4 GNSS PVT messages (4 Hz) without inertial data.
    ASSERT_EQ(imu.size(), 96U);
    EXPECT_EQ(whole_decoder.statistics().without_inertial, 4U);
    EXPECT_EQ(whole_decoder.statistics().device_clock, 0U);
    ASSERT_EQ(gnss.size(), 4U);
    for (std::size_t i = 1; i < imu.size(); ++i) {
      EXPECT_GT(imu[i].timestamp, imu[i - 1].timestamp);
      EXPECT_NEAR((imu[i].timestamp - imu[i - 1].timestamp).seconds(), 0.01, 0.0101) << i;  // 100 Hz, a GNSS message may sit between
    }
    // At rest after the first sample (the device's first output, its status word still
    // settling, reads 7.4 m/s^2): about 1 g of specific force, little rotation; the
    // orientation's "up" matches the measured specific force.
    for (const msgs::ImuMessage& sample : std::span(imu).subspan(1)) {
      EXPECT_NEAR(sample.linear_acceleration.norm(), 9.81, 0.3);
      EXPECT_LT(sample.angular_velocity.norm(), 0.05);
      if (!sample.orientation) continue;
      const Eigen::Vector3d up_in_sensor = sample.orientation->conjugate() * Eigen::Vector3d::UnitZ();
      EXPECT_GT(up_in_sensor.dot(sample.linear_acceleration.normalized()), 0.99);
    }
    // Split anywhere: the same messages.
    for (const std::size_t chunk : {1, 5, 97}) {
      XsensDecoder split;
      std::vector<msgs::ImuMessage> split_imu;
      std::vector<msgs::GnssMessage> split_gnss;
      decode_file(folder, chunk, split, split_imu, split_gnss);
      ASSERT_EQ(split_imu.size(), imu.size()) << chunk;
      for (std::size_t i = 0; i < imu.size(); ++i) {
        EXPECT_EQ(split_imu[i].timestamp, imu[i].timestamp);
        EXPECT_EQ(split_imu[i].linear_acceleration, imu[i].linear_acceleration);
      }
      EXPECT_EQ(split_gnss.size(), gnss.size());
    }
    for (const msgs::GnssMessage& fix : gnss) {
      EXPECT_EQ(fix.fix_type, msgs::GnssFixType::kFix3d);
      EXPECT_NEAR(fix.latitude, 57.68, 0.01);
      EXPECT_NEAR(fix.longitude, 11.88, 0.01);
    }
    if (folder != "1") continue;
    // The first fix of the first stream: 2019-01-20 13:47:24.25 UTC, 3D, 11 satellites.
    EXPECT_NEAR(gnss[0].latitude, 57.6794453, 1e-7);
    EXPECT_NEAR(gnss[0].longitude, 11.8825704, 1e-7);
    EXPECT_NEAR(gnss[0].altitude, 81.777, 1e-3);
    EXPECT_EQ(gnss[0].fix_type, msgs::GnssFixType::kFix3d);
    EXPECT_EQ(gnss[0].satellites_used, 11U);
    EXPECT_NEAR(gnss[0].timestamp.seconds(), 1547992044.0 + 0.249768484, 1e-6);
    EXPECT_NEAR(std::sqrt((*gnss[0].position_covariance)(0, 0) + (*gnss[0].position_covariance)(1, 1)), 2.259, 1e-9);
  }
}

// An Xbus MTData2 frame of the given packets (identifier, data).
std::string frame(const std::vector<std::pair<uint16_t, std::string>>& packets) {
  std::string payload;
  for (const auto& [identifier, data] : packets) {
    payload += static_cast<char>(identifier >> 8);
    payload += static_cast<char>(identifier & 0xFF);
    payload += static_cast<char>(data.size());
    payload += data;
  }
  std::string out = {'\xFA', '\xFF', static_cast<char>(kXsensMtData2), static_cast<char>(payload.size())};
  out += payload;
  uint8_t sum = 0;
  for (std::size_t i = 1; i < out.size(); ++i) sum = static_cast<uint8_t>(sum + static_cast<uint8_t>(out[i]));
  return out + static_cast<char>(static_cast<uint8_t>(-sum));
}

std::string big_endian(uint32_t value, int bytes) {
  std::string out;
  for (int i = bytes - 1; i >= 0; --i) out += static_cast<char>((value >> (8 * i)) & 0xFF);
  return out;
}

std::string floats(std::initializer_list<double> values) {
  std::string out;
  for (const double value : values) {
    const float single = static_cast<float>(value);
    uint32_t bits;
    std::memcpy(&bits, &single, sizeof(bits));
    out += big_endian(bits, 4);
  }
  return out;
}

TEST(Xsens, DeltaVAndDeltaQAloneGiveTheRatesAndCorruptFramesAreSkipped) {
  XsensDecoder decoder;
  std::vector<msgs::ImuMessage> full;
  std::vector<msgs::GnssMessage> gnss;
  std::vector<XsensMtData2> decoded = decode_file("1", 1 << 20, decoder, full, gnss);
  // The strapdown outputs alone (a configuration without Acceleration / RateOfTurn), in frames
  // of their own: DeltaV / dt and DeltaQ's rotation / dt agree with the rates the device sent.
  std::string stream;
  std::vector<const XsensMtData2*> inertial;
  for (const XsensMtData2& message : decoded) {
    if (!message.delta_v) continue;
    inertial.push_back(&message);
    const Eigen::Vector3d& v = *message.delta_v;
    const Eigen::Quaterniond& q = *message.delta_q;
    stream += frame({{0x1060, big_endian(*message.sample_time_fine, 4)},
                     {0x4010, floats({v.x(), v.y(), v.z()})},
                     {0x8030, floats({q.w(), q.x(), q.y(), q.z()})}});
  }
  XsensDecoder increments;
  std::vector<msgs::ImuMessage> derived;
  increments.feed(stream, derived, gnss);
  ASSERT_EQ(derived.size(), inertial.size() - 1) << "the first has no interval";
  EXPECT_EQ(increments.statistics().device_clock, derived.size() + 1) << "no UTCTime: the device's clock";
  for (std::size_t i = 0; i < derived.size(); ++i) {
    EXPECT_LT((derived[i].linear_acceleration - *inertial[i + 1]->acceleration).norm(), 0.05) << i;
    EXPECT_LT((derived[i].angular_velocity - *inertial[i + 1]->rate_of_turn).norm(), 2e-4) << i;
    EXPECT_NEAR(derived[i].timestamp.seconds(), *inertial[i + 1]->sample_time_fine * 1e-4, 1e-9);
  }
  // A packet whose size does not fit its identifier is malformed, the frame left out.
  std::vector<msgs::ImuMessage> none;
  XsensDecoder strict;
  strict.feed(frame({{0x4020, floats({1.0, 2.0})}}), none, gnss);
  EXPECT_EQ(strict.statistics().malformed, 1U);
  EXPECT_NE(strict.statistics().first_error.find("0x4020"), std::string::npos) << strict.statistics().first_error;
  EXPECT_TRUE(none.empty());

  // Corruption: a flipped byte in one frame costs that frame only; noise between frames is skipped.
  std::string bytes = read_file(kData + "1/output.bin");
  bytes[200] = static_cast<char>(bytes[200] ^ 0x5A);
  bytes.insert(0, "\xFA\x01noise\xFA");
  XsensDecoder corrupted;
  std::vector<msgs::ImuMessage> imu;
  gnss.clear();
  corrupted.feed(bytes, imu, gnss);
  EXPECT_GE(corrupted.statistics().checksum_errors, 1U);
  EXPECT_EQ(corrupted.statistics().mtdata2, 99U);
  EXPECT_EQ(imu.size(), full.size() - 1);
  EXPECT_FALSE(corrupted.statistics().first_error.empty());
  EXPECT_GE(corrupted.statistics().skipped_bytes, 8U);
}

}  // namespace
}  // namespace hanzo::fusion::drivers
