#include "hanzo/fusion/drivers/xsens.hpp"

#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "civil_time.hpp"

namespace hanzo::fusion::drivers {

namespace {

constexpr uint8_t kPreamble = 0xFA;
constexpr uint8_t kBusIdentifier = 0xFF;
constexpr std::size_t kMaxPayload = 2048;   // the protocol allows 2048 bytes of extended payload
constexpr double kFineTicksPerSecond = 10000.0;
constexpr int64_t kNanosecondsPerFineTick = 100000;

uint32_t big_endian(std::span<const uint8_t> bytes) {
  uint32_t value = 0;
  for (const uint8_t byte : bytes) value = (value << 8) | byte;
  return value;
}

/// Reads big-endian fields one after another; the caller checked the size.
class Reader {
 public:
  explicit Reader(std::span<const uint8_t> bytes) : bytes_(bytes) {}
  uint8_t u8() { return bytes_[at_++]; }
  uint16_t u16() { return static_cast<uint16_t>(take(2)); }
  uint32_t u32() { return take(4); }
  int32_t i32() { return static_cast<int32_t>(take(4)); }
  /// One real number in the packet's number format (bits 0-1 of its identifier).
  double real(int format) {
    switch (format) {
      case 0: {
        const uint32_t bits = take(4);
        float value;
        std::memcpy(&value, &bits, sizeof(value));
        return value;
      }
      case 1: return static_cast<double>(static_cast<int32_t>(take(4))) / double(1 << 20);  // FP12.20
      case 2: {  // FP16.32: 32 bits of fraction, then the 16-bit signed integer part
        const uint32_t fraction = take(4);
        const auto integer = static_cast<int16_t>(take(2));
        return static_cast<double>((static_cast<int64_t>(integer) << 32) | fraction) / 4294967296.0;
      }
      default: {
        const uint64_t high = take(4), low = take(4);
        const uint64_t bits = (high << 32) | low;
        double value;
        std::memcpy(&value, &bits, sizeof(value));
        return value;
      }
    }
  }
  Eigen::Vector3d vector3(int format) {
    const double x = real(format), y = real(format);
    return {x, y, real(format)};
  }

 private:
  uint32_t take(std::size_t count) {
    const uint32_t value = big_endian(bytes_.subspan(at_, count));
    at_ += count;
    return value;
  }
  std::span<const uint8_t> bytes_;
  std::size_t at_ = 0;
};

constexpr std::size_t real_size(int format) { return format == 0 || format == 1 ? 4 : format == 2 ? 6 : 8; }

XsensGnssPvt read_pvt(Reader& in) {
  XsensGnssPvt pvt;
  pvt.itow = in.u32();
  pvt.year = in.u16();
  pvt.month = in.u8();
  pvt.day = in.u8();
  pvt.hour = in.u8();
  pvt.minute = in.u8();
  pvt.second = in.u8();
  pvt.valid = in.u8();
  pvt.time_accuracy = in.u32();
  pvt.nano = in.i32();
  pvt.fix_type = in.u8();
  pvt.flags = in.u8();
  pvt.satellites = in.u8();
  in.u8();  // reserved
  pvt.longitude = in.i32();
  pvt.latitude = in.i32();
  pvt.height = in.i32();
  pvt.height_msl = in.i32();
  pvt.horizontal_accuracy = in.u32();
  pvt.vertical_accuracy = in.u32();
  pvt.velocity_north = in.i32();
  pvt.velocity_east = in.i32();
  pvt.velocity_down = in.i32();
  pvt.ground_speed = in.i32();
  pvt.heading_of_motion = in.i32();
  pvt.speed_accuracy = in.u32();
  pvt.heading_accuracy = in.u32();
  pvt.heading_of_vehicle = in.i32();
  for (uint16_t* dop : {&pvt.gdop, &pvt.pdop, &pvt.tdop, &pvt.vdop, &pvt.hdop, &pvt.ndop, &pvt.edop}) *dop = in.u16();
  return pvt;
}

Result<Timestamp> timestamp_of(int64_t year, int month, int day, int hour, int minute, int second, int64_t nanoseconds) {
  if (!valid_date(year, month, day) || hour > 23 || minute > 59 || second > 60) {
    return Error(fmt::format("date {:04}-{:02}-{:02} {:02}:{:02}:{:02} out of range", year, month, day, hour, minute, second));
  }
  const int64_t seconds = days_from_civil(year, month, day) * 86400 + hour * 3600 + minute * 60 + second;
  return Timestamp::from_nanoseconds(seconds * 1'000'000'000 + nanoseconds);
}

// R_ENU_frame of the local frames Xsens reports orientation in.
Eigen::Matrix3d enu_from(XsensCoordinates coordinates) {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  if (coordinates == XsensCoordinates::kNed) R << 0, 1, 0, 1, 0, 0, 0, 0, -1;
  if (coordinates == XsensCoordinates::kNwu) R << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  return R;
}

}  // namespace

Result<Timestamp> XsensUtcTime::to_timestamp() const {
  if (nanoseconds >= 1'000'000'000U) return Error(fmt::format("UTCTime: {} ns within a second", nanoseconds));
  return timestamp_of(year, month, day, hour, minute, second, nanoseconds);
}

Result<XsensMtData2> decode_mtdata2(std::span<const uint8_t> payload) {
  XsensMtData2 message;
  std::size_t at = 0;
  while (at < payload.size()) {
    if (payload.size() - at < 3) return Error(fmt::format("MTData2: {} bytes left after the last packet, a packet header needs 3", payload.size() - at));
    const uint16_t identifier = static_cast<uint16_t>(big_endian(payload.subspan(at, 2)));
    const std::size_t size = payload[at + 2];
    if (at + 3 + size > payload.size()) {
      return Error(fmt::format("MTData2: packet 0x{:04X} of {} bytes runs past the payload ({} left)", identifier, size, payload.size() - at - 3));
    }
    const std::span<const uint8_t> data = payload.subspan(at + 3, size);
    at += 3 + size;
    const int format = identifier & 0x3;
    const auto coordinates = static_cast<XsensCoordinates>(std::min((identifier >> 2) & 0x3, 2));
    const std::size_t real = real_size(format);
    // Expected size by type (0 = not decoded here).
    const uint16_t type = identifier & 0xFFF0;
    std::size_t expected = 0;
    switch (type) {
      case 0x1010: expected = 12; break;
      case 0x1020: expected = 2; break;
      case 0x1060: expected = 4; break;
      case 0x2010: case 0x8030: expected = 4 * real; break;
      case 0x2030: case 0x4010: case 0x4020: case 0x4030: case 0x8020: case 0xC020: case 0xD010: expected = 3 * real; break;
      case 0x5020: expected = real; break;
      case 0x5040: expected = 2 * real; break;
      case 0x7010: expected = 94; break;
      case 0xE010: expected = 1; break;
      case 0xE020: expected = 4; break;
      default: break;
    }
    if (expected == 0) {
      ++message.unknown_packets;
      continue;
    }
    if (size != expected) return Error(fmt::format("MTData2: packet 0x{:04X} has {} bytes, expected {}", identifier, size, expected));
    Reader in(data);
    switch (type) {
      case 0x1010: {
        XsensUtcTime utc;
        utc.nanoseconds = in.u32();
        utc.year = in.u16();
        utc.month = in.u8();
        utc.day = in.u8();
        utc.hour = in.u8();
        utc.minute = in.u8();
        utc.second = in.u8();
        utc.flags = in.u8();
        message.utc = utc;
        break;
      }
      case 0x1020: message.packet_counter = in.u16(); break;
      case 0x1060: message.sample_time_fine = in.u32(); break;
      case 0x2010: case 0x8030: {
        const double w = in.real(format), x = in.real(format), y = in.real(format), z = in.real(format);
        (type == 0x2010 ? message.quaternion : message.delta_q) = Eigen::Quaterniond(w, x, y, z);
        if (type == 0x2010) message.coordinates = coordinates;
        break;
      }
      case 0x2030: message.euler_degrees = in.vector3(format); message.coordinates = coordinates; break;
      case 0x4010: message.delta_v = in.vector3(format); break;
      case 0x4020: message.acceleration = in.vector3(format); break;
      case 0x4030: message.free_acceleration = in.vector3(format); message.coordinates = coordinates; break;
      case 0x8020: message.rate_of_turn = in.vector3(format); break;
      case 0xC020: message.magnetic_field = in.vector3(format); break;
      case 0xD010: message.velocity = in.vector3(format); message.coordinates = coordinates; break;
      case 0x5020: message.altitude_ellipsoid = in.real(format); break;
      case 0x5040: {
        const double latitude = in.real(format);
        message.lat_lon = Eigen::Vector2d(latitude, in.real(format));
        break;
      }
      case 0x7010: message.gnss_pvt = read_pvt(in); break;
      case 0xE010: message.status = in.u8(); break;
      case 0xE020: message.status = in.u32(); break;
      default: break;
    }
  }
  return message;
}

std::optional<Eigen::Quaterniond> xsens_orientation_enu(const XsensMtData2& message) {
  Eigen::Matrix3d R_local_sensor;
  if (message.quaternion) {
    const double norm = message.quaternion->norm();
    if (!(norm > 0.5 && norm < 2.0)) return std::nullopt;  // not a rotation (or not finite)
    R_local_sensor = message.quaternion->normalized().toRotationMatrix();
  } else if (message.euler_degrees) {
    const Eigen::Vector3d radians = *message.euler_degrees * (M_PI / 180.0);
    R_local_sensor = (Eigen::AngleAxisd(radians.z(), Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(radians.y(), Eigen::Vector3d::UnitY()) *
                      Eigen::AngleAxisd(radians.x(), Eigen::Vector3d::UnitX()))
                         .toRotationMatrix();
  } else {
    return std::nullopt;
  }
  if (!R_local_sensor.allFinite()) return std::nullopt;
  return Eigen::Quaterniond(enu_from(message.coordinates) * R_local_sensor).normalized();
}

void XsensDecoder::error(uint64_t& counter, const std::string& what) {
  ++counter;
  if (statistics_.first_error.empty()) statistics_.first_error = what;
}

void XsensDecoder::feed(std::string_view bytes, std::vector<msgs::ImuMessage>& imu, std::vector<msgs::GnssMessage>& gnss,
                        std::vector<XsensMtData2>* decoded) {
  buffer_.append(bytes);
  std::size_t at = 0;
  const auto byte = [&](std::size_t i) { return static_cast<uint8_t>(buffer_[i]); };
  while (true) {
    // The next preamble + bus identifier; everything before it is skipped.
    std::size_t start = at;
    while (start + 1 < buffer_.size() && !(byte(start) == kPreamble && byte(start + 1) == kBusIdentifier)) ++start;
    if (start + 1 >= buffer_.size()) {
      // Keep a trailing preamble byte: its bus identifier may come with the next bytes.
      const std::size_t keep = start < buffer_.size() && byte(start) == kPreamble ? start : buffer_.size();
      statistics_.skipped_bytes += keep - at;
      at = keep;
      break;
    }
    statistics_.skipped_bytes += start - at;
    at = start;
    if (buffer_.size() - at < 4) break;
    std::size_t header = 4, length = byte(at + 3);
    if (length == 0xFF) {
      if (buffer_.size() - at < 6) break;
      header = 6;
      length = (std::size_t{byte(at + 4)} << 8) | byte(at + 5);
      if (length > kMaxPayload) {  // not a frame: a preamble inside other data
        error(statistics_.checksum_errors, fmt::format("a frame claims {} bytes of payload (at most {})", length, kMaxPayload));
        ++statistics_.skipped_bytes;
        ++at;
        continue;
      }
    }
    if (buffer_.size() - at < header + length + 1) break;  // wait for the rest
    uint8_t sum = 0;
    for (std::size_t i = at + 1; i < at + header + length + 1; ++i) sum = static_cast<uint8_t>(sum + byte(i));
    if (sum != 0) {
      error(statistics_.checksum_errors, fmt::format("checksum of a frame (message 0x{:02X}, {} bytes) is off by {}", byte(at + 2), length, sum));
      ++statistics_.skipped_bytes;
      ++at;
      continue;
    }
    ++statistics_.messages;
    const uint8_t message_id = byte(at + 2);
    const auto payload = std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(buffer_.data()) + at + header, length);
    at += header + length + 1;
    if (message_id != kXsensMtData2) {
      ++statistics_.other_messages;
      continue;
    }
    ++statistics_.mtdata2;
    Result<XsensMtData2> message = decode_mtdata2(payload);
    if (!message) {
      error(statistics_.malformed, message.error().message);
      continue;
    }
    statistics_.unknown_packets += message->unknown_packets;
    handle(*message, imu, gnss);
    if (decoded) decoded->push_back(std::move(*message));
  }
  buffer_.erase(0, at);
}

std::optional<Timestamp> XsensDecoder::time_of(const XsensMtData2& message) {
  if (message.utc && message.utc->valid()) {
    if (Result<Timestamp> utc = message.utc->to_timestamp(); utc) {
      if (message.sample_time_fine) utc_anchor_ = {*utc, *message.sample_time_fine};
      return *utc;
    }
  }
  if (!message.sample_time_fine) return std::nullopt;
  if (utc_anchor_) {
    const uint32_t ticks = *message.sample_time_fine - utc_anchor_->second;  // modulo 2^32
    return utc_anchor_->first + Duration::from_nanoseconds(int64_t{ticks} * kNanosecondsPerFineTick);
  }
  ++statistics_.device_clock;
  return Timestamp::from_nanoseconds(int64_t{*message.sample_time_fine} * kNanosecondsPerFineTick);
}

void XsensDecoder::handle(const XsensMtData2& message, std::vector<msgs::ImuMessage>& imu, std::vector<msgs::GnssMessage>& gnss) {
  if (message.gnss_pvt) {
    const XsensGnssPvt& pvt = *message.gnss_pvt;
    const bool fix = (pvt.fix_type >= 2 && pvt.fix_type <= 4) && (pvt.flags & 0x01) != 0 && std::abs(pvt.latitude) <= 900'000'000 &&
                     std::abs(pvt.longitude) <= 1'800'000'000;
    Result<Timestamp> time = timestamp_of(pvt.year, pvt.month, pvt.day, pvt.hour, pvt.minute, pvt.second, pvt.nano);
    if (!fix || (pvt.valid & 0x03) != 0x03 || !time) {
      ++statistics_.gnss_without_fix;
    } else {
      msgs::GnssMessage out;
      out.timestamp = *time;
      out.latitude = pvt.latitude * 1e-7;
      out.longitude = pvt.longitude * 1e-7;
      out.altitude = pvt.height * 1e-3;
      out.fix_type = pvt.fix_type == 2 ? msgs::GnssFixType::kFix2d : msgs::GnssFixType::kFix3d;
      const double horizontal = pvt.horizontal_accuracy * 1e-3, vertical = pvt.vertical_accuracy * 1e-3;
      out.position_covariance = Eigen::Vector3d(0.5 * horizontal * horizontal, 0.5 * horizontal * horizontal, vertical * vertical).asDiagonal();
      out.satellites_used = pvt.satellites;
      out.hdop = static_cast<float>(pvt.hdop * 0.01);
      gnss.push_back(out);
      ++statistics_.gnss_fixes;
    }
  }
  const std::optional<Timestamp> time = time_of(message);
  const bool inertial = (message.acceleration || message.delta_v) && (message.rate_of_turn || message.delta_q);
  std::optional<double> interval;  // s since the previous inertial message
  if (inertial && message.sample_time_fine) {
    if (previous_inertial_fine_) interval = static_cast<uint32_t>(*message.sample_time_fine - *previous_inertial_fine_) / kFineTicksPerSecond;
    previous_inertial_fine_ = *message.sample_time_fine;
  }
  const bool rates = message.acceleration && message.rate_of_turn;
  if (!inertial || !time || (!rates && !(interval && *interval > 0))) {
    ++statistics_.without_inertial;
    return;
  }
  msgs::ImuMessage out;
  out.timestamp = *time;
  out.frame_id = config_.frame_id;
  out.linear_acceleration = message.acceleration ? *message.acceleration : Eigen::Vector3d(*message.delta_v / *interval);
  if (message.rate_of_turn) {
    out.angular_velocity = *message.rate_of_turn;
  } else {
    const Eigen::AngleAxisd turned(message.delta_q->normalized());
    out.angular_velocity = turned.angle() * turned.axis() / *interval;
  }
  if (!out.linear_acceleration.allFinite() || !out.angular_velocity.allFinite()) {
    error(statistics_.malformed, fmt::format("MTData2 message {}: acceleration or rate of turn not finite", message.packet_counter.value_or(0)));
    return;
  }
  out.orientation = xsens_orientation_enu(message);
  imu.push_back(std::move(out));
  ++statistics_.imu_messages;
}

}  // namespace hanzo::fusion::drivers
