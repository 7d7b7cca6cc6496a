#pragma once
// One rotation of a spinning LiDAR assembled from its packets' blocks (Velodyne, Hesai): points
// in the LiDAR frame with intensity (0-255 scaled to [0, 1]), ring and time. A block whose
// azimuth, measured from the cut angle, is smaller than the previous block's starts the next
// rotation; the message's time is its earliest point's.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::drivers {

class RotationFrame {
 public:
  RotationFrame(std::string frame_id, double cut_angle_deg) : frame_id_(std::move(frame_id)), cut_angle_deg_(cut_angle_deg) {
    frame_.frame_id = frame_id_;
  }

  /// A block at `azimuth_deg`: the rotation before it goes to `frames` when the azimuth wrapped
  /// past the cut angle. Returns the points emitted (0: none).
  std::size_t start_block(double azimuth_deg, std::vector<msgs::PointCloudMessage>& frames) {
    const double from_cut = std::fmod(std::fmod(azimuth_deg - cut_angle_deg_, 360.0) + 360.0, 360.0);
    const bool wrapped = last_from_cut_ && from_cut < *last_from_cut_;
    last_from_cut_ = from_cut;
    return wrapped ? emit(frames) : 0;
  }

  void add(const Eigen::Vector3f& point, uint8_t intensity, uint32_t ring, Timestamp time) {
    frame_.points.push_back(point);
    frame_.intensities.push_back(static_cast<float>(intensity) / 255.0F);
    frame_.ring_ids.push_back(ring);
    frame_.point_timestamps.push_back(time);
  }

  /// The rotation so far (if it has points) into `frames`; returns its points (0: none).
  std::size_t emit(std::vector<msgs::PointCloudMessage>& frames) {
    const std::size_t size = frame_.points.size();
    if (size == 0) return 0;
    frame_.timestamp = *std::min_element(frame_.point_timestamps.begin(), frame_.point_timestamps.end());
    frames.push_back(std::move(frame_));
    frame_ = msgs::PointCloudMessage();
    frame_.frame_id = frame_id_;
    // The next rotation is about as large: one allocation per array instead of a doubling series.
    frame_.points.reserve(size + size / 8);
    frame_.intensities.reserve(size + size / 8);
    frame_.ring_ids.reserve(size + size / 8);
    frame_.point_timestamps.reserve(size + size / 8);
    return size;
  }

 private:
  std::string frame_id_;
  double cut_angle_deg_;
  msgs::PointCloudMessage frame_;
  std::optional<double> last_from_cut_;  // of the previous block, degrees past the cut angle
};

}  // namespace hanzo::fusion::drivers
