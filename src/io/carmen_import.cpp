#include "hanzo/fusion/io/carmen_import.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <sstream>

#include <fmt/format.h>
#include <zlib.h>

#include "hanzo/fusion/core/logging.hpp"
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

namespace {

// One FLASER or ODOM line as read, before its time is trusted.
struct CarmenRecord {
  bool scan = false;
  std::string where;            // file:line
  double seconds = 0.0;         // the ipc_timestamp as written
  double resolution = 0.0;      // s: the step of the last digit it was written with
  std::vector<Eigen::Vector3f> points;  // FLASER
  Eigen::Vector3d pose = Eigen::Vector3d::Zero();  // FLASER: x y theta; ODOM: x y theta
  bool anchor = false;          // ODOM at time 0: re-anchors the odometry (corrected logs)
};

// The step of the last significant digit of a number as written: "32.9068" -> 1e-4,
// "1.13486e+09" -> 1e4, "1134860000" -> 1.
double written_resolution(std::string_view text) {
  const std::size_t exponent_at = text.find_first_of("eE");
  const std::string_view mantissa = text.substr(0, exponent_at);
  const std::size_t point = mantissa.find('.');
  const int decimals = point == std::string_view::npos ? 0 : static_cast<int>(mantissa.size() - point - 1);
  int exponent = 0;
  if (exponent_at != std::string_view::npos) {
    std::string_view digits = text.substr(exponent_at + 1);
    if (digits.starts_with('+')) digits.remove_prefix(1);  // from_chars takes no '+'
    exponent = static_cast<int>(parse_double(digits).value_or(0.0));
  }
  return std::pow(10.0, exponent - decimals);
}

// Whether the times of one kind of line (scans or odometry) can be used: at most half of their
// steps do not increase (the lines of the others are left out later). `why` says what is wrong,
// with the precision they were written with when it is coarser than 10 ms (the usual cause).
bool times_usable(const std::vector<const CarmenRecord*>& records, std::string& why) {
  std::size_t not_increasing = 0;
  double finest = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < records.size(); ++i) {
    finest = std::min(finest, records[i]->resolution);
    if (i > 0 && records[i]->seconds <= records[i - 1]->seconds) ++not_increasing;
  }
  if (not_increasing <= std::max<std::size_t>(2, records.size() / 2)) return true;
  why = fmt::format("{} of {} times do not increase", not_increasing, records.size() - 1);
  if (finest > 0.01) why += fmt::format(" (written to {:g} s)", finest);
  return false;
}

// Times for the records of the kind `target` from those of the other kind (line order between
// them, evenly spaced), or from `period` past the ends.
void interpolate_times(std::vector<CarmenRecord>& records, bool target_scans, double period) {
  std::vector<std::size_t> targets;
  std::optional<std::size_t> previous;
  const auto place = [&](std::optional<std::size_t> next) {
    const std::size_t m = targets.size();
    for (std::size_t k = 0; k < m; ++k) {
      double& seconds = records[targets[k]].seconds;
      if (previous && next) {
        seconds = records[*previous].seconds + (records[*next].seconds - records[*previous].seconds) * double(k + 1) / double(m + 1);
      } else if (previous) {
        seconds = records[*previous].seconds + period * double(k + 1);
      } else if (next) {
        seconds = records[*next].seconds - period * double(m - k);
      }
    }
    targets.clear();
  };
  for (std::size_t i = 0; i < records.size(); ++i) {
    if (records[i].anchor) continue;
    if (records[i].scan == target_scans) {
      targets.push_back(i);
    } else {
      place(i);
      previous = i;
    }
  }
  place(std::nullopt);
}

}  // namespace

Result<CarmenLog> read_carmen(const std::string& path, const CarmenImportConfig& config) {
  if (!(config.nominal_scan_rate_hz > 0)) return Error("carmen import: nominal_scan_rate_hz must be > 0");
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_maybe_gzip(path));
  CarmenLog log;
  CarmenImportReport& report = log.report;
  // 1. Every FLASER and ODOM line as written.
  std::vector<CarmenRecord> records;
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
    CarmenRecord record;
    record.where = where;
    std::size_t time_field = 0;
    if (fields[0] == "FLASER") {
      double count_value = 0;
      HANZO_ASSIGN_OR_RETURN(count_value, number(1));
      const auto n = static_cast<std::size_t>(count_value);
      if (count_value < 2 || count_value != static_cast<double>(n) || fields.size() < n + 11) {
        return Error(fmt::format("{}: FLASER with {} beams needs {} fields, has {}", where, fields[1], n + 11, fields.size()));
      }
      record.scan = true;
      for (int axis = 0; axis < 3; ++axis) HANZO_ASSIGN_OR_RETURN(record.pose[axis], number(n + 2 + static_cast<std::size_t>(axis)));
      time_field = n + 8;
      const double step = M_PI / static_cast<double>(n);
      for (std::size_t i = 0; i < n; ++i) {
        double range = 0;
        HANZO_ASSIGN_OR_RETURN(range, number(2 + i));
        if (range <= 0.0 || range >= config.max_range) continue;
        const double angle = -M_PI / 2 + step * static_cast<double>(i);
        record.points.emplace_back(static_cast<float>(range * std::cos(angle)), static_cast<float>(range * std::sin(angle)), 0.0F);
      }
    } else if (fields[0] == "ODOM") {
      // Read for their times even when not imported (no wheel separation); a malformed one is
      // an error only when imported.
      time_field = 7;
      Status readable = ok_status();
      for (std::size_t field : {std::size_t{1}, std::size_t{2}, std::size_t{3}, time_field}) {
        if (Result<double> value = number(field); !value) {
          readable = value.error();
          break;
        } else if (field <= 3) {
          record.pose[static_cast<int>(field - 1)] = *value;
        }
      }
      if (!readable) {
        if (config.wheel_separation > 0.0) return readable.error();
        ++report.skipped_lines;
        continue;
      }
    } else {
      ++report.skipped_lines;  // NEFF, PARAM, unknown messages
      continue;
    }
    HANZO_ASSIGN_OR_RETURN(record.seconds, number(time_field));
    record.resolution = written_resolution(fields[time_field]);
    // The "corrected" Radish logs put the corrected pose after each scan as an ODOM line at
    // time 0: it re-anchors the odometry instead of being integrated.
    record.anchor = !record.scan && record.seconds == 0.0;
    records.push_back(std::move(record));
  }

  // 2. Times that cannot be used (duplicates, written too coarsely) are rebuilt from the other
  // kind's times and the line order, or from the nominal scan rate.
  std::vector<const CarmenRecord*> scans, odometry;
  for (const CarmenRecord& record : records) {
    if (!record.anchor) (record.scan ? scans : odometry).push_back(&record);
  }
  std::string scans_why, odometry_why;
  bool scans_usable = times_usable(scans, scans_why);
  const bool odometry_usable = times_usable(odometry, odometry_why);
  const double period = 1.0 / config.nominal_scan_rate_hz;
  if (!scans_usable || !odometry_usable) {
    std::string source;
    if (!scans_usable && (!odometry_usable || odometry.size() < 2)) {
      const double start = std::max(1.0, scans.empty() ? 1.0 : scans.front()->seconds);
      std::size_t index = 0;
      for (CarmenRecord& record : records) {
        if (record.scan) record.seconds = start + period * static_cast<double>(index++);
      }
      scans_usable = true;
      source = fmt::format("line order at the nominal {:g} Hz scan rate", config.nominal_scan_rate_hz);
    }
    if (!scans_usable) {
      interpolate_times(records, true, period);
      source = "the ODOM lines' times and the line order";
    }
    if (!odometry_usable) {
      interpolate_times(records, false, period);
      if (source.empty()) source = "the scans' times and the line order";
    }
    report.timestamps_reconstructed = true;
    report.timestamp_warning = fmt::format("{}: {}{}{}; times rebuilt from {}", path, scans_why.empty() ? "" : "scan times: " + scans_why,
                                           !scans_why.empty() && !odometry_why.empty() ? "; " : "",
                                           odometry_why.empty() ? "" : "odometry times: " + odometry_why, source);
    logger()->warn("{}", report.timestamp_warning);
  }

  // 3. Messages in line order; lines whose time still does not increase are left out.
  std::optional<Timestamp> last_scan_time, last_odom_time;
  std::optional<Eigen::Vector3d> last_odom_pose;
  double left = 0.0, right = 0.0;
  for (CarmenRecord& record : records) {
    auto reject = [&](const std::string& reason) {
      if (report.rejected++ == 0) report.first_rejection = fmt::format("{}: {}", record.where, reason);
    };
    if (!record.scan && config.wheel_separation <= 0.0) {
      ++report.skipped_lines;  // odometry not imported
      continue;
    }
    if (record.anchor) {
      if (last_odom_pose) last_odom_pose = record.pose;
      ++report.skipped_lines;
      continue;
    }
    const Timestamp time = Timestamp::from_seconds(record.seconds);
    if (record.scan) {
      if (last_scan_time && time <= *last_scan_time) {
        reject(fmt::format("scan time {} s does not increase", record.seconds));
        continue;
      }
      if (record.points.empty()) {
        reject("scan without any return");
        continue;
      }
      msgs::PointCloudMessage scan;
      scan.timestamp = time;
      scan.frame_id = "laser";
      scan.points = std::move(record.points);
      last_scan_time = time;
      report.scan_poses.timestamps.push_back(time);
      report.scan_poses.poses.push_back(pose_matrix(SE2(record.pose.z(), record.pose.head<2>())));
      log.scans.push_back(std::move(scan));
      ++report.scans;
      continue;
    }
    if (last_odom_time && time <= *last_odom_time) {
      reject(fmt::format("odometry time {} s does not increase", record.seconds));
      continue;
    }
    if (last_odom_pose) {
      const Eigen::Vector3d& before = *last_odom_pose;
      const Eigen::Vector2d motion = record.pose.head<2>() - before.head<2>();
      const double heading = std::cos(before.z()) * motion.x() + std::sin(before.z()) * motion.y();
      const double distance = heading < 0 ? -motion.norm() : motion.norm();
      const double turn = wrap_angle(record.pose.z() - before.z());
      left += distance - turn * config.wheel_separation / 2;
      right += distance + turn * config.wheel_separation / 2;
    }
    last_odom_pose = record.pose;
    last_odom_time = time;
    msgs::WheelOdometryMessage wheel;
    wheel.timestamp = time;
    wheel.frame_id = "base_link";
    wheel.left_distance = left;
    wheel.right_distance = right;
    wheel.wheel_separation = config.wheel_separation;
    log.odometry.push_back(std::move(wheel));
    ++report.odometry;
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
