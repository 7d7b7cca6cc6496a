// NMEA-0183 against gpsd's decodes of real receiver logs (../shared/data/drivers/gnss_nmea_gpsd:
// SiRF-II, Telit, u-blox NEO-M9N with GST, Trimble RTK, u-blox ZED-F9P with UBX binary in
// between): every fix gpsd reports after a GGA has our position and time, every GST our
// covariance; bytes split anywhere decode the same; binary and corrupted sentences are counted
// and skipped.
#include <algorithm>
#include <cmath>
#include <ctime>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/drivers/nmea.hpp"

namespace hanzo::fusion::drivers {
namespace {

const std::string kLogs = std::string(HANZO_DATA_DIR) + "/drivers/gnss_nmea_gpsd/";

std::string read_file(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  std::ostringstream text;
  text << file.rdbuf();
  return text.str();
}

// gpsd's "2020-07-11T22:37:45.000Z" as Unix seconds.
double unix_seconds(const std::string& iso) {
  std::tm time{};
  double seconds = 0.0;
  EXPECT_EQ(std::sscanf(iso.c_str(), "%d-%d-%dT%d:%d:%lfZ", &time.tm_year, &time.tm_mon, &time.tm_mday, &time.tm_hour, &time.tm_min, &seconds), 6) << iso;
  time.tm_year -= 1900;
  time.tm_mon -= 1;
  return static_cast<double>(timegm(&time)) + seconds;
}

// Decodes `bytes` fed in pieces of random length (1 to 200 bytes).
std::vector<msgs::GnssMessage> decode(const std::string& bytes, NmeaDecoder& decoder, uint32_t seed = 1) {
  std::vector<msgs::GnssMessage> fixes;
  std::mt19937 random(seed);
  std::uniform_int_distribution<std::size_t> piece(1, 200);
  for (std::size_t offset = 0; offset < bytes.size();) {
    const std::size_t length = std::min(piece(random), bytes.size() - offset);
    decoder.feed(std::string_view(bytes).substr(offset, length), fixes);
    offset += length;
  }
  decoder.flush(fixes);
  return fixes;
}

struct Expected {
  std::map<long long, nlohmann::json> tpv;  // by time (ms): gpsd's fixes with a time and a position
  std::map<long long, nlohmann::json> gst;  // by time (ms)
};

long long milliseconds(double seconds) { return std::llround(seconds * 1000.0); }

Expected gpsd_decode(const std::string& log) {
  Expected expected;
  std::ifstream chk(kLogs + log + ".chk");
  std::string line, sentence;
  while (std::getline(chk, line)) {
    if (line.empty()) continue;
    if (line[0] == '$') {
      sentence = line;
      continue;
    }
    if (line[0] != '{') continue;
    const nlohmann::json object = nlohmann::json::parse(line);
    if (object["class"] == "GST" && object.contains("lat")) expected.gst[milliseconds(unix_seconds(object["time"]))] = object;
    if (object["class"] == "TPV" && object.contains("time") && object.contains("lat") && object.value("mode", 0) >= 2) {
      expected.tpv[milliseconds(unix_seconds(object["time"]))] = object;
    }
  }
  return expected;
}

}  // namespace

TEST(NmeaSentence, ChecksumsAreVerifiedAndBadSentencesNamed) {
  auto gga = parse_nmea_sentence("$GNGGA,132819.60,4134.49795459,N,09345.03431408,W,2,10,0.9,278.161,M,-31.442,M,6.6,0133*6A\r\n");
  ASSERT_TRUE(gga.ok()) << gga.error().message;
  EXPECT_EQ(gga->talker, "GN");
  EXPECT_EQ(gga->type, "GGA");
  ASSERT_EQ(gga->fields.size(), 14u);
  EXPECT_EQ(gga->fields[13], "0133");
  EXPECT_TRUE(gga->checksum_present);
  auto wrong = parse_nmea_sentence("$GNGGA,132819.60,4134.49795459,N,09345.03431408,W,2,10,0.9,278.161,M,-31.442,M,6.6,0133*6B");
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.error().message.find("checksum mismatch (6A computed, 6B written)"), std::string::npos) << wrong.error().message;
  EXPECT_FALSE(parse_nmea_sentence("GNGGA,1*00").ok());
  EXPECT_FALSE(parse_nmea_sentence("$GNGGA,1*G0").ok());
  EXPECT_FALSE(parse_nmea_sentence("$GN").ok());
  auto proprietary = parse_nmea_sentence("$PUBX,00,1*2E");
  ASSERT_TRUE(proprietary.ok()) << proprietary.error().message;
  EXPECT_EQ(proprietary->talker, "PUBX");
}

class GpsdLog : public ::testing::TestWithParam<const char*> {};

TEST_P(GpsdLog, FixesAndCovariancesEqualGpsdsDecode) {
  const std::string log = GetParam();
  const Expected expected = gpsd_decode(log);
  ASSERT_FALSE(expected.tpv.empty());
  auto decoder = NmeaDecoder::create().value();
  const std::vector<msgs::GnssMessage> fixes = decode(read_file(kLogs + log), decoder);
  const NmeaStatistics& statistics = decoder.statistics();
  EXPECT_EQ(statistics.checksum_errors, 0u) << statistics.first_error;
  EXPECT_EQ(statistics.malformed, 0u) << statistics.first_error;
  std::map<long long, const msgs::GnssMessage*> by_time;
  for (std::size_t i = 0; i < fixes.size(); ++i) {
    if (i > 0) {
      EXPECT_GT(fixes[i].timestamp, fixes[i - 1].timestamp);
    }
    by_time[milliseconds(fixes[i].timestamp.seconds())] = &fixes[i];
  }
  std::set<long long> without_geoid;  // GGA times of day (ms) whose geoid separation is empty
  std::istringstream lines(read_file(kLogs + log));
  for (std::string line; std::getline(lines, line);) {
    auto sentence = parse_nmea_sentence(line);
    if (sentence && sentence->type == "GGA" && sentence->fields.size() > 10 && sentence->fields[10].empty() && !sentence->fields[0].empty()) {
      const double hours = std::stod(sentence->fields[0].substr(0, 2)), minutes = std::stod(sentence->fields[0].substr(2, 2));
      without_geoid.insert(milliseconds(hours * 3600.0 + minutes * 60.0 + std::stod(sentence->fields[0].substr(4))));
    }
  }
  std::size_t compared = 0;
  for (const auto& [time, tpv] : expected.tpv) {
    const auto found = by_time.find(time);
    if (found == by_time.end()) continue;  // an RMC's time without a GGA (counted below)
    const msgs::GnssMessage& fix = *found->second;
    EXPECT_NEAR(fix.latitude, tpv["lat"].get<double>(), 1e-9) << tpv["time"];
    EXPECT_NEAR(fix.longitude, tpv["lon"].get<double>(), 1e-9) << tpv["time"];
    // Where the GGA has no geoid separation gpsd adds its own geoid model's; we keep mean sea level.
    if (without_geoid.count(time % 86400000) != 0) {
      EXPECT_NEAR(fix.altitude, tpv["altMSL"].get<double>(), 1e-4) << tpv["time"];
      EXPECT_GT((*fix.position_covariance)(2, 2), 900.0);
    } else if (tpv.contains("altHAE")) {
      EXPECT_NEAR(fix.altitude, tpv["altHAE"].get<double>(), 1e-4) << tpv["time"];
    }
    EXPECT_NE(fix.fix_type, msgs::GnssFixType::kNoFix);
    if (tpv.value("status", 1) == 2) {
      EXPECT_EQ(fix.fix_type, msgs::GnssFixType::kFix3d) << "DGPS";
    }
    ASSERT_TRUE(fix.position_covariance);
    ++compared;
  }
  std::size_t covariances = 0;
  for (const auto& [time, gst] : expected.gst) {
    const auto found = by_time.find(time);
    if (found == by_time.end()) continue;  // a GST of an epoch without a GGA position
    const Eigen::Matrix3d& covariance = *found->second->position_covariance;
    EXPECT_NEAR(std::sqrt(covariance(0, 0)), gst["lon"].get<double>(), 1e-9);
    EXPECT_NEAR(std::sqrt(covariance(1, 1)), gst["lat"].get<double>(), 1e-9);
    EXPECT_NEAR(std::sqrt(covariance(2, 2)), gst["alt"].get<double>(), 1e-9);
    ++covariances;
  }
  std::printf("%s: %zu fixes (%zu compared with gpsd's, %zu GST covariances), %llu sentences, %llu without a date, %llu without a position\n",
              log.c_str(), fixes.size(), compared, covariances, static_cast<unsigned long long>(statistics.sentences),
              static_cast<unsigned long long>(statistics.no_date), static_cast<unsigned long long>(statistics.no_position));
  EXPECT_EQ(covariances, expected.gst.size());
  EXPECT_GE(static_cast<double>(compared), 0.9 * static_cast<double>(expected.tpv.size()));
  EXPECT_EQ(statistics.gst, covariances);

  // The same bytes in other pieces: the same fixes.
  auto again = NmeaDecoder::create().value();
  const std::vector<msgs::GnssMessage> split_otherwise = decode(read_file(kLogs + log), again, 99);
  ASSERT_EQ(split_otherwise.size(), fixes.size());
  for (std::size_t i = 0; i < fixes.size(); ++i) EXPECT_EQ(split_otherwise[i].latitude, fixes[i].latitude);
}

INSTANTIATE_TEST_SUITE_P(Receivers, GpsdLog, ::testing::Values("haicom-305N.log", "telit-he910.log", "ublox-neo-m9n-nmea.log", "nmea-rtk.log"),
                         [](const ::testing::TestParamInfo<const char*>& parameter) {
                           std::string name = parameter.param;
                           name.erase(std::remove_if(name.begin(), name.end(), [](char c) { return !std::isalnum(static_cast<unsigned char>(c)); }),
                                      name.end());
                           return name;
                         });

// The u-blox ZED-F9P log interleaves UBX binary messages with its NMEA: every GGA that has a
// date before it (the log's first RMC) becomes a fix, the binary is skipped and counted.
TEST(NmeaDecoder, SkipsBinaryBetweenSentences) {
  auto decoder = NmeaDecoder::create().value();
  const std::string bytes = read_file(kLogs + "ublox-zed-f9p_hpg1.11.log");
  const std::vector<msgs::GnssMessage> fixes = decode(bytes, decoder);
  const NmeaStatistics& statistics = decoder.statistics();
  std::printf("ZED-F9P: %zu fixes, %llu without a date, %llu bytes skipped, %llu malformed (binary), %llu checksum errors\n", fixes.size(),
              static_cast<unsigned long long>(statistics.no_date), static_cast<unsigned long long>(statistics.skipped_bytes),
              static_cast<unsigned long long>(statistics.malformed), static_cast<unsigned long long>(statistics.checksum_errors));
  EXPECT_EQ(fixes.size() + statistics.no_date + statistics.no_position, 655u);  // the log's GGA sentences
  EXPECT_GT(fixes.size(), 600u);
  EXPECT_GT(statistics.skipped_bytes, 100000u);
  EXPECT_EQ(statistics.malformed, 0u) << statistics.first_error;  // every $ inside the binary recognized as such
  EXPECT_EQ(statistics.checksum_errors, 0u);
  for (const msgs::GnssMessage& fix : fixes) {
    EXPECT_NEAR(fix.latitude, -45.87, 0.1);  // Dunedin
    EXPECT_NEAR(fix.longitude, 170.5, 0.1);
  }
}

// Corrupted sentences (a flipped character, a cut-off line, a line of noise) are counted and
// skipped; the rest decodes as before; a date from the configuration serves GGA-only streams.
TEST(NmeaDecoder, CountsCorruptedSentencesAndUsesAConfiguredDate) {
  const std::string good = read_file(kLogs + "nmea-rtk.log");
  auto clean = NmeaDecoder::create().value();
  const std::vector<msgs::GnssMessage> reference = decode(good, clean);
  std::string corrupted = good;
  const std::size_t gga = corrupted.find("$GNGGA", corrupted.find("$GNGGA", corrupted.find("$GNGGA") + 1) + 1);  // the third
  corrupted[gga + 20] = corrupted[gga + 20] == '1' ? '2' : '1';  // a digit of its latitude
  const std::size_t next = corrupted.find("$GNGGA", gga + 1);
  corrupted.insert(next, "$GNGGA,1328\r\n\x01\x02\xff garbage \r\n");
  auto decoder = NmeaDecoder::create().value();
  const std::vector<msgs::GnssMessage> fixes = decode(corrupted, decoder);
  EXPECT_EQ(decoder.statistics().checksum_errors, 1u);
  EXPECT_EQ(decoder.statistics().malformed, 1u);  // the cut-off GGA
  EXPECT_EQ(decoder.statistics().skipped_bytes, clean.statistics().skipped_bytes + 15);  // the noise line and the cut GGA's LF
  EXPECT_NE(decoder.statistics().first_error.find("checksum mismatch"), std::string::npos);
  EXPECT_EQ(fixes.size() + 1, reference.size());

  // Only GGA (no RMC, no ZDA): left out without a date, timed with the configured one.
  std::string gga_only;
  std::istringstream lines(good);
  for (std::string line; std::getline(lines, line);) {
    if (line.size() > 6 && line[0] == '$' && line.compare(3, 3, "GGA") == 0) gga_only += line + "\n";
  }
  auto undated = NmeaDecoder::create().value();
  EXPECT_TRUE(decode(gga_only, undated).empty());
  EXPECT_EQ(undated.statistics().no_date, 122u);
  NmeaDecoderConfig config;
  config.date = "2020-03-18";
  auto dated = NmeaDecoder::create(config).value();
  const std::vector<msgs::GnssMessage> timed = decode(gga_only, dated);
  ASSERT_EQ(timed.size(), 122u);  // the first GGA too, which came before the log's first RMC
  EXPECT_EQ(clean.statistics().no_date, 1u);
  ASSERT_EQ(reference.size(), 121u);
  EXPECT_EQ(timed[1].timestamp, reference.front().timestamp);
  config.date = "2020-13-01";
  EXPECT_FALSE(NmeaDecoder::create(config).ok());
}

}  // namespace hanzo::fusion::drivers
