#pragma once
// match_image_pair(): verified correspondences between two images of the same scene, the
// matching that `hanzo-fusion features match`, relocalization and loop verification use.
//
//   1. features in both images (ORB, or the FeatureExtractor given: learned ones) and putative
//      descriptor matches (ratio test + mutual check, match_descriptors());
//   2. a robust geometry from them (OpenCV's USAC with MAGSAC++ scoring): a homography (planar
//      scene or pure rotation) or a fundamental matrix (general scene); kAuto takes the
//      homography when it explains at least homography_preference of the fundamental matrix's
//      inliers;
//   3. when that geometry is weak (fewer than min_inliers, or under min_inlier_ratio of the
//      putative matches: a wide baseline, where the view's foreshortening changes the
//      descriptors), affine views: each image is rotated by phi and compressed by a tilt t along
//      x (ASIFT's simulation, Morel and Yu 2009: phi in steps of 72 deg / t over [0, 180)), its
//      features matched against the other image and pooled, and the geometry estimated again;
//   4. guided matching of all features under that geometry (match_guided()) and the union with
//      the verified putative / affine-view matches, each within ransac_threshold_px of the
//      geometry (transfer error for a homography, epipolar distance for a fundamental matrix).
// Without a geometry (too few matches) the putative matches are returned unverified and
// geometry_found is false.
//
// Pixels: u right, v down, origin at the centre of the top-left pixel. Failure: the images'
// errors from OrbExtractor::extract() (empty, wrong type, too small), prefixed "image 1" /
// "image 2", or a configuration out of range.

#include <memory>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/vision/correspondence_filter.hpp"
#include "hanzo/fusion/vision/feature_extractor.hpp"
#include "hanzo/fusion/vision/feature_matcher.hpp"
#include "hanzo/fusion/vision/orb_extractor.hpp"

namespace hanzo::fusion::vision {

enum class PairGeometry { kAuto, kHomography, kFundamental };

struct ImagePairMatcherConfig {
  OrbExtractorConfig features;
  DescriptorMatcherConfig descriptors;
  GuidedMatcherConfig guided;
  PairGeometry geometry = PairGeometry::kAuto;
  /// Largest transfer / epipolar error of a verified match (pixels).
  double ransac_threshold_px = 3.0;
  /// kAuto: homography when its inliers >= this fraction of the fundamental matrix's.
  double homography_preference = 0.8;
  /// A geometry with fewer inliers, or a smaller inlier fraction of the putative matches, is
  /// weak: affine views are tried.
  int min_inliers = 30;
  double min_inlier_ratio = 0.3;
  /// Tilts simulated when the geometry is weak (each > 1); empty: no affine views.
  std::vector<double> view_tilts{1.41421356, 2.0, 2.82842712};
  /// A learned classifier of putative matches: when set, the putative matches are the mutual
  /// nearest neighbours without a ratio test, kept where its inlier probability is at least
  /// putative_filter_threshold, instead of the ratio test.
  std::shared_ptr<const CorrespondenceFilter> putative_filter;
  double putative_filter_threshold = 0.5;
};

/// A correspondence: a point of image 1 and of image 2 (pixels).
struct PointMatch {
  cv::Point2f point1;
  cv::Point2f point2;
  int distance = 0;  ///< descriptor distance (FeatureMatch::distance)
  /// Indices into features1 / features2; -1 for a point found in an affine view.
  int keypoint1 = -1;
  int keypoint2 = -1;
};

struct ImagePairMatches {
  ImageFeatures features1, features2;
  /// Descriptor matches between features1 and features2 before any geometry.
  std::vector<FeatureMatch> putative;
  /// Verified correspondences (the putative ones when geometry_found is false).
  std::vector<PointMatch> matches;
  bool geometry_found = false;
  GeometryModel model = GeometryModel::kHomography;
  /// image 2 ~ H image 1, or x2^T F x1 = 0.
  cv::Matx33d geometry = cv::Matx33d::eye();
  /// Affine views were needed (the first geometry was weak) and how many matches they added.
  bool affine_views_used = false;
  int affine_view_matches = 0;
};

Status validate(const ImagePairMatcherConfig& config);

/// `features`: the extractor of both images (and of the affine views); null: ORB with
/// config.features.
Result<ImagePairMatches> match_image_pair(const cv::Mat& image1, const cv::Mat& image2, const ImagePairMatcherConfig& config = {},
                                          const FeatureExtractor* features = nullptr);

/// The matches whose image-2 point lies within threshold_px of the homography's transfer of the
/// image-1 point (a ground-truth check: `features match --homography`).
int count_correct_matches(const std::vector<PointMatch>& matches, const cv::Matx33d& homography_1_to_2, double threshold_px);

}  // namespace hanzo::fusion::vision
