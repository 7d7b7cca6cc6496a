#pragma once
// The point map (spec, "LiDAR SLAM / Map representation: voxelized point cloud"): keyframe
// scans kept in their own sensor frame with their world poses, merged into one voxelized world
// cloud on demand. When the backend moves keyframes (a loop closure), set_poses() and the next
// cloud() rebuild the map from the corrected poses: no point is ever baked into a wrong place.
//
// Each voxel of the merged cloud becomes one point: the centroid of the points that fell in it,
// their mean intensity, and their spread as the per-point uncertainty
// (position_std = sqrt(trace(covariance) / 3), at least voxel_size / sqrt(12) / 2, the
// quantization of a voxel's centroid).
//
// Segmentation classes (optional): a keyframe may come with a class per point (the class of the
// segmentation pixel the point projects onto, msgs::kNoClass where no camera saw it), indices
// into the map's label table (class_index()), and later scans add their points' classes to it
// (add_class_votes: each votes for the keyframe point in its keyframe voxel). Each kept point
// counts the classes it was given (the three most frequent, Misra-Gries); each voxel of the
// merged map fuses its points' counts by a Bayesian update of a class histogram under a
// symmetric noise model: with segmentation_accuracy a and K classes, an observation of class l
// multiplies the odds of l against every other class by r = a (K - 1) / (1 - a), so after n_c
// observations of each class c,
//   P(c | observations) = r^n_c / sum_k r^n_k        (k over all K classes, unseen ones r^0 = 1).
// The voxel's class is the most observed one (ties: the lower index), with that posterior.
//
// Moving objects (moving_points): every keyframe's scan is a range image (scan_visibility.hpp)
// that tests the points of the later_keyframes keyframes before it, and the new keyframe's
// points are tested against the range images of the earlier_keyframes keyframes before it (a
// car arriving where the road was seen empty). Scans and keyframes are compared at the poses
// they were added with (the odometry's frame, in which they were registered to each other), not
// at corrected ones. Each point counts the scans that saw it and the scans that saw through its
// place; a point seen through at least min_seen_through times and more often than seen, or
// min_seen_through_in_a_row times since a scan last saw it, was on something that moved away (a
// passing car, a walking person): the merged map leaves it out. Counting both keeps what is
// merely hidden now and then, and what a scan saw through once by a pose error. Points are kept
// in their keyframes either way.

#include <cstddef>
#include <cstdint>
#include <array>
#include <deque>
#include <map>
#include <span>
#include <unordered_map>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/maps/scan_visibility.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

/// Removal of the points of moving objects by free-space evidence (point_map.hpp).
struct MovingPointConfig {
  bool enabled = true;
  VisibilityConfig visibility;
  int later_keyframes = 30;   ///< a keyframe's points are tested by the scans of this many later keyframes (>= 0)
  int earlier_keyframes = 8;  ///< and by the range images of this many earlier ones, kept in memory (>= 0)
  int min_seen_through = 2;   ///< scans (>= 1) that saw through a point before it can be left out
  int min_seen_through_in_a_row = 3;  ///< or that saw through it since any scan last saw it (>= 1)

  Status validate() const;
};

struct PointMapConfig {
  /// Voxel edge of the merged map (m). Spec defaults: 0.1 indoor, 0.5 outdoor.
  double voxel_size = 0.1;
  /// Keyframe clouds are downsampled to this voxel edge (m) when added, to bound memory;
  /// 0 uses voxel_size / 2.
  double keyframe_voxel_size = 0.0;
  /// Probability that a segmentation pixel's class is right, in (0, 1): the likelihood of the
  /// class histogram's Bayesian update.
  double segmentation_accuracy = 0.9;
  MovingPointConfig moving_points;

  Status validate() const;
};

class PointMap {
 public:
  explicit PointMap(const PointMapConfig& config);
  static Result<PointMap> create(const PointMapConfig& config);

  /// Adds (or replaces) keyframe `id`: `cloud_in_sensor_frame` seen from `T_world_sensor`, with
  /// an optional segmentation class per point (empty, or one per point: class_index() values
  /// or msgs::kNoClass). Rejects invalid clouds, non-finite poses and classes of another size
  /// or past the label table, changing nothing. With moving_points enabled, the scan's free
  /// space is tested against the points of earlier keyframes and theirs against its points.
  Status add_keyframe(uint64_t id, const SE3& T_world_sensor, const cloud::PointCloud& cloud_in_sensor_frame,
                      std::span<const uint16_t> point_classes = {});
  /// Moves keyframes (after optimization); every id must exist, else nothing changes.
  Status set_poses(const std::map<uint64_t, SE3>& T_world_sensor_by_id);
  Result<SE3> pose(uint64_t id) const;

  /// The voxelized world cloud (positions and, when every keyframe has them, intensities).
  /// Rebuilt only when keyframes changed since the last call.
  const cloud::PointCloud& cloud() const;
  /// Adds the segmentation classes of a later scan's points (sensor frame at T_world_sensor, a
  /// class per point) to keyframe `id`'s points in the same keyframe voxels (the others are
  /// dropped). Rejects an unknown id, a non-finite pose and classes of another size or past the
  /// label table, changing nothing.
  Status add_class_votes(uint64_t id, const SE3& T_world_sensor, const std::vector<Eigen::Vector3f>& points_in_sensor_frame,
                         std::span<const uint16_t> point_classes);
  /// The map as a FusionMap point layer (with per-point uncertainty, and classes with their
  /// posterior when any keyframe came with classes).
  msgs::PointLayer to_layer() const;

  /// The label table index of a segmentation class name, added when new (at most
  /// msgs::kNoClass - 1 names; kNoClass beyond).
  uint16_t class_index(std::string_view name);
  /// The label table (FusionMap::semantic_classes).
  const std::vector<std::string>& semantic_classes() const { return semantic_classes_; }

  std::size_t keyframe_count() const { return keyframes_.size(); }
  /// Keyframe points the merged map leaves out as on moving objects (moving_points).
  std::size_t moving_points_removed() const { return moving_points_removed_; }
  /// Bytes held by the keyframe clouds and the merged map.
  std::size_t memory_bytes() const;
  const PointMapConfig& config() const { return config_; }

 private:
  // The classes a kept point was given: the three most frequent (Misra-Gries: a fourth class
  // takes one count from each), counts saturating at 65535.
  struct PointClassVotes {
    static constexpr std::size_t kSlots = 3;
    std::array<uint16_t, kSlots> label{};
    std::array<uint16_t, kSlots> count{};
    void add(uint16_t class_index);
  };
  // How often scans saw a kept point and saw through its place (in all, and since it was last
  // seen), saturating at 255.
  struct PointSightings {
    uint8_t seen = 0;
    uint8_t seen_through = 0;
    uint8_t seen_through_in_a_row = 0;
  };
  struct Keyframe {
    SE3 T_world_sensor;
    // The pose it was added with: the free-space tests compare scans in the frame the odometry
    // registered them in (a later correction moves the old keyframes, not yet the new one).
    SE3 T_world_sensor_added;
    cloud::PointCloud cloud;                                 // sensor frame, downsampled
    std::vector<PointSightings> sightings;                   // empty (moving_points off) or one per cloud point
    std::vector<PointClassVotes> class_votes;                // empty or one per cloud point
    std::unordered_map<uint64_t, uint32_t> point_of_voxel;  // keyframe voxel -> cloud point (with class votes)
  };
  void rebuild() const;
  bool moved(const PointSightings& sightings) const;
  /// Counts what `image` (taken at T_world_scan, as added) says about keyframe's points.
  void test_points(Keyframe& keyframe, const RangeImage& image, const SE3& T_world_scan);
  /// The free-space tests of a new keyframe `id` and its scan's range image.
  void test_free_space(uint64_t id, std::span<const Eigen::Vector3f> scan_in_sensor_frame);
  double keyframe_voxel_size() const;
  Status check_classes(uint64_t id, std::size_t points, std::span<const uint16_t> point_classes) const;
  /// Each point (sensor frame, T_keyframe_sensor) with a class votes for its keyframe voxel's point.
  void vote(Keyframe& keyframe, const SE3& T_keyframe_sensor, const std::vector<Eigen::Vector3f>& points, std::span<const uint16_t> classes) const;

  PointMapConfig config_;
  std::map<uint64_t, Keyframe> keyframes_;
  std::deque<std::pair<uint64_t, RangeImage>> recent_images_;  // the newest keyframes' scans, oldest first
  std::size_t moving_points_removed_ = 0;
  mutable bool dirty_ = false;
  mutable cloud::PointCloud merged_;
  mutable std::vector<float> merged_std_;
  mutable std::vector<uint16_t> merged_classes_;
  mutable std::vector<float> merged_class_probability_;
  std::vector<std::string> semantic_classes_;
};

}  // namespace hanzo::fusion::maps
