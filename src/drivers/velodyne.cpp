#include "hanzo/fusion/drivers/velodyne.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numeric>
#include <sstream>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "byte_order.hpp"

namespace hanzo::fusion::drivers {

namespace {

constexpr std::size_t kDataPacketBytes = 1206;
constexpr std::size_t kPositionPacketBytes = 512;
constexpr int kBlocks = 12;
constexpr int kBlockBytes = 100;
constexpr int kChannels = 32;
constexpr double kDegrees = M_PI / 180.0;

// The text between <tag> and </tag> from `from` on, and where it ends; none when absent.
std::optional<std::pair<std::string, std::size_t>> element(const std::string& text, const std::string& tag, std::size_t from) {
  const std::string open = "<" + tag, close = "</" + tag + ">";
  std::size_t start = text.find(open, from);
  while (start != std::string::npos && text[start + open.size()] != '>' && text[start + open.size()] != ' ') start = text.find(open, start + 1);
  if (start == std::string::npos) return std::nullopt;
  const std::size_t body = text.find('>', start) + 1;
  const std::size_t end = text.find(close, body);
  if (end == std::string::npos) return std::nullopt;
  return std::make_pair(text.substr(body, end - body), end + close.size());
}

std::vector<std::string> items(const std::string& text) {
  std::vector<std::string> values;
  for (std::size_t at = 0;;) {
    const auto item = element(text, "item", at);
    if (!item) break;
    values.push_back(item->first);
    at = item->second;
  }
  return values;
}

Result<VelodyneCalibration> load_xml(const std::string& path, const std::string& text) {
  VelodyneCalibration calibration;
  if (const auto lsb = element(text, "distLSB_", 0)) calibration.distance_resolution = std::stod(lsb->first) / 100.0;  // cm
  const auto enabled = element(text, "enabled_", 0);
  const auto points = element(text, "points_", 0);
  if (!enabled || !points) return Error(fmt::format("{}: no enabled_ / points_ lists (not a Velodyne db.xml)", path));
  int count = 0;
  for (const std::string& value : items(enabled->first)) count += value == "1" ? 1 : 0;
  std::vector<std::optional<VelodyneLaser>> lasers(static_cast<std::size_t>(count));
  for (std::size_t at = 0;;) {
    const auto px = element(points->first, "px", at);
    if (!px) break;
    at = px->second;
    const auto field = [&](const char* name) {
      const auto value = element(px->first, name, 0);
      return value ? std::stod(value->first) : 0.0;
    };
    const int id = static_cast<int>(field("id_"));
    if (id < 0 || id >= count) continue;
    VelodyneLaser laser;
    laser.vertical_angle = field("vertCorrection_") * kDegrees;
    laser.rotational_correction = field("rotCorrection_") * kDegrees;
    laser.distance_correction = field("distCorrection_") / 100.0;
    laser.vertical_offset = field("vertOffsetCorrection_") / 100.0;
    laser.horizontal_offset = field("horizOffsetCorrection_") / 100.0;
    laser.two_point_correction = count == 64 && element(px->first, "distCorrectionX_", 0) && element(px->first, "distCorrectionY_", 0);
    laser.distance_correction_x = field("distCorrectionX_") / 100.0;
    laser.distance_correction_y = field("distCorrectionY_") / 100.0;
    lasers[static_cast<std::size_t>(id)] = laser;
  }
  for (std::size_t id = 0; id < lasers.size(); ++id) {
    if (!lasers[id]) return Error(fmt::format("{}: no px entry for enabled laser {}", path, id));
    calibration.lasers.push_back(*lasers[id]);
  }
  return calibration;
}

Result<VelodyneCalibration> load_yaml(const std::string& path, const std::string& text) {
  VelodyneCalibration calibration;
  try {
    const YAML::Node root = YAML::Load(text);
    if (!root["lasers"] || !root["lasers"].IsSequence()) return Error(fmt::format("{}: no 'lasers' list (not a Velodyne calibration)", path));
    if (root["distance_resolution"]) calibration.distance_resolution = root["distance_resolution"].as<double>();
    const int count = root["num_lasers"] ? root["num_lasers"].as<int>() : static_cast<int>(root["lasers"].size());
    std::vector<std::optional<VelodyneLaser>> lasers(static_cast<std::size_t>(std::max(count, 0)));
    for (const YAML::Node& entry : root["lasers"]) {
      const int id = entry["laser_id"].as<int>();
      if (id < 0 || id >= count) return Error(fmt::format("{}: laser_id {} outside 0..{}", path, id, count - 1));
      const auto value = [&](const char* name) { return entry[name] ? entry[name].as<double>() : 0.0; };
      lasers[static_cast<std::size_t>(id)] =
          VelodyneLaser{value("vert_correction"),        value("rot_correction"),
                        value("dist_correction"),        value("vert_offset_correction"),
                        value("horiz_offset_correction"), entry["two_pt_correction_available"] && entry["two_pt_correction_available"].as<bool>(),
                        value("dist_correction_x"),      value("dist_correction_y")};
    }
    for (std::size_t id = 0; id < lasers.size(); ++id) {
      if (!lasers[id]) return Error(fmt::format("{}: no entry for laser {}", path, id));
      calibration.lasers.push_back(*lasers[id]);
    }
  } catch (const YAML::Exception& error) {
    return Error(fmt::format("{}: {}", path, error.what()));
  }
  return calibration;
}

// sin and cos of every azimuth the packets can hold (0.01 degree steps), made once.
struct AzimuthTable {
  std::vector<double> sin, cos;
  AzimuthTable() : sin(36000), cos(36000) {
    for (std::size_t hundredths = 0; hundredths < 36000; ++hundredths) {
      sin[hundredths] = std::sin(static_cast<double>(hundredths) / 100.0 * kDegrees);
      cos[hundredths] = std::cos(static_cast<double>(hundredths) / 100.0 * kDegrees);
    }
  }
};
const AzimuthTable& azimuth_table() {
  static const AzimuthTable table;
  return table;
}

}  // namespace

Result<VelodyneModel> parse_velodyne_model(const std::string& name) {
  std::string key;
  for (const char c : name) {
    if (std::isalnum(static_cast<unsigned char>(c))) key.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(c))));
  }
  if (key == "VLP16") return VelodyneModel::kVlp16;
  if (key == "VLP32C") return VelodyneModel::kVlp32c;
  if (key == "HDL32E" || key == "HDL32") return VelodyneModel::kHdl32e;
  if (key == "HDL64E" || key == "HDL64") return VelodyneModel::kHdl64e;
  if (key == "VLS128") return VelodyneModel::kVls128;
  return Error(fmt::format("unknown Velodyne model '{}' (VLP-16, VLP-32C, HDL-32E, HDL-64E, VLS-128)", name), "model");
}

int laser_count(VelodyneModel model) {
  switch (model) {
    case VelodyneModel::kVlp16: return 16;
    case VelodyneModel::kVlp32c:
    case VelodyneModel::kHdl32e: return 32;
    case VelodyneModel::kHdl64e: return 64;
    case VelodyneModel::kVls128: return 128;
  }
  return 0;
}

Result<VelodyneCalibration> load_velodyne_calibration(const std::string& path) {
  std::ifstream file(path);
  if (!file) return Error(fmt::format("{}: cannot open file", path));
  std::ostringstream text;
  text << file.rdbuf();
  const std::string content = text.str();
  Result<VelodyneCalibration> calibration =
      content.find("<boost_serialization") != std::string::npos || content.rfind("<?xml", 0) == 0 ? load_xml(path, content) : load_yaml(path, content);
  if (calibration && calibration->lasers.empty()) return Error(fmt::format("{}: no lasers", path));
  if (calibration && !(calibration->distance_resolution > 0.0)) return Error(fmt::format("{}: distance resolution must be positive", path));
  return calibration;
}

VelodyneCalibration nominal_velodyne_calibration(VelodyneModel model) {
  VelodyneCalibration calibration;
  const auto add = [&](double degrees) { calibration.lasers.push_back({.vertical_angle = degrees * kDegrees}); };
  switch (model) {
    case VelodyneModel::kVlp16:
      for (int laser = 0; laser < 16; ++laser) add(laser % 2 == 0 ? -15.0 + laser : laser - 0.0);  // -15, 1, -13, 3, ...
      break;
    case VelodyneModel::kHdl32e:
      for (int laser = 0; laser < 32; ++laser) add((laser % 2 == 0 ? -92.0 + 2.0 * laser : -28.0 + 2.0 * (laser - 1)) / 3.0);  // 4/3 degree steps
      break;
    default: {  // evenly spread over the model's field of view (a nominal layout: give the unit's calibration file)
      const int count = laser_count(model);
      const double low = model == VelodyneModel::kHdl64e ? -24.9 : -25.0, high = model == VelodyneModel::kHdl64e ? 2.0 : 15.0;
      for (int laser = 0; laser < count; ++laser) add(low + (high - low) * laser / (count - 1));
    }
  }
  return calibration;
}

VelodyneDecoder::VelodyneDecoder(VelodyneCalibration calibration, VelodyneDecoderConfig config)
    : calibration_(std::move(calibration)), config_(std::move(config)), rotation_(config_.frame_id, config_.cut_angle_deg) {
  for (const VelodyneLaser& laser : calibration_.lasers) {
    trig_.push_back({std::cos(laser.vertical_angle), std::sin(laser.vertical_angle), std::cos(laser.rotational_correction),
                     std::sin(laser.rotational_correction)});
  }

  // Rings by elevation: 0 the lowest laser.
  std::vector<int> order(calibration_.lasers.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return calibration_.lasers[static_cast<std::size_t>(a)].vertical_angle < calibration_.lasers[static_cast<std::size_t>(b)].vertical_angle;
  });
  ring_.resize(order.size());
  for (std::size_t rank = 0; rank < order.size(); ++rank) ring_[static_cast<std::size_t>(order[rank])] = static_cast<uint32_t>(rank);
}

Result<VelodyneDecoder> VelodyneDecoder::create(VelodyneCalibration calibration, VelodyneDecoderConfig config) {
  const int expected = laser_count(config.model);
  if (static_cast<int>(calibration.lasers.size()) != expected) {
    return Error(fmt::format("Velodyne calibration has {} lasers, the model {}", calibration.lasers.size(), expected), "calibration");
  }
  if (!(calibration.distance_resolution > 0.0)) return Error("Velodyne calibration: distance resolution must be positive", "calibration");
  return VelodyneDecoder(std::move(calibration), std::move(config));
}

void VelodyneDecoder::malformed(const std::string& what) {
  ++statistics_.malformed;
  if (statistics_.first_error.empty()) statistics_.first_error = what;
}

double VelodyneDecoder::firing_offset(int block, int channel) const {
  switch (config_.model) {
    case VelodyneModel::kVlp16: return 1e-6 * (block * 110.592 + (channel / 16) * 55.296 + (channel % 16) * 2.304);
    case VelodyneModel::kHdl32e: return 1e-6 * (block * 46.08 + channel * 1.152);
    case VelodyneModel::kVlp32c: return 1e-6 * (block * 55.296 + (channel / 2) * 2.304);
    case VelodyneModel::kHdl64e: return 1e-6 * ((block / 2) * 48.0);  // per firing: lasers of a block fire together
    case VelodyneModel::kVls128: return 1e-6 * ((block / 4) * 53.3);
  }
  return 0.0;
}

void VelodyneDecoder::add_return(int laser, double azimuth_deg, uint16_t raw_distance, uint8_t intensity, Timestamp time) {
  if (raw_distance == 0) return;  // no echo
  const VelodyneLaser& calibration = calibration_.lasers[static_cast<std::size_t>(laser)];
  const Trig& trig = trig_[static_cast<std::size_t>(laser)];
  const double distance = raw_distance * calibration_.distance_resolution + calibration.distance_correction;
  const double xy = distance * trig.cos_vertical - calibration.vertical_offset * trig.sin_vertical;
  // sin / cos of (azimuth - rotational correction) from the 0.01-degree tables and the laser's.
  const auto index = static_cast<std::size_t>(std::lround(azimuth_deg * 100.0)) % 36000;
  const AzimuthTable& table = azimuth_table();
  const double sin_angle = table.sin[index] * trig.cos_rotation - table.cos[index] * trig.sin_rotation;
  const double cos_angle = table.cos[index] * trig.cos_rotation + table.sin[index] * trig.sin_rotation;
  double x_sensor = xy * sin_angle - calibration.horizontal_offset * cos_angle;
  double y_sensor = xy * cos_angle + calibration.horizontal_offset * sin_angle;
  double z = distance * trig.sin_vertical + calibration.vertical_offset * trig.cos_vertical;
  if (calibration.two_point_correction) {
    // The correction interpolated between the 2.4 m (x) / 1.93 m (y) and 25.04 m calibration points.
    const double raw = raw_distance * calibration_.distance_resolution;
    const double distance_x = raw + (calibration.distance_correction - calibration.distance_correction_x) * (std::abs(x_sensor) - 2.4) / (25.04 - 2.4) +
                              calibration.distance_correction_x;
    const double distance_y = raw + (calibration.distance_correction - calibration.distance_correction_y) * (std::abs(y_sensor) - 1.93) / (25.04 - 1.93) +
                              calibration.distance_correction_y;
    x_sensor = (distance_x * trig.cos_vertical - calibration.vertical_offset * trig.sin_vertical) * sin_angle - calibration.horizontal_offset * cos_angle;
    y_sensor = (distance_y * trig.cos_vertical - calibration.vertical_offset * trig.sin_vertical) * cos_angle + calibration.horizontal_offset * sin_angle;
    z = distance_y * trig.sin_vertical + calibration.vertical_offset * trig.cos_vertical;
  }
  rotation_.add(Eigen::Vector3f(static_cast<float>(y_sensor), static_cast<float>(-x_sensor), static_cast<float>(z)), intensity,
                ring_[static_cast<std::size_t>(laser)], time);
}

void VelodyneDecoder::emit(std::vector<msgs::PointCloudMessage>& frames) { count(rotation_.emit(frames)); }

void VelodyneDecoder::count(std::size_t emitted_points) {
  if (emitted_points == 0) return;
  ++statistics_.frames;
  statistics_.points += emitted_points;
}

void VelodyneDecoder::add_packet(std::string_view payload, Timestamp capture_time, std::vector<msgs::PointCloudMessage>& frames) {
  if (payload.size() == kPositionPacketBytes) {
    ++statistics_.position_packets;
    return;
  }
  if (payload.size() != kDataPacketBytes) return malformed(fmt::format("Velodyne packet of {} bytes (data packets have {})", payload.size(), kDataPacketBytes));
  // The packet's time: microseconds past the hour, in the capture time's hour (or the one before
  // or after, whichever is nearest).
  const uint32_t past_hour_us = little32(payload, 1200);
  Timestamp packet_time = capture_time;
  if (past_hour_us < 3'600'000'000u) {
    const int64_t hour_ns = 3'600'000'000'000LL;
    const int64_t hour = capture_time.nanoseconds() / hour_ns * hour_ns;
    int64_t best = hour + static_cast<int64_t>(past_hour_us) * 1000;
    for (const int64_t candidate : {best - hour_ns, best + hour_ns}) {
      if (std::llabs(candidate - capture_time.nanoseconds()) < std::llabs(best - capture_time.nanoseconds())) best = candidate;
    }
    packet_time = Timestamp::from_nanoseconds(best);
  }
  const bool dual = static_cast<uint8_t>(payload[1204]) == 0x39;
  // Blocks of one firing share their azimuth: a dual-return pair, the HDL-64E's upper and lower
  // blocks, the VLS-128's four.
  const int firing_blocks = config_.model == VelodyneModel::kVls128 ? 4 : (config_.model == VelodyneModel::kHdl64e || dual) ? 2 : 1;
  int azimuths[kBlocks];  // 0.01 degree
  int bases[kBlocks];
  for (int block = 0; block < kBlocks; ++block) {
    const uint16_t flag = little16(payload, static_cast<std::size_t>(block * kBlockBytes));
    switch (flag) {
      case 0xEEFF: bases[block] = 0; break;
      case 0xDDFF: bases[block] = 32; break;
      case 0xCCFF: bases[block] = 64; break;
      case 0xBBFF: bases[block] = 96; break;
      default: return malformed(fmt::format("Velodyne block {} has flag {:04X} (expected EEFF, DDFF, CCFF or BBFF)", block, flag));
    }
    const uint16_t raw_azimuth = little16(payload, static_cast<std::size_t>(block * kBlockBytes + 2));
    // 36000 (some firmware writes it for 0) is 0.
    if (raw_azimuth > 36000) return malformed(fmt::format("Velodyne block {} has azimuth {} (0.01 degree units, at most 36000)", block, raw_azimuth));
    azimuths[block] = raw_azimuth % 36000;
  }
  const int lasers = static_cast<int>(calibration_.lasers.size());
  if (config_.model != VelodyneModel::kVlp16 && *std::max_element(bases, bases + kBlocks) + kChannels > lasers) {
    return malformed(fmt::format("Velodyne blocks address lasers beyond the calibration's {}", lasers));
  }
  ++statistics_.packets;
  uint16_t previous_distances[kChannels] = {};
  for (int block = 0; block < kBlocks; ++block) {
    // The azimuth advance to the next firing (the last firing: the one before it).
    const int next = block + firing_blocks < kBlocks ? block + firing_blocks : block - firing_blocks;
    int gap = block + firing_blocks < kBlocks ? azimuths[next] - azimuths[block] : azimuths[block] - azimuths[next];
    if (gap < 0) gap += 36000;
    if (gap > 500) gap = 0;  // a jump of more than 5 degrees (corrupt data): no interpolation
    count(rotation_.start_block(azimuths[block] / 100.0, frames));
    const bool second_return = dual && block % 2 == 1;
    for (int channel = 0; channel < kChannels; ++channel) {
      const std::size_t at = static_cast<std::size_t>(block * kBlockBytes + 4 + channel * 3);
      const uint16_t distance = little16(payload, at);
      const auto intensity = static_cast<uint8_t>(payload[at + 2]);
      if (second_return && distance == previous_distances[channel]) continue;  // the same echo twice
      previous_distances[channel] = distance;
      const int laser = config_.model == VelodyneModel::kVlp16 ? channel % 16 : bases[block] + channel;
      // The share of the firing's duration before this laser fires, in exact fractions of the
      // firing slots, the advance rounded half to even (as VeloView's decodes are).
      int numerator = 0, denominator = 1;
      if (config_.per_laser_azimuth || (config_.model == VelodyneModel::kVlp16 && channel >= 16)) {
        switch (config_.model) {
          case VelodyneModel::kVlp16:
            numerator = config_.per_laser_azimuth ? (channel % 16) + 24 * (channel / 16) : 24;
            denominator = 48;  // 2.304 us slots of a 110.592 us block
            break;
          case VelodyneModel::kHdl32e: numerator = channel; denominator = 40; break;  // 1.152 of 46.08 us
          case VelodyneModel::kVlp32c: numerator = channel / 2; denominator = 24; break;  // 2.304 of 55.296 us
          default: numerator = 0; denominator = 1; break;  // HDL-64E, VLS-128: the block's azimuth
        }
      }
      const long product = static_cast<long>(gap) * numerator;
      long advance = product / denominator;
      const long remainder = 2 * (product % denominator);
      if (remainder > denominator || (remainder == denominator && advance % 2 == 1)) ++advance;
      const long azimuth = azimuths[block] + advance;
      add_return(laser, static_cast<double>(azimuth % 36000) / 100.0, distance, intensity, packet_time + Duration::from_seconds(firing_offset(block, channel)));
    }
  }
}

void VelodyneDecoder::flush(std::vector<msgs::PointCloudMessage>& frames) { emit(frames); }

}  // namespace hanzo::fusion::drivers
