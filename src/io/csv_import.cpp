#include "hanzo/fusion/io/csv_import.hpp"

#include <charconv>
#include <sstream>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/msgs/validate.hpp"
#include "text_lines.hpp"

namespace hanzo::fusion::io {
namespace {

enum class CsvKind { kImu, kGnss, kWheel };

Result<msgs::GnssFixType> fix_type_from(const std::string& name) {
  if (const std::optional<msgs::GnssFixType> type = msgs::gnss_fix_type_from_string(name)) return *type;
  return Error(fmt::format("fix_type '{}' is not NO_FIX, FIX_2D, FIX_3D, RTK_FLOAT or RTK_FIXED", name));
}

}  // namespace

Result<std::vector<msgs::SensorMessage>> parse_sensor_csv(const std::string& text, const std::string& source_name) {
  std::istringstream stream(text);
  std::string line;
  std::optional<CsvKind> kind;
  std::size_t columns = 0;
  std::vector<msgs::SensorMessage> messages;
  for (std::size_t line_number = 1; std::getline(stream, line); ++line_number) {
    const std::string where = fmt::format("{}:{}", source_name, line_number);
    const std::vector<std::string> fields = split_fields(line);
    if (fields.empty() || fields[0][0] == '#') continue;
    if (!kind) {
      const std::string header = fmt::format("{}", fmt::join(fields, ","));
      if (header == "timestamp_ns,ax,ay,az,wx,wy,wz") kind = CsvKind::kImu, columns = 7;
      else if (header == "timestamp_ns,latitude,longitude,altitude,fix_type") kind = CsvKind::kGnss, columns = 5;
      else if (header == "timestamp_ns,latitude,longitude,altitude,fix_type,satellites_used,hdop") kind = CsvKind::kGnss, columns = 7;
      else if (header == "timestamp_ns,left_distance,right_distance,wheel_separation") kind = CsvKind::kWheel, columns = 4;
      else {
        return Error(fmt::format("{}: unknown CSV header '{}' (see docs/sensor-logs.md for the IMU, GNSS and wheel layouts)",
                                 where, header));
      }
      continue;
    }
    if (fields.size() != columns) return Error(fmt::format("{}: expected {} columns, found {}", where, columns, fields.size()));
    int64_t ns = 0;
    const auto [end, error] = std::from_chars(fields[0].data(), fields[0].data() + fields[0].size(), ns);
    if (error != std::errc() || end != fields[0].data() + fields[0].size()) {
      return Error(fmt::format("{}: timestamp_ns '{}' is not an integer", where, fields[0]));
    }
    const Timestamp stamp = Timestamp::from_nanoseconds(ns);
    if (!messages.empty() && stamp <= msgs::timestamp_of(messages.back())) {
      return Error(fmt::format("{}: timestamp {} ns is not after the previous line's {} ns", where, ns,
                               msgs::timestamp_of(messages.back()).nanoseconds()));
    }
    std::vector<double> numbers(fields.size(), 0.0);
    for (std::size_t i = 1; i < fields.size(); ++i) {
      if (*kind == CsvKind::kGnss && i == 4) continue;  // fix_type is a name
      auto value = parse_double(fields[i]);
      if (!value) return Error(fmt::format("{}: column {}: '{}' is not a number", where, i + 1, fields[i]));
      numbers[i] = *value;
    }
    msgs::SensorMessage message;
    if (*kind == CsvKind::kImu) {
      msgs::ImuMessage imu;
      imu.timestamp = stamp;
      imu.linear_acceleration = {numbers[1], numbers[2], numbers[3]};
      imu.angular_velocity = {numbers[4], numbers[5], numbers[6]};
      message = imu;
    } else if (*kind == CsvKind::kGnss) {
      msgs::GnssMessage gnss;
      gnss.timestamp = stamp;
      gnss.latitude = numbers[1];
      gnss.longitude = numbers[2];
      gnss.altitude = numbers[3];
      HANZO_ASSIGN_OR_RETURN(gnss.fix_type, with_context(fix_type_from(fields[4]), where));
      if (columns == 7) {
        if (numbers[5] < 0 || numbers[5] != static_cast<double>(static_cast<uint32_t>(numbers[5]))) {
          return Error(fmt::format("{}: satellites_used '{}' is not a whole number >= 0", where, fields[5]));
        }
        gnss.satellites_used = static_cast<uint32_t>(numbers[5]);
        gnss.hdop = static_cast<float>(numbers[6]);
      }
      message = gnss;
    } else {
      msgs::WheelOdometryMessage wheel;
      wheel.timestamp = stamp;
      wheel.left_distance = numbers[1];
      wheel.right_distance = numbers[2];
      wheel.wheel_separation = numbers[3];
      message = wheel;
    }
    const Status valid = std::visit([](const auto& typed) { return msgs::validate(typed); }, message);
    if (!valid) return Error(fmt::format("{}: {}", where, valid.error().message), valid.error().field);
    messages.push_back(std::move(message));
  }
  if (!kind) return Error(fmt::format("{}: empty file (no CSV header)", source_name));
  return messages;
}

Result<std::vector<msgs::SensorMessage>> read_sensor_csv(const std::string& path) {
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_file(path));
  return parse_sensor_csv(text, path);
}

}  // namespace hanzo::fusion::io
