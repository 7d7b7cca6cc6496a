#include "hanzo/fusion/io/csv_export.hpp"

#include <fmt/format.h>

#include "hanzo/fusion/core/yaml_value.hpp"

namespace hanzo::fusion::io {
namespace {

template <typename... T>
void row(std::string& out, int64_t time, const T&... values) {
  out += std::to_string(time);
  ((out += ',', out += values), ...);
  out += '\n';
}

std::string number(double value) { return format_double(value); }
// Shortest text that reads back as the same float (hdop, radar fields are float on the wire).
std::string number(float value) { return fmt::format("{}", value); }

struct HeaderOf {
  std::string operator()(const msgs::ImuMessage&) const { return "timestamp_ns,ax,ay,az,wx,wy,wz\n"; }
  std::string operator()(const msgs::GnssMessage&) const {
    return "timestamp_ns,latitude,longitude,altitude,fix_type,satellites_used,hdop\n";
  }
  std::string operator()(const msgs::WheelOdometryMessage&) const {
    return "timestamp_ns,left_distance,right_distance,wheel_separation\n";
  }
  std::string operator()(const msgs::RadarMessage&) const {
    return "timestamp_ns,target,range,azimuth,elevation,radial_velocity,rcs\n";
  }
  std::string operator()(const msgs::RangeMessage&) const { return "timestamp_ns,range,min_range,max_range,field_of_view,variance\n"; }
  std::string operator()(const msgs::DetectionsMessage&) const { return "timestamp_ns,detection,class_name,score,x_min,y_min,x_max,y_max,track_id\n"; }
  std::string operator()(const msgs::PointCloudMessage&) const {
    return "timestamp_ns,points,has_intensity,has_ring,has_point_time\n";
  }
  std::string operator()(const msgs::ImageMessage&) const { return "timestamp_ns,width,height,encoding\n"; }
  std::string operator()(const msgs::PoseEstimate&) const { return "timestamp_ns,x,y,z,qw,qx,qy,qz,vx,vy,vz\n"; }
  std::string operator()(const msgs::SensorMessage& m) const { return std::visit(*this, m); }
};

struct RowsOf {
  std::string& out;
  void operator()(const msgs::ImuMessage& m) const {
    const auto& a = m.linear_acceleration;
    const auto& w = m.angular_velocity;
    row(out, m.timestamp.nanoseconds(), number(a.x()), number(a.y()), number(a.z()), number(w.x()), number(w.y()), number(w.z()));
  }
  void operator()(const msgs::GnssMessage& m) const {
    row(out, m.timestamp.nanoseconds(), number(m.latitude), number(m.longitude), number(m.altitude),
        std::string(msgs::to_string(m.fix_type)), std::to_string(m.satellites_used), number(m.hdop));
  }
  void operator()(const msgs::WheelOdometryMessage& m) const {
    row(out, m.timestamp.nanoseconds(), number(m.left_distance), number(m.right_distance), number(m.wheel_separation));
  }
  void operator()(const msgs::RadarMessage& m) const {
    for (std::size_t i = 0; i < m.targets.size(); ++i) {
      const msgs::RadarTarget& t = m.targets[i];
      row(out, m.timestamp.nanoseconds(), std::to_string(i), number(t.range), number(t.azimuth), number(t.elevation),
          number(t.radial_velocity), number(t.rcs));
    }
  }
  void operator()(const msgs::RangeMessage& m) const {
    row(out, m.timestamp.nanoseconds(), number(m.range), number(m.min_range), number(m.max_range), number(m.field_of_view), number(m.variance));
  }
  void operator()(const msgs::DetectionsMessage& m) const {
    for (std::size_t i = 0; i < m.detections.size(); ++i) {
      const msgs::Detection2D& d = m.detections[i];
      row(out, m.timestamp.nanoseconds(), std::to_string(i), d.class_name, number(d.score), number(d.x_min), number(d.y_min), number(d.x_max),
          number(d.y_max), std::to_string(d.track_id));
    }
  }
  void operator()(const msgs::PointCloudMessage& m) const {
    row(out, m.timestamp.nanoseconds(), std::to_string(m.points.size()), std::to_string(!m.intensities.empty()),
        std::to_string(!m.ring_ids.empty()), std::to_string(!m.point_timestamps.empty()));
  }
  void operator()(const msgs::ImageMessage& m) const {
    row(out, m.timestamp.nanoseconds(), std::to_string(m.width), std::to_string(m.height), std::string(msgs::to_string(m.encoding)));
  }
  void operator()(const msgs::PoseEstimate& m) const {
    const auto& p = m.T_world_body.position;
    const auto& q = m.T_world_body.orientation;
    const auto& v = m.velocity;
    row(out, m.timestamp.nanoseconds(), number(p.x()), number(p.y()), number(p.z()), number(q.w()), number(q.x()),
        number(q.y()), number(q.z()), number(v.x()), number(v.y()), number(v.z()));
  }
  void operator()(const msgs::SensorMessage& m) const { std::visit(*this, m); }
};

}  // namespace

std::string csv_header(const LogEntry& entry) { return std::visit(HeaderOf{}, entry.message); }

void append_csv_rows(const LogEntry& entry, std::string& out) { std::visit(RowsOf{out}, entry.message); }

}  // namespace hanzo::fusion::io
