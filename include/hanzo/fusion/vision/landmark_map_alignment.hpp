#pragma once
// LandmarkMapAligner: where a keyframe of one session's visual landmark map lies in another
// session's map, without a guess (the camera half of joining sessions: pipeline/session_merge.hpp).
//
//  1. Candidates: the query keyframe's landmark descriptors ranked against map a's keyframes
//     (vision/landmark_place_index.hpp: bag of words for ORB maps, VLAD or matched landmarks for
//     learned ones); the `candidates` best are tried.
//  2. Pairs: the query's landmarks matched by descriptor (ratio test, mutual) to the landmarks of
//     the candidate and its neighbour_keyframes on each side: 3D-3D pairs, each landmark in its
//     own map's frame. Landmarks less certain than max_relative_std of their distance to the
//     keyframe that sees them are left out (far points seen over a short baseline).
//  3. RANSAC over three pairs (fixed seed): the similarity x_a = s R x_b + t (Umeyama 1991,
//     eqs. 40-42; s = 1 unless either map is scale_free, i.e. monocular). A pair is an inlier
//     within max(min_inlier_distance, inlier_ratio x its distance to the candidate's camera) in
//     map a (a landmark's error grows with its depth). The best set is refined by Umeyama on its
//     inliers, twice.
//  4. Accepted with min_inliers inliers making min_inlier_fraction of the pairs; the candidate
//     with the most inliers wins.
//
// Frames: each map's own world frame; the result maps b's frame into a's. Units: each map's
// (metres, or a monocular map's first baseline). Failures: create() refuses a map without
// keyframes or with descriptors that do not fit its landmarks (map a must outlive the aligner);
// align() refuses maps of
// different descriptor types and returns an Error naming why no loop was found.

#include <cstddef>
#include <string>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/vision/landmark_place_index.hpp"

namespace hanzo::fusion::vision {

struct LandmarkMapAlignmentConfig {
  LandmarkPlaceIndexConfig places;  ///< candidate ranking (vocabulary, VLAD model)
  int candidates = 3;               ///< keyframes of map a tried per query
  int neighbour_keyframes = 2;      ///< keyframes on each side whose landmarks join a candidate's
  double descriptor_ratio = 0.8;    ///< Lowe's ratio of the landmark matches
  double max_relative_std = 0.1;    ///< landmarks with position_std above this share of their depth are left out
  int ransac_iterations = 500;
  double inlier_ratio = 0.05;        ///< of the landmark's distance to the candidate's camera
  double min_inlier_distance = 0.1;  ///< in map a's units
  int min_inliers = 20;
  double min_inlier_fraction = 0.3;  ///< of the matched pairs
  double max_scale_change = 20.0;    ///< scale-free maps: s within [1/this, this]

  Status validate() const;
};

/// Keyframe b of map b seen in map a: x_a = scale * (T_a_b.rotation() * x_b) + T_a_b.translation().
struct LandmarkMapLoop {
  std::size_t keyframe_a = 0;   ///< the candidate
  std::size_t keyframe_b = 0;   ///< the query
  double scale = 1.0;           ///< map a's units per map b's unit
  SE3 T_a_b;                    ///< rotation and translation of the similarity
  int inliers = 0;
  int pairs = 0;                ///< matched landmark pairs of the candidate
  double rmse = 0.0;            ///< of the inliers, in map a's units
  double place_score = 0.0;     ///< the candidate's rank score
};

class LandmarkMapAligner {
 public:
  static Result<LandmarkMapAligner> create(const msgs::VisualLandmarkLayer& map_a, const LandmarkMapAlignmentConfig& config = {});

  /// Keyframe `keyframe_b` of `map_b` in map a: the best verified candidate, else why none.
  /// `descriptors_b`: landmark_descriptors(map_b).
  Result<LandmarkMapLoop> align(const msgs::VisualLandmarkLayer& map_b, const cv::Mat& descriptors_b, std::size_t keyframe_b) const;

  const LandmarkPlaceIndex& places() const { return places_; }

 private:
  LandmarkMapAligner(const msgs::VisualLandmarkLayer& map_a, LandmarkPlaceIndex places, LandmarkMapAlignmentConfig config)
      : map_a_(&map_a), places_(std::move(places)), config_(std::move(config)) {}
  const msgs::VisualLandmarkLayer* map_a_;  // not owned: outlives the aligner
  LandmarkPlaceIndex places_;
  LandmarkMapAlignmentConfig config_;
};

}  // namespace hanzo::fusion::vision
