#pragma once
// Descriptor matching between two sets of features: binary ORB descriptors (CV_8UC1, 32 bytes a
// row) by Hamming distance, or learned float descriptors (CV_32FC1 unit rows) by Euclidean
// distance, held as an integer 1000 x the distance (kFloatDistanceScale) so both share one
// matcher; each kind has its own largest distance in the configurations.
//
// match_descriptors(): brute force over Hamming distances. A query keeps its nearest train
// descriptor when (1) the distance is at most max_distance, (2) Lowe's ratio test holds:
// nearest < ratio * second nearest (a nearest without a distinct runner-up is ambiguous: a
// repeated texture), and (3) with `mutual`, the query is also the train descriptor's nearest.
//
// match_guided(): the same tests, but a query is compared only with the train keypoints its
// predicted position allows (a homography's transfer within radius_px, or the epipolar line of a
// fundamental matrix within radius_px) and within one pyramid octave of its own: the search
// that recovers matches a global ratio test loses to distinctiveness over the whole image
// (wide baselines, repeated structure).

#include <functional>
#include <limits>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/vision/orb_extractor.hpp"

namespace hanzo::fusion::vision {

/// The nearest and the second-nearest of candidates offered one by one with their descriptor
/// distances: the state of a ratio test.
struct NearestCandidates {
  int index = -1;
  int best = std::numeric_limits<int>::max();
  int second = std::numeric_limits<int>::max();

  void offer(int candidate, int distance) {
    if (distance < best) {
      second = best;
      best = distance;
      index = candidate;
    } else if (distance < second) {
      second = distance;
    }
  }
  /// A nearest within max_distance that passes the ratio test (ratio >= 1: no test; a lone
  /// candidate passes).
  bool passes(double ratio, int max_distance) const {
    return index >= 0 && best <= max_distance && (ratio >= 1.0 || second == std::numeric_limits<int>::max() || best < ratio * second);
  }
};

/// Float descriptors' distances are held as kFloatDistanceScale x the Euclidean distance.
inline constexpr double kFloatDistanceScale = 1000.0;

/// Distance between row `a` of `descriptors_a` and row `b` of `descriptors_b` (both CV_8UC1 or
/// both CV_32FC1, of the same width): Hamming bits, or kFloatDistanceScale x Euclidean.
int descriptor_distance(const cv::Mat& descriptors_a, int a, const cv::Mat& descriptors_b, int b);

/// The largest distance of a match in descriptor_distance()'s units for rows like `descriptors`':
/// `max_hamming_bits` for binary (CV_8UC1) rows, kFloatDistanceScale x `max_euclidean` for float
/// (CV_32FC1) rows.
int descriptor_distance_limit(const cv::Mat& descriptors, int max_hamming_bits, double max_euclidean);

struct FeatureMatch {
  int query = -1;     ///< index into the first (query) features
  int train = -1;     ///< index into the second (train) features
  int distance = 0;   ///< Hamming bits (0..256), or kFloatDistanceScale x Euclidean (0..2000 for unit vectors)
  int second_distance = -1;  ///< the runner-up's distance (the ratio test's denominator); -1: none
};

struct DescriptorMatcherConfig {
  /// Lowe's ratio (0, 1]: nearest < ratio * second nearest. 1 turns the test off.
  double ratio = 0.8;
  /// Keep only mutual nearest neighbours.
  bool mutual = true;
  /// Largest Hamming distance kept (bits); ORB matches of the same point are mostly under 64.
  int max_distance = 80;
  /// Float descriptors: the ratio test's ratio and the largest Euclidean distance of the unit
  /// vectors (0..2) kept. Learned descriptors are more distinctive than ORB's, so a looser
  /// ratio keeps more correct matches (docs/vision.md, graf).
  double float_ratio = 0.95;
  double max_float_distance = 1.2;
};

/// Matches query to train descriptors (both CV_8UC1 with 32 bytes a row, or both CV_32FC1 of one
/// width); sorted by query.
std::vector<FeatureMatch> match_descriptors(const cv::Mat& query_descriptors, const cv::Mat& train_descriptors,
                                            const DescriptorMatcherConfig& config = {});

/// Where the geometry puts a query keypoint in the train image.
enum class GeometryModel { kHomography, kFundamental };

struct GuidedMatcherConfig {
  /// Homography: transfer distance; fundamental: distance to the epipolar line (pixels).
  double radius_px = 6.0;
  /// Ratio among the candidates in the search region; 1 turns the test off: the region already
  /// excludes most look-alikes, and the geometry verifies what is kept.
  double ratio = 1.0;
  int max_distance = 100;
  /// Float descriptors: the largest Euclidean distance of the unit vectors (0..2).
  double max_float_distance = 1.2;
  /// Largest difference of pyramid octaves between the two keypoints (-1: any).
  int max_octave_difference = 2;
};

/// Matches guided by a 3x3 geometry (train ~ H query, or train^T F query = 0); each train
/// keypoint is used at most once (the closer descriptor wins). Sorted by query.
std::vector<FeatureMatch> match_guided(const ImageFeatures& query, const ImageFeatures& train, GeometryModel model,
                                       const cv::Matx33d& geometry, const GuidedMatcherConfig& config = {});

}  // namespace hanzo::fusion::vision
