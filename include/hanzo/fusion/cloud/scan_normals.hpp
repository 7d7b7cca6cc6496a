#pragma once
// Surface normals of a spinning-LiDAR scan from its range-image structure: each point's
// neighbours are the points within column_window columns on its own ring and the rings
// directly above and below (not its k nearest points in space, which for a 16- or 32-beam
// sensor mostly lie on the same ring: a line, whose plane is undetermined). Neighbours farther
// than min(max_neighbour_distance, max_relative_distance x range) are left out (depth
// discontinuities). The point gets the normal of the plane through them when they include
// another ring (two points or more), number at least min_neighbours and are planar (smallest covariance eigenvalue
// below plane_ratio x the middle one); otherwise a zero normal.
//
// The range image: row = ring, column = azimuth bin of atan2(y, x) in the sensor frame
// (azimuth_bins columns; 0: the largest point count of any ring, about the firings per
// revolution). Normals are unit vectors pointing toward the sensor origin, in the cloud's frame.
// Needs ring indices: a cloud without rings gets zero normals everywhere.

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/cloud/point_cloud.hpp"

namespace hanzo::fusion::cloud {

struct ScanNormalConfig {
  int azimuth_bins = 0;                ///< >= 0
  /// Columns on each side; 0: about one ring spacing (the median elevation step between
  /// adjacent rings, in azimuth bins), sampled at up to 4 columns per side.
  int column_window = 0;
  double max_neighbour_distance = 2.0; ///< m
  double max_relative_distance = 0.5;  ///< of the point's range
  int min_neighbours = 4;              ///< >= 3
  double plane_ratio = 0.1;
};

/// The range image of one scan, answering normal queries for any of its points (for callers
/// that need normals of a few points only, e.g. those a map accepts). Holds a reference to the
/// scan: it must outlive the object.
class ScanNormalEstimator {
 public:
  /// Builds the range image on up to num_threads threads (see parallel.hpp); the same image on
  /// any number.
  ScanNormalEstimator(const PointCloud& scan, const ScanNormalConfig& config = {}, int num_threads = 1);
  /// The unit normal of point `index` (facing the sensor), or zero; see above.
  Eigen::Vector3f normal(std::size_t index) const;
  /// True when no point on the same ring within two columns or on the adjacent rings within
  /// one column lies within max_gap (m) of point `index`: a lone return, such as a rain drop or
  /// fog in front of a sensor whose neighbouring rays see a wall metres behind. False for a
  /// cloud without rings (nothing to tell).
  bool isolated(std::size_t index, float max_gap) const;

 private:
  std::size_t cell_index(int ring, int column) const {
    return static_cast<std::size_t>(column) * static_cast<std::size_t>(rings_) + static_cast<std::size_t>(ring);
  }
  /// A column index up to one turn outside [0, columns_) brought back into it.
  int wrapped_column(int column) const { return column < 0 ? column + columns_ : column >= columns_ ? column - columns_ : column; }

  const PointCloud& scan_;
  ScanNormalConfig config_;
  int rings_ = 0;
  int columns_ = 0;
  int window_ = 1;
  std::vector<uint32_t> image_;   // column-major, kEmpty where no point
  std::vector<int> column_of_;
};

/// One normal per point of `scan` (zero where none); see above.
std::vector<Eigen::Vector3f> estimate_scan_normals(const PointCloud& scan, const ScanNormalConfig& config = {});
/// The normals of the points `indices` only (one per index, same order), the neighbours still
/// taken from the whole scan: for callers that keep a subset (a downsampled map).
std::vector<Eigen::Vector3f> estimate_scan_normals(const PointCloud& scan, const std::vector<uint32_t>& indices,
                                                   const ScanNormalConfig& config = {});

}  // namespace hanzo::fusion::cloud
