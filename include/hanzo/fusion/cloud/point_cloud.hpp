#pragma once
// PointCloud: the point type of every point-cloud algorithm in hanzo-fusion. One array per
// attribute (structure of arrays), so an algorithm touches only what it reads: registration
// reads positions and covariances, deskewing positions and times, nothing copies intensities
// it does not need.
//
// Positions are float metres in the cloud's frame (the sensor frame for a scan, the map frame
// for a map); 1 mm resolution up to 16 km from the origin. Optional attributes are either
// empty or hold exactly one value per point; `validate()` checks that invariant, algorithms
// assume it (a precondition, asserted).

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"

namespace hanzo::fusion::msgs {
struct PointCloudMessage;
}

namespace hanzo::fusion::cloud {

struct PointCloud {
  std::vector<Eigen::Vector3f> positions;   // m
  std::vector<float> intensities;           // sensor units (LiDAR reflectivity, often [0, 1] or [0, 255])
  std::vector<uint16_t> rings;              // laser (beam) index
  std::vector<float> times;                 // s, relative to the scan's timestamp (deskewing)
  std::vector<Eigen::Vector3f> normals;     // unit, from local geometry (estimate_normals)
  std::vector<Eigen::Matrix3f> covariances; // m^2, local shape (estimate_covariances)

  size_t size() const { return positions.size(); }
  bool empty() const { return positions.empty(); }
  bool has_intensities() const { return !intensities.empty(); }
  bool has_rings() const { return !rings.empty(); }
  bool has_times() const { return !times.empty(); }
  bool has_normals() const { return !normals.empty(); }
  bool has_covariances() const { return !covariances.empty(); }

  void reserve(size_t count);
  void clear();

  /// Ok when every optional attribute is empty or sized like positions and every position,
  /// intensity, time, normal and covariance is finite. The message names the first problem
  /// ("PointCloud.times: 12 values for 40 points", "PointCloud.positions[7].y: nan").
  Status validate() const;
};

/// The points `indices` of `cloud` (every attribute), in the order given. Indices must be valid.
PointCloud select(const PointCloud& cloud, const std::vector<uint32_t>& indices);

/// `cloud` expressed in another frame: positions p' = T p, normals and covariances rotated.
PointCloud transformed(const PointCloud& cloud, const SE3& T_new_old);
void transform_in_place(PointCloud& cloud, const SE3& T_new_old);

/// Drops points that are not finite (NaN returns of real drivers) and points closer than
/// `min_range` or farther than `max_range` from the origin (m; 0 disables each bound).
PointCloud crop_range(const PointCloud& cloud, double min_range, double max_range);

/// From a sensor message: positions, intensities, rings and per-point times (relative to the
/// message timestamp, s). Fails when the message is invalid (msgs::validate).
Result<PointCloud> from_message(const msgs::PointCloudMessage& message);

}  // namespace hanzo::fusion::cloud
