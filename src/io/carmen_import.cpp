#include "hanzo/fusion/io/carmen_import.hpp"

#include <cmath>
#include <sstream>

#include <fmt/format.h>
#include <zlib.h>

#include "hanzo/fusion/msgs/validate.hpp"
#include "text_lines.hpp"

namespace hanzo::fusion::io {
namespace {

// The whole file, gunzipped when it is gzip (zlib's gzread passes plain files through).
Result<std::string> read_maybe_gzip(const std::string& path) {
  gzFile file = gzopen(path.c_str(), "rb");
  if (file == nullptr) return Error(fmt::format("{}: cannot open file", path));
  std::string text;
  char buffer[1 << 16];
  int n = 0;
  while ((n = gzread(file, buffer, sizeof buffer)) > 0) text.append(buffer, static_cast<std::size_t>(n));
  int error = Z_OK;
  const char* message = gzerror(file, &error);
  gzclose(file);
  if (n < 0 || (error != Z_OK && error != Z_STREAM_END)) return Error(fmt::format("{}: cannot decompress ({})", path, message));
  return text;
}

double wrap_angle(double angle) { return std::remainder(angle, 2.0 * M_PI); }

}  // namespace

Result<CarmenLog> read_carmen(const std::string& path, const CarmenImportConfig& config) {
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_maybe_gzip(path));
  CarmenLog log;
  CarmenImportReport& report = log.report;
  std::optional<Timestamp> last_scan_time, last_odom_time;
  std::optional<Eigen::Vector3d> last_odom_pose;
  double left = 0.0, right = 0.0;
  std::istringstream stream(text);
  std::string line;
  for (std::size_t line_number = 1; std::getline(stream, line); ++line_number) {
    const std::vector<std::string> fields = split_fields(line);
    if (fields.empty() || fields[0][0] == '#') continue;
    const std::string where = fmt::format("{}:{}", path, line_number);
    auto number = [&](std::size_t i) -> Result<double> {
      if (i >= fields.size()) return Error(fmt::format("{}: {} line has too few fields ({})", where, fields[0], fields.size()));
      auto value = parse_double(fields[i]);
      if (!value || !std::isfinite(*value)) return Error(fmt::format("{}: field {} '{}' is not a finite number", where, i + 1, fields[i]));
      return *value;
    };
    auto reject = [&](const std::string& reason) {
      if (report.rejected++ == 0) report.first_rejection = fmt::format("{}: {}", where, reason);
    };
    if (fields[0] == "FLASER") {
      double count_value = 0;
      HANZO_ASSIGN_OR_RETURN(count_value, number(1));
      const auto n = static_cast<std::size_t>(count_value);
      if (count_value < 2 || count_value != static_cast<double>(n) || fields.size() < n + 11) {
        return Error(fmt::format("{}: FLASER with {} beams needs {} fields, has {}", where, fields[1], n + 11, fields.size()));
      }
      double x = 0, y = 0, theta = 0, seconds = 0;
      HANZO_ASSIGN_OR_RETURN(x, number(n + 2));
      HANZO_ASSIGN_OR_RETURN(y, number(n + 3));
      HANZO_ASSIGN_OR_RETURN(theta, number(n + 4));
      HANZO_ASSIGN_OR_RETURN(seconds, number(n + 8));
      const Timestamp time = Timestamp::from_seconds(seconds);
      if (last_scan_time && time <= *last_scan_time) {
        reject(fmt::format("scan time {} s does not increase", seconds));
        continue;
      }
      msgs::PointCloudMessage scan;
      scan.timestamp = time;
      scan.frame_id = "laser";
      const double step = M_PI / static_cast<double>(n);
      for (std::size_t i = 0; i < n; ++i) {
        double range = 0;
        HANZO_ASSIGN_OR_RETURN(range, number(2 + i));
        if (range <= 0.0 || range >= config.max_range) continue;
        const double angle = -M_PI / 2 + step * static_cast<double>(i);
        scan.points.emplace_back(static_cast<float>(range * std::cos(angle)), static_cast<float>(range * std::sin(angle)), 0.0F);
      }
      if (scan.points.empty()) {
        reject("scan without any return");
        continue;
      }
      last_scan_time = time;
      report.scan_poses.timestamps.push_back(time);
      report.scan_poses.poses.push_back(pose_matrix(SE2(theta, {x, y})));
      log.scans.push_back(std::move(scan));
      ++report.scans;
    } else if (fields[0] == "ODOM") {
      if (config.wheel_separation <= 0.0) {
        ++report.skipped_lines;
        continue;
      }
      double x = 0, y = 0, theta = 0, seconds = 0;
      HANZO_ASSIGN_OR_RETURN(x, number(1));
      HANZO_ASSIGN_OR_RETURN(y, number(2));
      HANZO_ASSIGN_OR_RETURN(theta, number(3));
      HANZO_ASSIGN_OR_RETURN(seconds, number(7));
      if (seconds == 0.0) {
        // The "corrected" Radish logs put the corrected pose after each scan as an ODOM line at
        // time 0: re-anchor the odometry there instead of integrating the jump to it.
        if (last_odom_pose) last_odom_pose = Eigen::Vector3d(x, y, theta);
        ++report.skipped_lines;
        continue;
      }
      const Timestamp time = Timestamp::from_seconds(seconds);
      if (last_odom_time && time <= *last_odom_time) {
        reject(fmt::format("odometry time {} s does not increase", seconds));
        continue;
      }
      if (last_odom_pose) {
        const Eigen::Vector3d& before = *last_odom_pose;
        const Eigen::Vector2d motion(x - before.x(), y - before.y());
        const double heading = std::cos(before.z()) * motion.x() + std::sin(before.z()) * motion.y();
        const double distance = heading < 0 ? -motion.norm() : motion.norm();
        const double turn = wrap_angle(theta - before.z());
        left += distance - turn * config.wheel_separation / 2;
        right += distance + turn * config.wheel_separation / 2;
      }
      last_odom_pose = Eigen::Vector3d(x, y, theta);
      last_odom_time = time;
      msgs::WheelOdometryMessage wheel;
      wheel.timestamp = time;
      wheel.frame_id = "base_link";
      wheel.left_distance = left;
      wheel.right_distance = right;
      wheel.wheel_separation = config.wheel_separation;
      log.odometry.push_back(std::move(wheel));
      ++report.odometry;
    } else {
      ++report.skipped_lines;
    }
  }
  if (report.scans == 0 && report.odometry == 0) return Error(fmt::format("{}: no FLASER or ODOM lines", path));
  return log;
}

Result<CarmenImportReport> import_carmen(const std::string& path, SensorLogWriter& writer, const CarmenImportConfig& config) {
  CarmenLog log;
  HANZO_ASSIGN_OR_RETURN(log, read_carmen(path, config));
  CarmenImportReport& report = log.report;
  // Both lists are in time order: merge them (scans first at equal times).
  auto write = [&](const std::string& topic, const auto& message) -> Status {
    // An invalid message (e.g. at time zero) is counted and left out; write errors end the import.
    const Status valid = msgs::validate(message);
    if (!valid) {
      if (report.rejected++ == 0) report.first_rejection = fmt::format("{}: {}", path, valid.error().message);
      return {};
    }
    return writer.write(topic, msgs::SensorMessage(message), topic.substr(topic.starts_with('/') ? 1 : 0));
  };
  size_t scan = 0, odometry = 0;
  while (scan < log.scans.size() || odometry < log.odometry.size()) {
    if (odometry == log.odometry.size() || (scan < log.scans.size() && log.scans[scan].timestamp <= log.odometry[odometry].timestamp)) {
      HANZO_RETURN_IF_ERROR(write(config.laser_topic, log.scans[scan++]));
    } else {
      HANZO_RETURN_IF_ERROR(write(config.odometry_topic, log.odometry[odometry++]));
    }
  }
  return report;
}

}  // namespace hanzo::fusion::io
