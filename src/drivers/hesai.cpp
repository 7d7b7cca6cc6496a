#include "hanzo/fusion/drivers/hesai.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <numeric>
#include <sstream>

#include <Eigen/Core>
#include <fmt/format.h>

#include "byte_order.hpp"
#include "civil_time.hpp"

namespace hanzo::fusion::drivers {

namespace {

constexpr std::size_t kPacketBytes = 1262;
constexpr std::size_t kPacketWithSequenceBytes = 1266;
constexpr int kBlocks = 10;
constexpr std::size_t kBlockBytes = 124;
constexpr std::size_t kTail = kBlocks * kBlockBytes;  // 1240
constexpr double kDistanceResolution = 0.004;         // m per raw unit
constexpr double kDegrees = M_PI / 180.0;
constexpr double kBlockPeriod = 55.56e-6;    // s between blocks' firings
constexpr double kLastBlockOffset = 28.58e-6;  // s from the last block's firing to the packet's time
constexpr uint8_t kDualReturn = 0x39;

// Rows "channel,value[,value]" after a header line; fails naming the file and line.
Result<std::vector<std::vector<double>>> read_rows(const std::string& path, std::size_t columns) {
  std::ifstream file(path);
  if (!file) return Error(fmt::format("{}: cannot open file", path));
  std::vector<std::vector<double>> rows;
  std::string line;
  for (int number = 1; std::getline(file, line); ++number) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    std::vector<double> row;
    std::stringstream fields(line);
    std::string field;
    bool numeric = true;
    while (std::getline(fields, field, ',')) {
      char* end = nullptr;
      const double value = std::strtod(field.c_str(), &end);
      if (field.empty() || end != field.c_str() + field.size() || !std::isfinite(value)) numeric = false;
      row.push_back(value);
    }
    if (!numeric && number == 1) continue;  // the header
    if (!numeric || row.size() != columns) {
      return Error(fmt::format("{}:{}: expected {} numbers separated by commas, got \"{}\"", path, number, columns, line));
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

}  // namespace

Result<HesaiCalibration> load_hesai_calibration(const std::string& angle_file, const std::string& firetime_file) {
  HesaiCalibration calibration;
  calibration.channels.resize(kHesaiPandar40Channels);
  std::vector<bool> seen(kHesaiPandar40Channels, false);
  std::vector<std::vector<double>> angles;
  HANZO_ASSIGN_OR_RETURN(angles, read_rows(angle_file, 3));
  for (const std::vector<double>& row : angles) {
    const int channel = static_cast<int>(row[0]);
    if (channel != row[0] || channel < 1 || channel > kHesaiPandar40Channels) {
      return Error(fmt::format("{}: channel {} outside 1-{}", angle_file, row[0], kHesaiPandar40Channels));
    }
    calibration.channels[channel - 1].elevation = row[1] * kDegrees;
    calibration.channels[channel - 1].azimuth_offset = row[2] * kDegrees;
    seen[channel - 1] = true;
  }
  if (const auto missing = std::find(seen.begin(), seen.end(), false); missing != seen.end()) {
    return Error(fmt::format("{}: channel {} missing (the Pandar40P has {})", angle_file, missing - seen.begin() + 1, kHesaiPandar40Channels));
  }
  if (firetime_file.empty()) return calibration;
  std::vector<std::vector<double>> firetimes;
  HANZO_ASSIGN_OR_RETURN(firetimes, read_rows(firetime_file, 2));
  std::fill(seen.begin(), seen.end(), false);
  for (const std::vector<double>& row : firetimes) {
    const int channel = static_cast<int>(row[0]);
    if (channel != row[0] || channel < 1 || channel > kHesaiPandar40Channels) {
      return Error(fmt::format("{}: channel {} outside 1-{}", firetime_file, row[0], kHesaiPandar40Channels));
    }
    if (std::abs(row[1]) > 1000.0) return Error(fmt::format("{}: channel {} fires {} us from its block (more than 1 ms)", firetime_file, channel, row[1]));
    calibration.channels[channel - 1].firetime = row[1] * 1e-6;
    seen[channel - 1] = true;
  }
  if (const auto missing = std::find(seen.begin(), seen.end(), false); missing != seen.end()) {
    return Error(fmt::format("{}: channel {} missing (the Pandar40P has {})", firetime_file, missing - seen.begin() + 1, kHesaiPandar40Channels));
  }
  return calibration;
}

HesaiDecoder::HesaiDecoder(HesaiCalibration calibration, HesaiDecoderConfig config)
    : calibration_(std::move(calibration)), config_(std::move(config)), rotation_(config_.frame_id, config_.cut_angle_deg) {
  for (const HesaiChannel& channel : calibration_.channels) {
    trig_.push_back({std::cos(channel.elevation), std::sin(channel.elevation), std::cos(channel.azimuth_offset), std::sin(channel.azimuth_offset)});
  }
  std::vector<int> order(calibration_.channels.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return calibration_.channels[static_cast<std::size_t>(a)].elevation < calibration_.channels[static_cast<std::size_t>(b)].elevation;
  });
  ring_.resize(order.size());
  for (std::size_t rank = 0; rank < order.size(); ++rank) ring_[static_cast<std::size_t>(order[rank])] = static_cast<uint32_t>(rank);
}

Result<HesaiDecoder> HesaiDecoder::create(HesaiCalibration calibration, HesaiDecoderConfig config) {
  if (calibration.channels.size() != static_cast<std::size_t>(kHesaiPandar40Channels)) {
    return Error(fmt::format("Hesai calibration has {} channels, the Pandar40P {}", calibration.channels.size(), kHesaiPandar40Channels), "calibration");
  }
  if (!(config.max_clock_offset_s > 0)) return Error("Hesai decoder: max_clock_offset_s must be positive", "max_clock_offset_s");
  return HesaiDecoder(std::move(calibration), std::move(config));
}

void HesaiDecoder::malformed(const std::string& what) {
  ++statistics_.malformed;
  if (statistics_.first_error.empty()) statistics_.first_error = what;
}

void HesaiDecoder::count(std::size_t emitted_points) {
  if (emitted_points == 0) return;
  ++statistics_.frames;
  statistics_.points += emitted_points;
}

void HesaiDecoder::add_packet(std::string_view payload, Timestamp capture_time, std::vector<msgs::PointCloudMessage>& frames) {
  if (payload.size() != kPacketBytes && payload.size() != kPacketWithSequenceBytes) {
    return malformed(fmt::format("Hesai packet of {} bytes (Pandar40P packets have {} or {})", payload.size(), kPacketBytes, kPacketWithSequenceBytes));
  }
  int azimuths[kBlocks];  // 0.01 degree
  for (int block = 0; block < kBlocks; ++block) {
    const std::size_t at = static_cast<std::size_t>(block) * kBlockBytes;
    if (little16(payload, at) != 0xEEFF) return malformed(fmt::format("Hesai block {} has flag {:04X} (expected FFEE)", block, little16(payload, at)));
    const uint16_t raw_azimuth = little16(payload, at + 2);
    if (raw_azimuth > 36000) return malformed(fmt::format("Hesai block {} has azimuth {} (0.01 degree units, at most 36000)", block, raw_azimuth));
    azimuths[block] = raw_azimuth % 36000;
  }
  // The packet's time: its UTC second plus microseconds, or its arrival (time_source).
  const auto byte = [&](std::size_t at) { return static_cast<uint8_t>(payload[at]); };
  const uint32_t microseconds = little32(payload, kTail + 10);
  const int year = 2000 + byte(kTail + 16), month = byte(kTail + 17), day = byte(kTail + 18);
  const int hour = byte(kTail + 19), minute = byte(kTail + 20), second = byte(kTail + 21);
  std::optional<Timestamp> sensor_time;
  if (valid_date(year, month, day) && hour < 24 && minute < 60 && second <= 60 && microseconds < 1'000'000) {
    const int64_t seconds = days_from_civil(year, month, day) * 86400 + hour * 3600 + minute * 60 + second;
    sensor_time = Timestamp::from_nanoseconds(seconds * 1'000'000'000 + int64_t{microseconds} * 1000);
  }
  const bool use_sensor = config_.time_source == HesaiTimeSource::kPacket ||
                          (config_.time_source == HesaiTimeSource::kAuto && sensor_time &&
                           std::abs((*sensor_time - capture_time).seconds()) <= config_.max_clock_offset_s);
  if (use_sensor && !sensor_time) {
    return malformed(fmt::format("Hesai packet time {:04}-{:02}-{:02} {:02}:{:02}:{:02} + {} us is not a time", year, month, day, hour, minute,
                                 second, microseconds));
  }
  const Timestamp packet_time = use_sensor ? *sensor_time : capture_time;
  if (!use_sensor) ++statistics_.capture_clock_packets;
  const bool dual = byte(kTail + 14) == kDualReturn;
  ++statistics_.packets;

  uint16_t previous_distances[kHesaiPandar40Channels] = {};
  for (int block = 0; block < kBlocks; ++block) {
    count(rotation_.start_block(azimuths[block] / 100.0, frames));
    const int firings_after = dual ? (kBlocks / 2 - 1 - block / 2) : (kBlocks - 1 - block);
    const Timestamp block_time = packet_time - Duration::from_seconds(kLastBlockOffset + kBlockPeriod * firings_after);
    const bool second_return = dual && block % 2 == 1;
    const double block_azimuth = azimuths[block] / 100.0 * kDegrees;
    const double sin_block = std::sin(block_azimuth), cos_block = std::cos(block_azimuth);
    for (int channel = 0; channel < kHesaiPandar40Channels; ++channel) {
      const std::size_t at = static_cast<std::size_t>(block) * kBlockBytes + 4 + static_cast<std::size_t>(channel) * 3;
      const uint16_t raw_distance = little16(payload, at);
      if (second_return && raw_distance == previous_distances[channel]) continue;  // the same echo twice
      previous_distances[channel] = raw_distance;
      if (raw_distance == 0) continue;  // no echo
      const Trig& trig = trig_[static_cast<std::size_t>(channel)];
      const double distance = raw_distance * kDistanceResolution;
      // sin / cos of the block's azimuth plus the channel's offset.
      const double sin_azimuth = sin_block * trig.cos_offset + cos_block * trig.sin_offset;
      const double cos_azimuth = cos_block * trig.cos_offset - sin_block * trig.sin_offset;
      const double horizontal = distance * trig.cos_elevation;
      const double x_sensor = horizontal * sin_azimuth, y_sensor = horizontal * cos_azimuth;
      rotation_.add(Eigen::Vector3f(static_cast<float>(y_sensor), static_cast<float>(-x_sensor), static_cast<float>(distance * trig.sin_elevation)),
                    byte(at + 2), ring_[static_cast<std::size_t>(channel)],
                    block_time + Duration::from_seconds(calibration_.channels[static_cast<std::size_t>(channel)].firetime));
    }
  }
}

void HesaiDecoder::flush(std::vector<msgs::PointCloudMessage>& frames) { count(rotation_.emit(frames)); }

}  // namespace hanzo::fusion::drivers
