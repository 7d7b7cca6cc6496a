#pragma once
// LandmarkPlaceIndex: the keyframes of a visual landmark map (the FusionMap's visual_landmarks
// layer) ranked by how much a set of descriptors looks like each keyframe's view, for
// relocalizing an image in the map (vision/map_relocalizer.hpp) and for finding the places two
// sessions' maps share (vision/landmark_map_alignment.hpp).
//
// Each keyframe is described by the descriptors of the landmarks it sees:
//   ORB maps ("bow"): a bag of words of the vocabulary, scored with its L1 score
//     (Galvez-Lopez and Tardos 2012, eq. 3; vision/vocabulary.hpp).
//   Learned maps with a VLAD model of their features ("learned"): the VLAD vector
//     (Jegou et al. 2010), scored by cosine (vision/vlad.hpp).
//   Learned maps without one ("matches"): the query's descriptors are matched to every landmark
//     (ratio 0.9, mutual, Euclidean distance of the unit rows under 1) and each keyframe scores the
//     share of its landmarks matched.
//
// Failures: create() refuses descriptors that are not one row per landmark, a keyframe seeing a
// landmark past the list, and a VLAD model trained on other features than the map's.

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/vision/vlad.hpp"
#include "hanzo/fusion/vision/vocabulary.hpp"

namespace hanzo::fusion::vision {

/// The layer's landmark descriptors, one row each: CV_8UC1 32 bytes (ORB) or CV_32FC1 of
/// float_descriptor_size (learned). Error when their count does not fit the landmarks.
Result<cv::Mat> landmark_descriptors(const msgs::VisualLandmarkLayer& map);

struct LandmarkPlaceIndexConfig {
  /// ORB maps. Null: Vocabulary::load_default().
  std::shared_ptr<const Vocabulary> vocabulary;
  /// Learned maps: the VLAD model of the map's features. Null: VladModel::load_default(the map's
  /// descriptor_type), and when there is none, keyframes ranked by matched landmarks.
  std::shared_ptr<const VladModel> place_model;
  /// Learned maps: false ranks by matched landmarks even where a VLAD model exists.
  bool learned_place_recognition = true;
};

struct PlaceCandidate {
  double score = 0.0;  ///< bag-of-words score, VLAD cosine or share of landmarks matched
  int keyframe = 0;    ///< index into the map's keyframes
};

class LandmarkPlaceIndex {
 public:
  static Result<LandmarkPlaceIndex> create(const msgs::VisualLandmarkLayer& map, const LandmarkPlaceIndexConfig& config = {});

  /// The `count` keyframes most like `descriptors` (rows of the map's kind), best first.
  std::vector<PlaceCandidate> rank(const cv::Mat& descriptors, int count) const;
  /// The descriptors of the landmarks keyframe k sees, one row each.
  cv::Mat keyframe_descriptors(std::size_t keyframe) const;

  /// "bow", "learned" or "matches".
  const std::string& method() const { return method_; }
  /// One row per landmark of the map.
  const cv::Mat& descriptors() const { return descriptors_; }

 private:
  LandmarkPlaceIndex() = default;
  std::string method_;
  cv::Mat descriptors_;
  std::vector<std::vector<uint32_t>> keyframe_landmarks_;
  std::shared_ptr<const Vocabulary> vocabulary_;   // "bow"
  std::vector<BowVector> keyframe_words_;          // "bow"
  std::shared_ptr<const VladModel> place_model_;   // "learned"
  std::vector<Eigen::VectorXf> keyframe_vlad_;     // "learned"
};

}  // namespace hanzo::fusion::vision
