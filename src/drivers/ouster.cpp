#include "hanzo/fusion/drivers/ouster.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numeric>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

namespace hanzo::fusion::drivers {

namespace {

constexpr std::size_t kLegacyImuBytes = 48;
constexpr std::size_t kProfileHeaderBytes = 32, kProfileFooterBytes = 32;
constexpr std::size_t kNmeaBlockBytes = 100, kImuSampleBytes = 36;
constexpr std::size_t kZonePacketBytes = kProfileHeaderBytes + 8 + 32 + 36 * 16 + kProfileFooterBytes;
constexpr int64_t kDayNs = 86'400'000'000'000LL;
constexpr double kGravity = 9.80665;

template <typename T>
T read_le(const uint8_t* data) {
  T value;
  std::memcpy(&value, data, sizeof(T));
  return value;
}

Eigen::Matrix4d matrix_of(const nlohmann::json& values) {
  Eigen::Matrix4d matrix = Eigen::Matrix4d::Identity();
  if (!values.is_array() || values.size() != 16) return matrix;
  for (int k = 0; k < 16; ++k) matrix(k / 4, k % 4) = values[static_cast<std::size_t>(k)].get<double>();
  return matrix;
}

// The first of `paths` (each a list of keys) that the document holds.
const nlohmann::json* find(const nlohmann::json& root, std::initializer_list<std::initializer_list<const char*>> paths) {
  for (const auto& path : paths) {
    const nlohmann::json* node = &root;
    for (const char* key : path) {
      if (!node->is_object() || !node->contains(key)) {
        node = nullptr;
        break;
      }
      node = &(*node)[key];
    }
    if (node != nullptr) return node;
  }
  return nullptr;
}

uint32_t bits(const uint8_t* pixel, int first_bit, int count) {
  uint64_t word = 0;
  std::memcpy(&word, pixel + first_bit / 8, std::min<std::size_t>(8, static_cast<std::size_t>((first_bit % 8 + count + 7) / 8)));
  return static_cast<uint32_t>((word >> (first_bit % 8)) & ((uint64_t{1} << count) - 1));
}

}  // namespace

Result<OusterMetadata> parse_ouster_metadata(const std::string& json_text) {
  nlohmann::json root;
  try {
    root = nlohmann::json::parse(json_text);
  } catch (const nlohmann::json::exception& error) {
    return Error(fmt::format("Ouster metadata: not JSON ({})", error.what()));
  }
  OusterMetadata metadata;
  try {
    const nlohmann::json* altitudes = find(root, {{"beam_altitude_angles"}, {"beam_intrinsics", "beam_altitude_angles"}});
    const nlohmann::json* azimuths = find(root, {{"beam_azimuth_angles"}, {"beam_intrinsics", "beam_azimuth_angles"}});
    if (altitudes == nullptr || azimuths == nullptr) return Error("Ouster metadata: no beam_altitude_angles / beam_azimuth_angles", "beam_altitude_angles");
    metadata.beam_altitude_deg = altitudes->get<std::vector<double>>();
    metadata.beam_azimuth_deg = azimuths->get<std::vector<double>>();
    if (const nlohmann::json* mode = find(root, {{"lidar_mode"}, {"config_params", "lidar_mode"}})) metadata.lidar_mode = mode->get<std::string>();
    if (const nlohmann::json* product = find(root, {{"prod_line"}, {"sensor_info", "prod_line"}})) metadata.product = product->get<std::string>();
    if (const nlohmann::json* offset = find(root, {{"lidar_origin_to_beam_origin_mm"}, {"beam_intrinsics", "lidar_origin_to_beam_origin_mm"}})) {
      metadata.lidar_origin_to_beam_origin_mm = offset->get<double>();
    }
    // The OS-1's defaults where the file has no transform (the reduced legacy metadata).
    metadata.lidar_to_sensor << -1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 36.18, 0, 0, 0, 1;
    if (const nlohmann::json* transform = find(root, {{"lidar_to_sensor_transform"}, {"lidar_intrinsics", "lidar_to_sensor_transform"}})) {
      metadata.lidar_to_sensor = matrix_of(*transform);
    }
    metadata.imu_to_sensor << 1, 0, 0, 6.253, 0, 1, 0, -11.775, 0, 0, 1, 7.645, 0, 0, 0, 1;
    if (const nlohmann::json* transform = find(root, {{"imu_to_sensor_transform"}, {"imu_intrinsics", "imu_to_sensor_transform"}})) {
      metadata.imu_to_sensor = matrix_of(*transform);
    }
    const nlohmann::json* format = find(root, {{"data_format"}, {"lidar_data_format"}});
    metadata.pixels_per_column = static_cast<int>(metadata.beam_altitude_deg.size());
    if (format != nullptr) {
      metadata.pixels_per_column = format->value("pixels_per_column", metadata.pixels_per_column);
      metadata.columns_per_frame = format->value("columns_per_frame", 0);
      metadata.columns_per_packet = format->value("columns_per_packet", 16);
      if (format->contains("column_window")) metadata.column_window = (*format)["column_window"].get<std::array<int, 2>>();
      metadata.udp_profile_lidar = format->value("udp_profile_lidar", std::string("LEGACY"));
    }
    if (const nlohmann::json* profile = find(root, {{"config_params", "udp_profile_lidar"}}); profile != nullptr && format == nullptr) {
      metadata.udp_profile_lidar = profile->get<std::string>();
    }
    if (const nlohmann::json* profile = find(root, {{"lidar_data_format", "udp_profile_imu"}, {"config_params", "udp_profile_imu"}, {"data_format", "udp_profile_imu"}})) {
      metadata.udp_profile_imu = profile->get<std::string>();
    }
    if (const nlohmann::json* samples = find(root, {{"imu_data_format", "imu_measurements_per_packet"}})) {
      metadata.imu_measurements_per_packet = samples->get<int>();
    }
    if (metadata.columns_per_frame == 0) {  // from the mode: "1024x10" is 1024 columns
      int columns = 0, rate = 0;
      if (std::sscanf(metadata.lidar_mode.c_str(), "%dx%d", &columns, &rate) != 2 || columns <= 0) {
        return Error("Ouster metadata: neither data_format.columns_per_frame nor a lidar_mode like 1024x10", "lidar_mode");
      }
      metadata.columns_per_frame = columns;
    }
    if (format == nullptr || !format->contains("column_window")) metadata.column_window = {0, metadata.columns_per_frame - 1};
  } catch (const nlohmann::json::exception& error) {
    return Error(fmt::format("Ouster metadata: {}", error.what()));
  }
  return metadata;
}

Result<OusterMetadata> load_ouster_metadata(const std::string& path) {
  std::ifstream file(path);
  if (!file) return Error(fmt::format("{}: cannot open file", path));
  std::ostringstream text;
  text << file.rdbuf();
  Result<OusterMetadata> metadata = parse_ouster_metadata(text.str());
  if (!metadata) return Error(fmt::format("{}: {}", path, metadata.error().message));
  return metadata;
}

// The pixel layouts of the lidar profiles (ouster-sdk's field tables), LEGACY apart.
std::optional<OusterPixelLayout> ouster_pixel_layout(const std::string& profile) {
  using Layout = OusterPixelLayout;
  if (profile == "LEGACY") return Layout{12, 20, 0, 4, 0, 0, 0};
  if (profile == "RNG19_RFL8_SIG16_NIR16" || profile == "RNG19_RFL8_SIG16_NIR16_ZONE16") return Layout{12, 19, 0, 4, 0, 0, 0};
  if (profile == "RNG19_RFL8_SIG16_NIR16_DUAL") return Layout{16, 19, 0, 3, 32, 19, 7};
  if (profile == "FIVE_WORD_PIXEL") return Layout{20, 19, 0, 3, 32, 19, 7};
  if (profile == "RNG15_RFL8_NIR8") return Layout{4, 15, 3, 2, 0, 0, 0};
  if (profile == "RNG15_RFL8_NIR8_ZONE16") return Layout{8, 15, 3, 2, 0, 0, 0};
  if (profile == "RNG15_RFL8_NIR8_DUAL") return Layout{8, 15, 3, 2, 32, 15, 6};
  return std::nullopt;
}

OusterDecoder::OusterDecoder(OusterMetadata metadata, std::string frame_id) : metadata_(std::move(metadata)), frame_id_(std::move(frame_id)) {
  legacy_ = metadata_.udp_profile_lidar == "LEGACY";
  layout_ = ouster_pixel_layout(metadata_.udp_profile_lidar).value_or(OusterPixelLayout{});
  const int beams = metadata_.pixels_per_column, columns = metadata_.columns_per_frame;
  direction_.resize(static_cast<std::size_t>(beams * columns));
  offset_mm_.resize(direction_.size());
  const double n = metadata_.lidar_origin_to_beam_origin_mm;
  for (int column = 0; column < columns; ++column) {
    const double encoder = 2.0 * M_PI * (1.0 - static_cast<double>(column) / columns);
    for (int beam = 0; beam < beams; ++beam) {
      const double azimuth = encoder - metadata_.beam_azimuth_deg[static_cast<std::size_t>(beam)] * M_PI / 180.0;
      const double altitude = metadata_.beam_altitude_deg[static_cast<std::size_t>(beam)] * M_PI / 180.0;
      const Eigen::Vector3d direction(std::cos(azimuth) * std::cos(altitude), std::sin(azimuth) * std::cos(altitude), std::sin(altitude));
      const std::size_t index = static_cast<std::size_t>(column * beams + beam);
      direction_[index] = direction;
      offset_mm_[index] = Eigen::Vector3d(n * std::cos(encoder) - n * direction.x(), n * std::sin(encoder) - n * direction.y(), -n * direction.z());
    }
  }
  std::vector<int> order(static_cast<std::size_t>(beams));
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return metadata_.beam_altitude_deg[static_cast<std::size_t>(a)] < metadata_.beam_altitude_deg[static_cast<std::size_t>(b)];
  });
  ring_.resize(order.size());
  for (std::size_t rank = 0; rank < order.size(); ++rank) ring_[static_cast<std::size_t>(order[rank])] = static_cast<uint32_t>(rank);
  rotation_ = metadata_.lidar_to_sensor.topLeftCorner<3, 3>();
  translation_mm_ = metadata_.lidar_to_sensor.topRightCorner<3, 1>();
}

Result<OusterDecoder> OusterDecoder::create(OusterMetadata metadata, std::string frame_id) {
  if (!ouster_pixel_layout(metadata.udp_profile_lidar)) {
    return Error(fmt::format("Ouster packet profile {} is not decoded (LEGACY, RNG19_RFL8_SIG16_NIR16[_DUAL, _ZONE16], FIVE_WORD_PIXEL, "
                             "RNG15_RFL8_NIR8[_DUAL, _ZONE16])",
                             metadata.udp_profile_lidar),
                 "udp_profile_lidar");
  }
  if (metadata.udp_profile_imu != "LEGACY" && metadata.udp_profile_imu != "ACCEL32_GYRO32_NMEA" && metadata.udp_profile_imu != "OFF") {
    return Error(fmt::format("Ouster IMU profile {} is not decoded (LEGACY, ACCEL32_GYRO32_NMEA)", metadata.udp_profile_imu), "udp_profile_imu");
  }
  if (metadata.udp_profile_imu == "ACCEL32_GYRO32_NMEA" && metadata.imu_measurements_per_packet <= 0) {
    return Error("Ouster metadata: IMU profile ACCEL32_GYRO32_NMEA without imu_data_format.imu_measurements_per_packet", "imu_measurements_per_packet");
  }
  const auto beams = static_cast<std::size_t>(metadata.pixels_per_column);
  if (beams == 0 || metadata.beam_altitude_deg.size() != beams || metadata.beam_azimuth_deg.size() != beams) {
    return Error(fmt::format("Ouster metadata: {} pixels per column but {} altitudes and {} azimuths", beams, metadata.beam_altitude_deg.size(),
                             metadata.beam_azimuth_deg.size()),
                 "pixels_per_column");
  }
  if (metadata.columns_per_frame <= 0 || metadata.columns_per_packet <= 0 || metadata.column_window[0] < 0 ||
      metadata.column_window[1] >= metadata.columns_per_frame) {
    return Error("Ouster metadata: columns per frame / packet or the column window out of range", "data_format");
  }
  return OusterDecoder(std::move(metadata), std::move(frame_id));
}

std::size_t OusterDecoder::lidar_packet_bytes() const {
  const auto beams = static_cast<std::size_t>(metadata_.pixels_per_column), columns = static_cast<std::size_t>(metadata_.columns_per_packet);
  return legacy_ ? columns * (16 + 12 * beams + 4) : kProfileHeaderBytes + columns * (12 + layout_.bytes * beams) + kProfileFooterBytes;
}

std::size_t OusterDecoder::imu_packet_bytes() const {
  if (metadata_.udp_profile_imu != "ACCEL32_GYRO32_NMEA") return kLegacyImuBytes;
  return kProfileHeaderBytes + kNmeaBlockBytes + static_cast<std::size_t>(metadata_.imu_measurements_per_packet) * kImuSampleBytes + kProfileFooterBytes;
}

void OusterDecoder::malformed(const std::string& what) {
  ++statistics_.malformed;
  if (statistics_.first_error.empty()) statistics_.first_error = what;
}

Timestamp OusterDecoder::sensor_time(uint64_t nanoseconds, Timestamp capture_time) {
  const auto sensor = static_cast<int64_t>(nanoseconds);
  if (!clock_offset_ns_) clock_offset_ns_ = std::llabs(capture_time.nanoseconds() - sensor) < kDayNs ? 0 : capture_time.nanoseconds() - sensor;
  return Timestamp::from_nanoseconds(sensor + *clock_offset_ns_);
}

void OusterDecoder::emit(std::vector<OusterFrame>& frames) {
  if (!frame_) return;
  OusterFrame& done = *frame_;
  const int first = metadata_.column_window[0], last = metadata_.column_window[1];
  done.complete = std::all_of(seen_.begin() + first, seen_.begin() + last + 1, [](bool seen) { return seen; });
  if (!done.cloud.points.empty()) {
    done.cloud.timestamp = *std::min_element(done.cloud.point_timestamps.begin(), done.cloud.point_timestamps.end());
    ++statistics_.frames;
    if (!done.complete) ++statistics_.incomplete_frames;
    frames.push_back(std::move(done));
  }
  frame_.reset();
}

void OusterDecoder::add_column(uint64_t time_ns, uint16_t measurement_id, const uint8_t* pixels, Timestamp capture_time) {
  if (measurement_id >= metadata_.columns_per_frame) return malformed(fmt::format("Ouster column with measurement id {} of {}", measurement_id, metadata_.columns_per_frame));
  OusterFrame& frame = *frame_;
  const int beams = metadata_.pixels_per_column;
  seen_[measurement_id] = true;
  ++frame.columns;
  const Timestamp time = sensor_time(time_ns, capture_time);
  for (int beam = 0; beam < beams; ++beam) {
    const std::size_t index = static_cast<std::size_t>(measurement_id * beams + beam);
    const uint32_t ring = ring_[static_cast<std::size_t>(beam)];
    const uint8_t* pixel = pixels + layout_.bytes * static_cast<std::size_t>(beam);
    const uint32_t range_mm = bits(pixel, 0, layout_.range_bits) << layout_.range_shift;
    // LEGACY: the calibrated reflectivity (16 bits) clamped to 255.
    const float intensity = legacy_ ? static_cast<float>(std::min<uint16_t>(read_le<uint16_t>(pixel + 4), 255)) / 255.0F
                                    : static_cast<float>(pixel[layout_.reflectivity_byte]) / 255.0F;
    frame.range_mm[static_cast<std::size_t>(beam * metadata_.columns_per_frame + measurement_id)] = range_mm;
    add_point(frame, index, range_mm, intensity, ring, time);
    if (layout_.second_range_bits > 0) {
      const uint32_t second_mm = bits(pixel, layout_.second_range_bit, layout_.second_range_bits) << layout_.range_shift;
      if (second_mm != range_mm) add_point(frame, index, second_mm, static_cast<float>(pixel[layout_.second_reflectivity_byte]) / 255.0F, ring, time);
    }
  }
}

void OusterDecoder::add_point(OusterFrame& frame, std::size_t index, uint32_t range_mm, float intensity, uint32_t ring, Timestamp time) {
  if (range_mm == 0) return;  // no return
  const Eigen::Vector3d lidar_mm = range_mm * direction_[index] + offset_mm_[index];
  const Eigen::Vector3d sensor_m = (rotation_ * lidar_mm + translation_mm_) * 1e-3;
  frame.cloud.points.push_back(sensor_m.cast<float>());
  frame.cloud.intensities.push_back(intensity);
  frame.cloud.ring_ids.push_back(ring);
  frame.cloud.point_timestamps.push_back(time);
}

void OusterDecoder::add_imu_packet(const uint8_t* data, Timestamp capture_time, std::vector<msgs::ImuMessage>& imu) {
  const auto push = [&](uint64_t time_ns, const uint8_t* accel, double accel_scale, const uint8_t* gyro, double gyro_scale) {
    msgs::ImuMessage sample;
    sample.timestamp = sensor_time(time_ns, capture_time);
    sample.frame_id = "imu";
    for (int axis = 0; axis < 3; ++axis) {
      sample.linear_acceleration[axis] = read_le<float>(accel + 4 * axis) * accel_scale;
      sample.angular_velocity[axis] = read_le<float>(gyro + 4 * axis) * gyro_scale;
    }
    if (!sample.linear_acceleration.allFinite() || !sample.angular_velocity.allFinite()) {
      ++statistics_.invalid_imu_samples;
      return malformed("Ouster IMU sample with non-finite values");
    }
    imu.push_back(sample);
  };
  ++statistics_.imu_packets;
  if (metadata_.udp_profile_imu != "ACCEL32_GYRO32_NMEA") return push(read_le<uint64_t>(data + 8), data + 24, kGravity, data + 36, M_PI / 180.0);
  for (int k = 0; k < metadata_.imu_measurements_per_packet; ++k) {
    const uint8_t* sample = data + kProfileHeaderBytes + kNmeaBlockBytes + static_cast<std::size_t>(k) * kImuSampleBytes;
    const uint64_t time_ns = read_le<uint64_t>(sample);
    if (time_ns == 0 || (read_le<uint16_t>(sample + 10) & 1U) == 0) {  // a slot not filled, or not valid
      ++statistics_.invalid_imu_samples;
      continue;
    }
    push(time_ns, sample + 12, 1.0, sample + 24, 1.0);
  }
}

void OusterDecoder::add_packet(std::string_view payload, Timestamp capture_time, std::vector<OusterFrame>& frames, std::vector<msgs::ImuMessage>& imu) {
  const auto* data = reinterpret_cast<const uint8_t*>(payload.data());
  if (payload.size() == imu_packet_bytes()) return add_imu_packet(data, capture_time, imu);
  if (payload.size() == kZonePacketBytes && !legacy_) {
    ++statistics_.zone_packets;
    return;
  }
  if (payload.size() != lidar_packet_bytes()) {
    return malformed(fmt::format("Ouster packet of {} bytes (lidar packets of this metadata have {}, IMU packets {})", payload.size(), lidar_packet_bytes(),
                                 imu_packet_bytes()));
  }
  const auto beams = static_cast<std::size_t>(metadata_.pixels_per_column);
  const std::size_t column_bytes = legacy_ ? 16 + 12 * beams + 4 : 12 + layout_.bytes * beams;
  const uint8_t* first_column = legacy_ ? data : data + kProfileHeaderBytes;
  const uint16_t packet_frame = legacy_ ? read_le<uint16_t>(first_column + 10) : read_le<uint16_t>(data + 2);
  ++statistics_.lidar_packets;
  if (frame_ && frame_->frame_id != packet_frame) emit(frames);
  if (!frame_) {
    frame_ = OusterFrame();
    frame_->frame_id = packet_frame;
    frame_->cloud.frame_id = frame_id_;
    frame_->range_mm.assign(beams * static_cast<std::size_t>(metadata_.columns_per_frame), 0);
    seen_.assign(static_cast<std::size_t>(metadata_.columns_per_frame), false);
  }
  for (int column = 0; column < metadata_.columns_per_packet; ++column) {
    const uint8_t* block = first_column + static_cast<std::size_t>(column) * column_bytes;
    const uint64_t time_ns = read_le<uint64_t>(block);
    const uint16_t measurement_id = read_le<uint16_t>(block + 8);
    const bool valid = legacy_ ? read_le<uint32_t>(block + column_bytes - 4) == 0xFFFFFFFFu : (read_le<uint16_t>(block + 10) & 1u) != 0;
    if (!valid) {
      ++statistics_.invalid_columns;
      continue;
    }
    add_column(time_ns, measurement_id, block + (legacy_ ? 16 : 12), capture_time);
  }
}

void OusterDecoder::flush(std::vector<OusterFrame>& frames) { emit(frames); }

}  // namespace hanzo::fusion::drivers
