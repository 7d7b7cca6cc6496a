#pragma once
// Scan Context place recognition for 3D LiDAR loop closure (Kim & Kim, "Scan Context:
// Egocentric Spatial Descriptor for Place Recognition within 3D Point Cloud Map", IROS 2018).
//
// Descriptor (sec. III-A): the scan's points, in the sensor frame with z up, binned by range
// into num_rings rings up to max_range and by azimuth into num_sectors sectors; each bin holds
// the highest point's height above the sensor plus height_offset (0 when empty), so the
// descriptor describes the surroundings' shape, independent of point density.
// Ring key (sec. III-C, eq. 5): per ring, the fraction of non-empty bins: rotation invariant, so
// the nearest ring keys (a linear scan of num_rings numbers per entry) preselect candidates
// without knowing the yaw.
// Distance (eq. 6-7): the smallest, over column shifts (yaw hypotheses), mean cosine distance
// between corresponding non-empty sector columns; the best shift gives the yaw between the two
// scans (T_candidate_query yaw = shift x 360 / num_sectors degrees, counter-clockwise).
//
// Use: describe every keyframe, query the database with a new keyframe's descriptor (recent
// keyframes excluded), verify a candidate by registration started from the returned yaw.
// Frames and units: sensor frame, metres, radians.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::lidar {

struct ScanContextConfig {
  int num_rings = 20;           ///< Kim & Kim: 20
  int num_sectors = 60;         ///< 6 deg each
  double max_range = 80.0;      ///< m
  double height_offset = 2.0;   ///< m added to heights (a sensor about 2 m above the ground)
  int candidates = 10;          ///< ring-key nearest candidates compared by full distance
  double max_distance = 0.2;    ///< a match needs a descriptor distance below this (paper: 0.1-0.2)
  int exclude_recent = 50;      ///< the most recently added entries are not loop candidates

  Status validate() const;
};

struct ScanContext {
  int num_rings = 0, num_sectors = 0;
  Eigen::MatrixXd bins;         ///< num_rings x num_sectors, m (0: empty)
  Eigen::VectorXd ring_key;     ///< num_rings, fraction of occupied bins per ring
};

/// The descriptor of a scan (sensor frame). Non-finite points are ignored; fails on an invalid
/// config or a scan with no point within max_range.
Result<ScanContext> make_scan_context(const cloud::PointCloud& scan, const ScanContextConfig& config = {});

struct ScanContextDistance {
  double distance = 1.0;  ///< in [0, 1]: 0 identical, 1 unrelated
  int shift = 0;          ///< sectors the query is rotated by to match
  double yaw = 0.0;       ///< rad, the query's heading in the candidate's frame
};
/// Eq. 6-7 over all column shifts. Both descriptors must have the same size.
Result<ScanContextDistance> scan_context_distance(const ScanContext& query, const ScanContext& candidate);

struct ScanContextMatch {
  uint64_t id = 0;               ///< the id the candidate was added with
  ScanContextDistance distance;
};

/// Descriptors of past keyframes, searched by ring key then by full distance.
class ScanContextDatabase {
 public:
  explicit ScanContextDatabase(ScanContextConfig config = {});
  /// Adds a keyframe's descriptor under `id`. Fails when the size differs from the config's.
  Status add(uint64_t id, ScanContext descriptor);
  /// Removes the newest entry (no-op when empty).
  void remove_newest() {
    if (!entries_.empty()) entries_.pop_back();
  }
  /// The best match among all but the exclude_recent newest entries, if its distance is below
  /// max_distance.
  Result<std::optional<ScanContextMatch>> query(const ScanContext& descriptor) const;
  size_t size() const { return entries_.size(); }

 private:
  struct Entry {
    uint64_t id;
    ScanContext descriptor;
  };
  ScanContextConfig config_;
  std::vector<Entry> entries_;
};

}  // namespace hanzo::fusion::lidar
