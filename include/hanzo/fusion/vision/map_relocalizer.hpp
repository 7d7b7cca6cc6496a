#pragma once
// MapRelocalizer: places a camera image in a saved visual landmark map (the FusionMap's
// visual_landmarks layer, written from VisualOdometry::landmark_layer).
//
//   1. The `candidates` map keyframes most like the image. ORB maps: each keyframe's bag of words
//      is built from the descriptors of the landmarks it sees and the image's ORB features query
//      them (vision/place_database.hpp). Learned maps (float descriptors, e.g. aliked-t16): each
//      keyframe's VLAD vector is aggregated from its landmarks' descriptors and compared with the
//      image's (vision/vlad.hpp); without a VLAD model for the map's features, the image's
//      descriptors are matched to every map landmark and each keyframe scores the share of its
//      landmarks matched.
//   2. For each candidate, the landmarks of it and its `neighbour_keyframes` neighbours on each
//      side are matched to the image's keypoints by descriptor (ratio 0.9, mutual) and the pose is
//      solved by PnP RANSAC on undistorted bearings, then refined by Gauss-Newton on the
//      reprojection errors (Huber, chi-square outlier rounds; vision/pose_refinement).
//   3. A candidate with min_inliers inliers brings every usable map landmark into view with its
//      pose: they are matched by projection (within projection_search_radius_px, then half of
//      it) and the pose refined on all of them (ORB-SLAM's relocalization scheme). The candidate
//      whose pose explains the most landmarks wins.
//   4. Unless it is ambiguous: the winner is refused when another candidate's pose at least
//      ambiguity_distance_m or ambiguity_angle_deg away explains ambiguity_ratio of its
//      landmarks (a wall or a tiled floor seen from afar is explained almost as well by a tilt
//      traded against a shift; repeated texture matches at either).
//
// Frames: the map's world frame (the odometry's: its first keyframe's camera frame, or the
// Session's world); the result is T_world_camera of the image's camera (optical frame).
// Failures: create() refuses a layer without landmarks or keyframes, descriptors that do not
// fit the landmarks, an extractor (or VLAD model) of other features than the map's and a camera
// without positive focal lengths; relocalize() returns an Error naming why no pose was found (no
// features, no candidate, too few inliers) and never changes the map.

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/vision/feature_extractor.hpp"
#include "hanzo/fusion/vision/landmark_place_index.hpp"
#include "hanzo/fusion/vision/orb_extractor.hpp"

namespace hanzo::fusion::vision {

struct MapRelocalizerConfig {
  /// The query image's features for a map of learned features: an extractor whose name() is the
  /// map's descriptor_type (pipeline/feature_extractors.hpp makes one from the name). Null: ORB
  /// with `features` (an ORB map only).
  std::shared_ptr<const FeatureExtractor> extractor;
  /// ORB features of the query image (more than tracking uses: the view may be far from the map's).
  OrbExtractorConfig features = [] {
    OrbExtractorConfig config;
    config.max_features = 2000;
    return config;
  }();
  int candidates = 5;           ///< keyframes tried, best bag-of-words score first
  int neighbour_keyframes = 2;  ///< keyframes on each side whose landmarks join a candidate's
  int min_inliers = 30;         ///< refined inliers needed to accept a pose
  double pixel_sigma = 1.0;     ///< keypoint noise at octave 0 (pixels)
  double projection_search_radius_px = 10.0;  ///< guided matching around the PnP pose, at octave 0
  /// Landmarks whose position_std exceeds this (map units) are left out: a far point seen over a
  /// short baseline is mostly off along its ray, and from another viewpoint it pulls the pose
  /// back toward the one that made it. 0: use all.
  double max_landmark_std = 0.1;
  /// ORB maps. Null: the default vocabulary (Vocabulary::load_default).
  std::shared_ptr<const Vocabulary> vocabulary;
  /// Learned maps: the VLAD model of the map's features. Null: VladModel::load_default(the map's
  /// descriptor_type), and when there is none, candidates by matched landmarks.
  std::shared_ptr<const VladModel> place_model;
  /// Learned maps: false ranks candidates by matched landmarks even where a VLAD model exists.
  bool learned_place_recognition = true;
  /// Ambiguity (step 4): refused when another candidate's pose this far from the winner (m, or
  /// degrees) explains at least this share of its landmarks. 0 or more than 1: no check.
  double ambiguity_ratio = 0.9;
  double ambiguity_distance_m = 0.3;
  double ambiguity_angle_deg = 2.0;
};

struct MapRelocalization {
  SE3 T_world_camera;
  int inliers = 0;
  int keyframe = 0;       ///< index of the map keyframe that placed it
  double score = 0.0;     ///< its place score (bag of words, VLAD cosine, or share of its landmarks matched)
  std::string place_recognition;  ///< how candidates were found: "bow", "learned" (VLAD) or "matches"
};

class KeypointGrid;
struct PoseRefinement;
struct ProjectedLandmark;

class MapRelocalizer {
 public:
  static Result<MapRelocalizer> create(msgs::VisualLandmarkLayer map, const PinholeCamera& camera, MapRelocalizerConfig config = {});

  /// The pose of an 8-bit grey, BGR or BGRA image in the map.
  Result<MapRelocalization> relocalize(const cv::Mat& image) const;

  const msgs::VisualLandmarkLayer& map() const { return map_; }

 private:
  MapRelocalizer() = default;
  bool usable(uint32_t landmark) const;  // under max_landmark_std
  PoseRefinement refine_by_projection(const SE3& T_camera_world, const std::vector<ProjectedLandmark>& landmarks, const ImageFeatures& features,
                                      const KeypointGrid& grid, double radius_px) const;
  msgs::VisualLandmarkLayer map_;
  PinholeCamera camera_;
  MapRelocalizerConfig config_;
  std::shared_ptr<const FeatureExtractor> extractor_;
  std::shared_ptr<const LandmarkPlaceIndex> places_;  // candidate keyframes
  double scale_factor_ = 1.0;  // the extractor's pyramid scale per octave (ORB)
  cv::Mat descriptors_;  // one row per landmark: CV_8UC1 32 bytes (ORB) or CV_32FC1 (learned)
};

}  // namespace hanzo::fusion::vision
