#pragma once
// Internal to msgs: the small conversions every message converter shares.

#include <cstdint>
#include <limits>
#include <string>
#include <string_view>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <fmt/format.h>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/v1/common.pb.h"

namespace hanzo::fusion::msgs::wire {

inline void write(const Eigen::Vector3d& vector, v1::Vector3* out) {
  out->set_x(vector.x());
  out->set_y(vector.y());
  out->set_z(vector.z());
}

inline void write(const Eigen::Quaterniond& q, v1::Quaternion* out) {
  out->set_w(q.w());
  out->set_x(q.x());
  out->set_y(q.y());
  out->set_z(q.z());
}

inline void write(const Pose& pose, v1::Pose* out) {
  write(pose.position, out->mutable_position());
  write(pose.orientation, out->mutable_orientation());
}

inline uint64_t write_time(Timestamp time) { return static_cast<uint64_t>(time.nanoseconds()); }

/// Wire timestamps are uint64; the engine's are int64 (up to the year 2262).
inline Result<Timestamp> read_time(uint64_t nanoseconds, std::string_view message, std::string_view field) {
  if (nanoseconds > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) {
    return Error{fmt::format("{}.{}: {} ns is beyond the year 2262 (int64 nanoseconds)", message, field, nanoseconds),
                 std::string(field)};
  }
  return Timestamp::from_nanoseconds(static_cast<int64_t>(nanoseconds));
}

}  // namespace hanzo::fusion::msgs::wire
