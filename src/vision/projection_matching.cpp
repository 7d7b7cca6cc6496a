#include "projection_matching.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include "hanzo/fusion/vision/feature_matcher.hpp"

namespace hanzo::fusion::vision {

std::vector<std::pair<int, int>> match_by_projection(const std::vector<ProjectedLandmark>& landmarks, const ImageFeatures& features,
                                                     const KeypointGrid& grid, const PinholeCamera& camera, const SE3& T_camera_world,
                                                     const ProjectionSearch& search) {
  const cv::Size image_size = features.image_size;
  double octave_radius[16];
  for (int level = 0; level < 16; ++level) octave_radius[level] = search.radius_px * std::pow(search.scale_factor, level);
  const auto radius_at = [&](int octave) { return octave_radius[std::clamp(octave, 0, 15)]; };
  std::vector<std::pair<int, int>> owner(features.size(), {-1, std::numeric_limits<int>::max()});  // (landmark index, distance)
  for (std::size_t i = 0; i < landmarks.size(); ++i) {
    const ProjectedLandmark& landmark = landmarks[i];
    const std::optional<Eigen::Vector2d> pixel = camera.project(T_camera_world.act(landmark.position_world));
    if (!pixel || pixel->x() < 0 || pixel->y() < 0 || pixel->x() >= image_size.width || pixel->y() >= image_size.height) continue;
    // Unknown octave: the widest radius a keypoint may need, checked per keypoint below.
    const double widest = radius_at(landmark.octave >= 0 ? landmark.octave : 7);
    NearestCandidates nearest;
    grid.for_each_near(pixel->x(), pixel->y(), widest, [&](int k) {
      const cv::KeyPoint& keypoint = features.keypoints[static_cast<std::size_t>(k)];
      if (landmark.octave >= 0 && std::abs(keypoint.octave - landmark.octave) > search.max_octave_difference) return;
      const double radius = landmark.octave >= 0 ? widest : radius_at(keypoint.octave);
      if ((Eigen::Vector2d(keypoint.pt.x, keypoint.pt.y) - *pixel).squaredNorm() > radius * radius) return;
      nearest.offer(k, descriptor_distance(landmark.descriptor, 0, features.descriptors, k));
    });
    if (!nearest.passes(search.ratio, search.max_descriptor_distance)) continue;
    auto& slot = owner[static_cast<std::size_t>(nearest.index)];
    if (nearest.best < slot.second) slot = {static_cast<int>(i), nearest.best};
  }
  std::vector<std::pair<int, int>> matches;
  for (std::size_t k = 0; k < owner.size(); ++k) {
    if (owner[k].first >= 0) matches.emplace_back(static_cast<int>(k), landmarks[static_cast<std::size_t>(owner[k].first)].id);
  }
  return matches;
}

}  // namespace hanzo::fusion::vision
