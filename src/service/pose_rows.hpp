#pragma once
// How a PoseEstimate becomes a trajectory row and back, shared by the storage backends:
// the tracking state as its name ("TRACKING"), the active sensors comma-separated, and the 6x6
// covariance as 36 little-endian doubles (row-major) or NULL.

#include <cstring>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/msgs/estimate_messages.hpp"

namespace hanzo::fusion::service::detail {

inline std::string encode_covariance(const msgs::Matrix6d& covariance) {
  std::string bytes(36 * sizeof(double), '\0');
  for (int row = 0; row < 6; ++row) {
    for (int column = 0; column < 6; ++column) {
      const double value = covariance(row, column);
      std::memcpy(bytes.data() + (row * 6 + column) * sizeof(double), &value, sizeof(double));
    }
  }
  return bytes;
}

/// nullopt unless `bytes` holds exactly 36 doubles.
inline std::optional<msgs::Matrix6d> decode_covariance(std::string_view bytes) {
  if (bytes.size() != 36 * sizeof(double)) return std::nullopt;
  msgs::Matrix6d covariance;
  for (int row = 0; row < 6; ++row) {
    for (int column = 0; column < 6; ++column) {
      double value = 0.0;
      std::memcpy(&value, bytes.data() + (row * 6 + column) * sizeof(double), sizeof(double));
      covariance(row, column) = value;
    }
  }
  return covariance;
}

inline msgs::TrackingState tracking_state_from_name(std::string_view name) {
  for (msgs::TrackingState state : {msgs::TrackingState::kInitializing, msgs::TrackingState::kTracking,
                                    msgs::TrackingState::kDegraded, msgs::TrackingState::kLost}) {
    if (msgs::to_string(state) == name) return state;
  }
  return msgs::TrackingState::kUnspecified;
}

inline std::string join_sensors(const std::vector<std::string>& sensors) {
  std::string text;
  for (const std::string& sensor : sensors) {
    if (!text.empty()) text += ',';
    text += sensor;
  }
  return text;
}

inline std::vector<std::string> split_sensors(std::string_view text) {
  std::vector<std::string> sensors;
  while (!text.empty()) {
    const std::size_t comma = text.find(',');
    sensors.emplace_back(text.substr(0, comma));
    if (comma == std::string_view::npos) break;
    text.remove_prefix(comma + 1);
  }
  return sensors;
}

}  // namespace hanzo::fusion::service::detail
