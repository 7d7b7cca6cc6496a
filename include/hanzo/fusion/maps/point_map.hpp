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

#include <cstddef>
#include <cstdint>
#include <array>
#include <map>
#include <span>
#include <unordered_map>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

struct PointMapConfig {
  /// Voxel edge of the merged map (m). Spec defaults: 0.1 indoor, 0.5 outdoor.
  double voxel_size = 0.1;
  /// Keyframe clouds are downsampled to this voxel edge (m) when added, to bound memory;
  /// 0 uses voxel_size / 2.
  double keyframe_voxel_size = 0.0;
  /// Probability that a segmentation pixel's class is right, in (0, 1): the likelihood of the
  /// class histogram's Bayesian update.
  double segmentation_accuracy = 0.9;

  Status validate() const;
};

class PointMap {
 public:
  explicit PointMap(const PointMapConfig& config);
  static Result<PointMap> create(const PointMapConfig& config);

  /// Adds (or replaces) keyframe `id`: `cloud_in_sensor_frame` seen from `T_world_sensor`, with
  /// an optional segmentation class per point (empty, or one per point: class_index() values
  /// or msgs::kNoClass). Rejects invalid clouds, non-finite poses and classes of another size
  /// or past the label table, changing nothing.
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
  struct Keyframe {
    SE3 T_world_sensor;
    cloud::PointCloud cloud;                                 // sensor frame, downsampled
    std::vector<PointClassVotes> class_votes;                // empty or one per cloud point
    std::unordered_map<uint64_t, uint32_t> point_of_voxel;  // keyframe voxel -> cloud point (with class votes)
  };
  void rebuild() const;
  double keyframe_voxel_size() const;
  Status check_classes(uint64_t id, std::size_t points, std::span<const uint16_t> point_classes) const;
  /// Each point (sensor frame, T_keyframe_sensor) with a class votes for its keyframe voxel's point.
  void vote(Keyframe& keyframe, const SE3& T_keyframe_sensor, const std::vector<Eigen::Vector3f>& points, std::span<const uint16_t> classes) const;

  PointMapConfig config_;
  std::map<uint64_t, Keyframe> keyframes_;
  mutable bool dirty_ = false;
  mutable cloud::PointCloud merged_;
  mutable std::vector<float> merged_std_;
  mutable std::vector<uint16_t> merged_classes_;
  mutable std::vector<float> merged_class_probability_;
  std::vector<std::string> semantic_classes_;
};

}  // namespace hanzo::fusion::maps
