#include "hanzo/fusion/maps/point_map.hpp"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include <fmt/format.h>

#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "class_votes.hpp"

namespace hanzo::fusion::maps {
namespace {

// The posterior of `votes`' most observed class among class_count classes (point_map.hpp).
float class_posterior(const ClassVotes& votes, std::size_t class_count, double accuracy) {
  const auto [best, best_count] = votes.most();
  const double classes = static_cast<double>(std::max<std::size_t>(class_count, 2));
  const double log_ratio = std::log(accuracy * (classes - 1.0) / (1.0 - accuracy));
  // sum_k r^(n_k - n_best): observed classes, then the unseen ones (r^(0 - n_best) each).
  double sum = 0.0;
  for (const auto& [label, count] : votes.counts) sum += std::exp(log_ratio * (static_cast<double>(count) - static_cast<double>(best_count)));
  sum += (classes - static_cast<double>(votes.counts.size())) * std::exp(-log_ratio * static_cast<double>(best_count));
  return static_cast<float>(1.0 / sum);
}

}  // namespace

Status MovingPointConfig::validate() const {
  HANZO_RETURN_IF_ERROR(visibility.validate());
  if (later_keyframes < 0 || earlier_keyframes < 0) {
    return Error{fmt::format("moving_points: later_keyframes and earlier_keyframes must be >= 0, got {} and {}", later_keyframes, earlier_keyframes),
                 "later_keyframes"};
  }
  for (const auto& [value, name] : {std::pair{min_seen_through, "min_seen_through"}, std::pair{min_seen_through_in_a_row, "min_seen_through_in_a_row"}}) {
    if (value < 1 || value > 255) return Error{fmt::format("moving_points.{}: must lie in [1, 255], got {}", name, value), name};
  }
  return ok_status();
}

Status PointMapConfig::validate() const {
  if (!(std::isfinite(voxel_size) && voxel_size > 0.0)) {
    return Error{fmt::format("point_map.voxel_size: must be a positive number of meters, got {}", voxel_size), "voxel_size"};
  }
  if (!(std::isfinite(keyframe_voxel_size) && keyframe_voxel_size >= 0.0)) {
    return Error{fmt::format("point_map.keyframe_voxel_size: must be >= 0 meters, got {}", keyframe_voxel_size),
                 "keyframe_voxel_size"};
  }
  if (!(segmentation_accuracy > 0.0 && segmentation_accuracy < 1.0)) {
    return Error{fmt::format("point_map.segmentation_accuracy: must lie in (0, 1), got {}", segmentation_accuracy), "segmentation_accuracy"};
  }
  if (moving_points.enabled) HANZO_RETURN_IF_ERROR(with_context(moving_points.validate(), "point_map"));
  return ok_status();
}

PointMap::PointMap(const PointMapConfig& config) : config_(config) {}

Result<PointMap> PointMap::create(const PointMapConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  return PointMap(config);
}

Status PointMap::check_classes(uint64_t id, std::size_t points, std::span<const uint16_t> point_classes) const {
  if (!point_classes.empty() && point_classes.size() != points) {
    return Error{fmt::format("keyframe {}: {} classes for {} points", id, point_classes.size(), points), "point_classes"};
  }
  for (const uint16_t label : point_classes) {
    if (label != msgs::kNoClass && label >= semantic_classes_.size()) {
      return Error{fmt::format("keyframe {}: class {} past the label table's {} classes", id, label, semantic_classes_.size()), "point_classes"};
    }
  }
  return ok_status();
}

Status PointMap::add_keyframe(uint64_t id, const SE3& T_world_sensor, const cloud::PointCloud& cloud_in_sensor_frame,
                              std::span<const uint16_t> point_classes) {
  if (!T_world_sensor.matrix().allFinite()) return Error{fmt::format("keyframe {}: pose is not finite", id), "T_world_sensor"};
  HANZO_RETURN_IF_ERROR(with_context(cloud_in_sensor_frame.validate(), fmt::format("keyframe {}", id)));
  HANZO_RETURN_IF_ERROR(check_classes(id, cloud_in_sensor_frame.size(), point_classes));
  cloud::PointCloud kept = cloud::voxel_downsample(cloud_in_sensor_frame, keyframe_voxel_size());
  // Only what the map uses.
  kept.rings.clear();
  kept.times.clear();
  kept.normals.clear();
  kept.covariances.clear();
  Keyframe& keyframe = keyframes_[id];
  for (const PointSightings& replaced : keyframe.sightings) moving_points_removed_ -= moved(replaced) ? 1 : 0;
  keyframe = Keyframe{T_world_sensor, T_world_sensor, std::move(kept), {}, {}, {}};
  if (!point_classes.empty()) vote(keyframe, SE3(), cloud_in_sensor_frame.positions, point_classes);
  if (config_.moving_points.enabled) {
    keyframe.sightings.resize(keyframe.cloud.size());
    test_free_space(id, cloud_in_sensor_frame.positions);
  }
  dirty_ = true;
  return ok_status();
}

bool PointMap::moved(const PointSightings& sightings) const {
  const MovingPointConfig& config = config_.moving_points;
  return sightings.seen_through_in_a_row >= config.min_seen_through_in_a_row ||
         (sightings.seen_through >= config.min_seen_through && sightings.seen_through > sightings.seen);
}

void PointMap::test_points(Keyframe& keyframe, const RangeImage& image, const SE3& T_world_scan) {
  const SE3 T_scan_keyframe = T_world_scan.inverse() * keyframe.T_world_sensor_added;
  const Eigen::Matrix3f rotation = T_scan_keyframe.rotation().matrix().cast<float>();
  const Eigen::Vector3f translation = T_scan_keyframe.translation().cast<float>();
  for (std::size_t i = 0; i < keyframe.cloud.size(); ++i) {
    PointSightings& sightings = keyframe.sightings[i];
    const Visibility visibility = image.classify(rotation * keyframe.cloud.positions[i] + translation);
    if (visibility != Visibility::kSeen && visibility != Visibility::kSeenThrough) continue;
    const bool was_moved = moved(sightings);
    const bool seen = visibility == Visibility::kSeen;
    uint8_t& count = seen ? sightings.seen : sightings.seen_through;
    if (count < UINT8_MAX) ++count;
    if (seen) {
      sightings.seen_through_in_a_row = 0;
    } else if (sightings.seen_through_in_a_row < UINT8_MAX) {
      ++sightings.seen_through_in_a_row;
    }
    const bool is_moved = moved(sightings);
    if (is_moved != was_moved) moving_points_removed_ = is_moved ? moving_points_removed_ + 1 : moving_points_removed_ - 1;
  }
}

void PointMap::test_free_space(uint64_t id, std::span<const Eigen::Vector3f> scan_in_sensor_frame) {
  const MovingPointConfig& config = config_.moving_points;
  std::erase_if(recent_images_, [id](const auto& entry) { return entry.first == id; });
  Keyframe& added = keyframes_.at(id);
  RangeImage image(config.visibility, scan_in_sensor_frame, added.T_world_sensor_added.rotation().matrix().transpose() * Eigen::Vector3d::UnitZ());
  // The later keyframes' points tested by this scan...
  auto earlier = keyframes_.find(id);
  for (int tested = 0; tested < config.later_keyframes && earlier != keyframes_.begin(); ++tested) {
    --earlier;
    test_points(earlier->second, image, added.T_world_sensor_added);
  }
  // ... and this keyframe's points by the scans before it.
  for (const auto& [scan_id, scan_image] : recent_images_) {
    if (const auto scan = keyframes_.find(scan_id); scan != keyframes_.end()) test_points(added, scan_image, scan->second.T_world_sensor_added);
  }
  if (config.earlier_keyframes == 0) return;
  recent_images_.emplace_back(id, std::move(image));
  while (recent_images_.size() > static_cast<std::size_t>(config.earlier_keyframes)) recent_images_.pop_front();
}

Status PointMap::add_class_votes(uint64_t id, const SE3& T_world_sensor, const std::vector<Eigen::Vector3f>& points_in_sensor_frame,
                                 std::span<const uint16_t> point_classes) {
  const auto found = keyframes_.find(id);
  if (found == keyframes_.end()) return Error{fmt::format("class votes: no keyframe {}", id), "id"};
  if (!T_world_sensor.matrix().allFinite()) return Error{fmt::format("keyframe {}: class votes from a pose that is not finite", id), "T_world_sensor"};
  HANZO_RETURN_IF_ERROR(check_classes(id, points_in_sensor_frame.size(), point_classes));
  if (point_classes.empty()) return ok_status();
  vote(found->second, found->second.T_world_sensor.inverse() * T_world_sensor, points_in_sensor_frame, point_classes);
  dirty_ = true;
  return ok_status();
}

void PointMap::vote(Keyframe& keyframe, const SE3& T_keyframe_sensor, const std::vector<Eigen::Vector3f>& points, std::span<const uint16_t> classes) const {
  const auto inverse_voxel = static_cast<float>(1.0 / keyframe_voxel_size());
  if (keyframe.class_votes.empty()) {
    // Each kept point is its voxel's centroid, inside the voxel.
    keyframe.class_votes.resize(keyframe.cloud.size());
    keyframe.point_of_voxel.reserve(keyframe.cloud.size());
    for (std::size_t i = 0; i < keyframe.cloud.size(); ++i) {
      uint64_t key = 0;
      if (cloud::pack_voxel_key(cloud::voxel_coordinates(keyframe.cloud.positions[i], inverse_voxel), &key)) {
        keyframe.point_of_voxel.emplace(key, static_cast<uint32_t>(i));
      }
    }
  }
  const Eigen::Matrix3f rotation = T_keyframe_sensor.rotation().matrix().cast<float>();
  const Eigen::Vector3f translation = T_keyframe_sensor.translation().cast<float>();
  for (std::size_t i = 0; i < points.size(); ++i) {
    uint64_t key = 0;
    if (classes[i] == msgs::kNoClass || !cloud::pack_voxel_key(cloud::voxel_coordinates(rotation * points[i] + translation, inverse_voxel), &key)) continue;
    if (const auto point = keyframe.point_of_voxel.find(key); point != keyframe.point_of_voxel.end()) keyframe.class_votes[point->second].add(classes[i]);
  }
}

double PointMap::keyframe_voxel_size() const { return config_.keyframe_voxel_size > 0.0 ? config_.keyframe_voxel_size : config_.voxel_size / 2.0; }

void PointMap::PointClassVotes::add(uint16_t class_index) {
  for (std::size_t slot = 0; slot < kSlots; ++slot) {
    if (count[slot] > 0 && label[slot] == class_index) {
      if (count[slot] < UINT16_MAX) ++count[slot];
      return;
    }
  }
  for (std::size_t slot = 0; slot < kSlots; ++slot) {
    if (count[slot] == 0) {
      label[slot] = class_index;
      count[slot] = 1;
      return;
    }
  }
  for (uint16_t& held : count) --held;
}

uint16_t PointMap::class_index(std::string_view name) {
  const auto found = std::find(semantic_classes_.begin(), semantic_classes_.end(), name);
  if (found != semantic_classes_.end()) return static_cast<uint16_t>(found - semantic_classes_.begin());
  if (semantic_classes_.size() + 1 >= msgs::kNoClass) return msgs::kNoClass;
  semantic_classes_.emplace_back(name);
  return static_cast<uint16_t>(semantic_classes_.size() - 1);
}

Status PointMap::set_poses(const std::map<uint64_t, SE3>& T_world_sensor_by_id) {
  for (const auto& [id, pose] : T_world_sensor_by_id) {
    if (!keyframes_.contains(id)) return Error{fmt::format("set_poses: no keyframe {}", id), "id"};
    if (!pose.matrix().allFinite()) return Error{fmt::format("set_poses: keyframe {} pose is not finite", id), "T_world_sensor"};
  }
  for (const auto& [id, pose] : T_world_sensor_by_id) keyframes_[id].T_world_sensor = pose;
  dirty_ = dirty_ || !T_world_sensor_by_id.empty();
  return ok_status();
}

Result<SE3> PointMap::pose(uint64_t id) const {
  const auto found = keyframes_.find(id);
  if (found == keyframes_.end()) return Error{fmt::format("no keyframe {}", id), "id"};
  return found->second.T_world_sensor;
}

void PointMap::rebuild() const {
  struct Voxel {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double sum_squared_norm = 0.0;
    double intensity_sum = 0.0;
    uint32_t count = 0;
  };
  const bool with_intensity = !keyframes_.empty() && std::all_of(keyframes_.begin(), keyframes_.end(), [](const auto& entry) {
    return entry.second.cloud.has_intensities() || entry.second.cloud.empty();
  });
  const float inverse_voxel = static_cast<float>(1.0 / config_.voxel_size);
  std::unordered_map<uint64_t, Voxel> voxels;
  std::unordered_map<uint64_t, ClassVotes> class_votes;
  const bool with_classes = std::any_of(keyframes_.begin(), keyframes_.end(), [](const auto& entry) { return !entry.second.class_votes.empty(); });
  std::size_t dropped = 0;
  for (const auto& [id, keyframe] : keyframes_) {
    const Eigen::Matrix3d rotation = keyframe.T_world_sensor.rotation().matrix();
    const Eigen::Vector3d translation = keyframe.T_world_sensor.translation();
    for (std::size_t i = 0; i < keyframe.cloud.size(); ++i) {
      if (!keyframe.sightings.empty() && moved(keyframe.sightings[i])) continue;
      const Eigen::Vector3d world = rotation * keyframe.cloud.positions[i].cast<double>() + translation;
      uint64_t key = 0;
      if (!cloud::pack_voxel_key(cloud::voxel_coordinates(world.cast<float>(), inverse_voxel), &key)) {
        ++dropped;
        continue;
      }
      Voxel& voxel = voxels[key];
      voxel.sum += world;
      voxel.sum_squared_norm += world.squaredNorm();
      if (with_intensity) voxel.intensity_sum += keyframe.cloud.intensities[i];
      ++voxel.count;
      if (keyframe.class_votes.empty()) continue;
      const PointClassVotes& point_votes = keyframe.class_votes[i];
      for (std::size_t slot = 0; slot < PointClassVotes::kSlots; ++slot) {
        if (point_votes.count[slot] > 0) class_votes[key].add(point_votes.label[slot], point_votes.count[slot]);
      }
    }
  }
  if (dropped > 0) logger()->warn("point map: {} points outside the voxel key range were left out", dropped);

  std::vector<std::pair<uint64_t, const Voxel*>> ordered;
  ordered.reserve(voxels.size());
  for (const auto& [key, voxel] : voxels) ordered.emplace_back(key, &voxel);
  std::sort(ordered.begin(), ordered.end(), [](const auto& a, const auto& b) { return a.first < b.first; });

  merged_.clear();
  merged_std_.clear();
  merged_classes_.clear();
  merged_class_probability_.clear();
  merged_.positions.reserve(ordered.size());
  merged_std_.reserve(ordered.size());
  if (with_intensity) merged_.intensities.reserve(ordered.size());
  const double quantization_std = config_.voxel_size / std::sqrt(12.0) / 2.0;
  for (const auto& [key, voxel] : ordered) {
    const Eigen::Vector3d mean = voxel->sum / voxel->count;
    const double variance = std::max(0.0, voxel->sum_squared_norm / voxel->count - mean.squaredNorm()) / 3.0;
    merged_.positions.push_back(mean.cast<float>());
    merged_std_.push_back(static_cast<float>(std::max(std::sqrt(variance), quantization_std)));
    if (with_intensity) merged_.intensities.push_back(static_cast<float>(voxel->intensity_sum / voxel->count));
    if (!with_classes) continue;
    const auto votes = class_votes.find(key);
    if (votes == class_votes.end()) {
      merged_classes_.push_back(msgs::kNoClass);
      merged_class_probability_.push_back(0.0F);
    } else {
      merged_classes_.push_back(votes->second.most().first);
      merged_class_probability_.push_back(class_posterior(votes->second, semantic_classes_.size(), config_.segmentation_accuracy));
    }
  }
  dirty_ = false;
}

const cloud::PointCloud& PointMap::cloud() const {
  if (dirty_) rebuild();
  return merged_;
}

msgs::PointLayer PointMap::to_layer() const {
  const cloud::PointCloud& merged = cloud();
  msgs::PointLayer layer;
  layer.points = merged.positions;
  layer.position_std = merged_std_;
  layer.intensities = merged.intensities;
  layer.voxel_size = config_.voxel_size;
  layer.classes = merged_classes_;
  layer.class_probability = merged_class_probability_;
  return layer;
}

std::size_t PointMap::memory_bytes() const {
  std::size_t bytes = merged_.positions.capacity() * sizeof(Eigen::Vector3f) + merged_.intensities.capacity() * sizeof(float) +
                      merged_std_.capacity() * sizeof(float);
  for (const auto& [id, image] : recent_images_) bytes += image.memory_bytes();
  for (const auto& [id, keyframe] : keyframes_) {
    bytes += sizeof(Keyframe) + keyframe.cloud.positions.capacity() * sizeof(Eigen::Vector3f) +
             keyframe.cloud.intensities.capacity() * sizeof(float) + keyframe.class_votes.capacity() * sizeof(PointClassVotes) +
             keyframe.sightings.capacity() * sizeof(PointSightings) +
             keyframe.point_of_voxel.size() * 32;
  }
  return bytes;
}

}  // namespace hanzo::fusion::maps
