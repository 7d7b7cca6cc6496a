#include "hanzo/fusion/io/trajectory.hpp"

#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/core/yaml_value.hpp"
#include "text_lines.hpp"

namespace hanzo::fusion::io {

PoseMatrix pose_matrix(const SE2& pose) {
  PoseMatrix matrix = PoseMatrix::Identity();
  matrix.block<2, 2>(0, 0) = pose.rotation_matrix();
  matrix.block<2, 1>(0, 3) = pose.translation();
  return matrix;
}

SE2 planar_pose(const PoseMatrix& pose) { return SE2(std::atan2(pose(1, 0), pose(0, 0)), pose.block<2, 1>(0, 3)); }

double Trajectory::path_length() const {
  double length = 0.0;
  for (std::size_t i = 1; i < size(); ++i) length += (position(i) - position(i - 1)).norm();
  return length;
}

Trajectory Trajectory::subset(const std::vector<std::size_t>& indices) const {
  Trajectory out;
  out.timestamps.reserve(indices.size());
  out.poses.reserve(indices.size());
  for (std::size_t index : indices) {
    out.timestamps.push_back(timestamps[index]);
    out.poses.push_back(poses[index]);
  }
  return out;
}

void Trajectory::transform(const PoseMatrix& T_new_world, double scale) {
  for (PoseMatrix& pose : poses) {
    pose.block<3, 1>(0, 3) *= scale;
    pose = T_new_world * pose;
  }
}

Result<TrajectoryFormat> trajectory_format_from_name(const std::string& name) {
  if (name == "tum") return TrajectoryFormat::kTum;
  if (name == "kitti") return TrajectoryFormat::kKitti;
  if (name == "euroc") return TrajectoryFormat::kEuroc;
  return Error(fmt::format("unknown trajectory format '{}' (expected tum, kitti or euroc)", name));
}

const char* trajectory_format_name(TrajectoryFormat format) {
  switch (format) {
    case TrajectoryFormat::kTum: return "tum";
    case TrajectoryFormat::kKitti: return "kitti";
    case TrajectoryFormat::kEuroc: return "euroc";
  }
  return "?";
}

Result<Timestamp> parse_seconds(const std::string& text) {
  // Plain decimals ("123.456789") are converted digit by digit so that no precision is lost;
  // anything else (exponents) goes through double.
  std::size_t pos = 0;
  const bool negative = !text.empty() && text[0] == '-';
  if (negative || (!text.empty() && text[0] == '+')) pos = 1;
  const std::size_t digits_begin = pos;
  int64_t whole = 0;
  while (pos < text.size() && std::isdigit(static_cast<unsigned char>(text[pos])) && pos - digits_begin < 12) {
    whole = whole * 10 + (text[pos++] - '0');
  }
  int64_t fraction_ns = 0;
  bool plain = pos > digits_begin;
  if (plain && pos < text.size() && text[pos] == '.') {
    ++pos;
    int64_t scale = 100'000'000;
    while (pos < text.size() && std::isdigit(static_cast<unsigned char>(text[pos]))) {
      if (scale == 0) { plain = false; break; }  // more than 9 fractional digits: via double
      fraction_ns += (text[pos++] - '0') * scale;
      scale /= 10;
    }
  }
  // int64 nanoseconds hold +-292 years around 1970: a time beyond is refused, not wrapped.
  constexpr int64_t kLargestSeconds = 9'000'000'000;
  if (plain && pos == text.size()) {
    if (whole > kLargestSeconds) return Error(fmt::format("'{}' is beyond the times this format holds (years 1685-2255)", text));
    const int64_t ns = whole * 1'000'000'000 + fraction_ns;
    return Timestamp::from_nanoseconds(negative ? -ns : ns);
  }
  double seconds = 0.0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), seconds);
  if (error != std::errc() || end != text.data() + text.size() || !std::isfinite(seconds)) {
    return Error(fmt::format("'{}' is not a time in seconds", text));
  }
  if (std::abs(seconds) > static_cast<double>(kLargestSeconds)) return Error(fmt::format("'{}' is beyond the times this format holds (years 1685-2255)", text));
  return Timestamp::from_seconds(seconds);
}

std::string format_seconds(Timestamp timestamp) {
  const int64_t ns = timestamp.nanoseconds();
  const int64_t magnitude = ns < 0 ? -ns : ns;
  std::string text = fmt::format("{}{}.{:09d}", ns < 0 ? "-" : "", magnitude / 1'000'000'000, magnitude % 1'000'000'000);
  while (text.back() == '0') text.pop_back();
  if (text.back() == '.') text.pop_back();
  return text;
}

namespace {

PoseMatrix pose_from_quaternion(const Eigen::Vector3d& position, const Eigen::Quaterniond& q) {
  PoseMatrix pose = PoseMatrix::Identity();
  pose.block<3, 3>(0, 0) = q.normalized().toRotationMatrix();
  pose.block<3, 1>(0, 3) = position;
  return pose;
}

Result<PoseMatrix> parse_pose(const std::vector<double>& v, TrajectoryFormat format, const std::string& where) {
  for (double x : v) {
    if (!std::isfinite(x)) return Error(fmt::format("{}: non-finite number", where));
  }
  if (format == TrajectoryFormat::kKitti) {
    PoseMatrix pose = PoseMatrix::Identity();
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 4; ++col) pose(row, col) = v[static_cast<std::size_t>(row * 4 + col)];
    }
    return pose;
  }
  // TUM: x y z qx qy qz qw after the time; EuRoC: x y z qw qx qy qz after the time.
  const Eigen::Vector3d position(v[1], v[2], v[3]);
  const Eigen::Quaterniond q = format == TrajectoryFormat::kTum ? Eigen::Quaterniond(v[7], v[4], v[5], v[6])
                                                                 : Eigen::Quaterniond(v[4], v[5], v[6], v[7]);
  if (q.norm() < 1e-6) return Error(fmt::format("{}: zero quaternion", where));
  return pose_from_quaternion(position, q);
}

}  // namespace

Result<Trajectory> parse_trajectory(const std::string& text, TrajectoryFormat format, const std::string& source_name,
                                    const std::vector<Timestamp>* kitti_times) {
  Trajectory trajectory;
  const std::size_t columns = format == TrajectoryFormat::kKitti ? 12 : 8;
  std::size_t line_number = 0;
  std::istringstream stream(text);
  std::string line;
  while (std::getline(stream, line)) {
    ++line_number;
    const std::string where = fmt::format("{}:{}", source_name, line_number);
    const std::vector<std::string> fields = split_fields(line);
    if (fields.empty() || fields[0][0] == '#') continue;
    // EuRoC ground truth may carry 17 columns (velocity and biases follow the pose).
    const bool width_ok = fields.size() == columns || (format == TrajectoryFormat::kEuroc && fields.size() > columns);
    if (!width_ok) {
      return Error(fmt::format("{}: expected {} numbers for a {} pose, found {}", where, columns,
                               trajectory_format_name(format), fields.size()));
    }
    Timestamp stamp;
    if (format == TrajectoryFormat::kTum) {
      HANZO_ASSIGN_OR_RETURN(stamp, with_context(parse_seconds(fields[0]), where));
    } else if (format == TrajectoryFormat::kEuroc) {
      int64_t ns = 0;
      const auto [end, error] = std::from_chars(fields[0].data(), fields[0].data() + fields[0].size(), ns);
      if (error != std::errc() || end != fields[0].data() + fields[0].size()) {
        return Error(fmt::format("{}: '{}' is not a timestamp in integer nanoseconds", where, fields[0]));
      }
      stamp = Timestamp::from_nanoseconds(ns);
    }
    std::vector<double> numbers(columns);
    const std::size_t first_number = format == TrajectoryFormat::kKitti ? 0 : 1;  // TUM/EuRoC: time first
    for (std::size_t i = first_number; i < columns; ++i) {
      auto parsed = parse_double(fields[i]);
      if (!parsed) return Error(fmt::format("{}: column {}: '{}' is not a number", where, i + 1, fields[i]));
      numbers[i] = *parsed;
    }
    PoseMatrix pose;
    HANZO_ASSIGN_OR_RETURN(pose, parse_pose(numbers, format, where));
    if (format == TrajectoryFormat::kKitti) {
      const std::size_t index = trajectory.size();
      if (kitti_times != nullptr) {
        if (index >= kitti_times->size()) {
          return Error(fmt::format("{}: more poses than the {} times given", where, kitti_times->size()));
        }
        stamp = (*kitti_times)[index];
      } else {
        stamp = Timestamp::from_nanoseconds(static_cast<int64_t>(index) * 1'000'000'000);
      }
    }
    if (!trajectory.empty() && stamp == trajectory.timestamps.back()) {
      logger()->warn("{}: timestamp {} repeats the previous pose's; pose dropped", where, format_seconds(stamp));
      ++trajectory.dropped_duplicate_timestamps;
      continue;
    }
    if (!trajectory.empty() && stamp < trajectory.timestamps.back()) {
      return Error(fmt::format("{}: timestamp {} goes back in time (previous {})", where, format_seconds(stamp),
                               format_seconds(trajectory.timestamps.back())));
    }
    trajectory.timestamps.push_back(stamp);
    trajectory.poses.push_back(pose);
  }
  if (kitti_times != nullptr && kitti_times->size() != trajectory.size()) {
    return Error(fmt::format("{}: {} poses but {} times", source_name, trajectory.size(), kitti_times->size()));
  }
  if (trajectory.empty()) return Error(fmt::format("{}: no poses", source_name));
  return trajectory;
}

Result<Trajectory> read_trajectory(const std::string& path, TrajectoryFormat format,
                                   const std::optional<std::string>& kitti_times_path) {
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_file(path));
  if (!kitti_times_path) return parse_trajectory(text, format, path);
  if (format != TrajectoryFormat::kKitti) return Error("a times file is only used with the kitti format");
  std::string times_text;
  HANZO_ASSIGN_OR_RETURN(times_text, read_file(*kitti_times_path));
  std::vector<Timestamp> times;
  std::istringstream stream(times_text);
  std::string line;
  for (std::size_t line_number = 1; std::getline(stream, line); ++line_number) {
    const std::vector<std::string> fields = split_fields(line);
    if (fields.empty()) continue;
    Timestamp stamp;
    HANZO_ASSIGN_OR_RETURN(stamp, with_context(parse_seconds(fields[0]), fmt::format("{}:{}", *kitti_times_path, line_number)));
    times.push_back(stamp);
  }
  return parse_trajectory(text, format, path, &times);
}

std::string format_trajectory(const Trajectory& trajectory, TrajectoryFormat format) {
  std::string out;
  if (format == TrajectoryFormat::kTum) out += "# timestamp tx ty tz qx qy qz qw\n";
  if (format == TrajectoryFormat::kEuroc) {
    out += "#timestamp [ns], p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n";
  }
  for (std::size_t i = 0; i < trajectory.size(); ++i) {
    const PoseMatrix& pose = trajectory.poses[i];
    if (format == TrajectoryFormat::kKitti) {
      for (int row = 0; row < 3; ++row) {
        for (int col = 0; col < 4; ++col) {
          out += format_double(pose(row, col));
          out += (row == 2 && col == 3) ? '\n' : ' ';
        }
      }
      continue;
    }
    Eigen::Quaterniond q(Eigen::Matrix3d(pose.block<3, 3>(0, 0)));
    if (q.w() < 0) q.coeffs() *= -1.0;
    const Eigen::Vector3d p = pose.block<3, 1>(0, 3);
    if (format == TrajectoryFormat::kTum) {
      out += fmt::format("{} {} {} {} {} {} {} {}\n", format_seconds(trajectory.timestamps[i]), format_double(p.x()),
                         format_double(p.y()), format_double(p.z()), format_double(q.x()), format_double(q.y()),
                         format_double(q.z()), format_double(q.w()));
    } else {
      out += fmt::format("{},{},{},{},{},{},{},{}\n", trajectory.timestamps[i].nanoseconds(), format_double(p.x()),
                         format_double(p.y()), format_double(p.z()), format_double(q.w()), format_double(q.x()),
                         format_double(q.y()), format_double(q.z()));
    }
  }
  return out;
}

Status write_trajectory(const std::string& path, const Trajectory& trajectory, TrajectoryFormat format) {
  return yaml::write_file_atomically(path, format_trajectory(trajectory, format));
}

}  // namespace hanzo::fusion::io
