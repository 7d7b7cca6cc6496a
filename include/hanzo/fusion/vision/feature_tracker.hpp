#pragma once
// FeatureTracker: sparse optical-flow feature tracks for filter-based visual-inertial odometry
// (the MSCKF, msckf.hpp), as OpenVINS's KLT tracker:
//
//   1. the previous image's features are tracked into the new image by pyramidal Lucas-Kanade
//      (cv::calcOpticalFlowPyrLK, window_px square, pyramid_levels); lost or out-of-image
//      features end their tracks;
//   2. when the features moved (median over 1 px), the tracked pairs are checked by a RANSAC
//      fundamental matrix on undistorted coordinates (ransac_threshold_px); outliers end;
//   3. new Shi-Tomasi corners (or a detector's keypoints, FeatureTrackerConfig::detector) (the local maxima of cv::cornerMinEigenVal) at least min_distance_px
//      from every kept feature top the image up to max_features, spread over a grid of cells
//      (each cell gets its share, its strongest corners first, down to quality_level of its
//      strongest and min_image_quality of the image's strongest: a strong checkerboard does not
//      starve the weakly textured rest of the image); each gets a new id;
//   4. stereo: every left feature is searched in the right image by Lucas-Kanade (started at
//      its last right position, else at the left position), and kept when the result lies
//      within stereo_epipolar_px of the rig's epipolar line and tracks back to the left
//      feature within 1 px. The right observation has the left feature's id.
//
// Output: FeatureObservation per feature and camera (camera 0 the left/only, 1 the right),
// undistorted normalized coordinates through each camera's PinholeCamera; features whose pixel
// cannot be undistorted are dropped.
//
// Failures: track() refuses an empty image, one of another size than configured, a type
// other than 8-bit grey / BGR / BGRA, or a static mask not CV_8UC1 of the image's size (the
// tracks are kept; the next good image continues them).

#include <memory>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/vision/static_mask.hpp"
#include "hanzo/fusion/vision/feature_extractor.hpp"
#include "hanzo/fusion/vision/feature_observation.hpp"

namespace hanzo::fusion::vision {

struct FeatureTrackerConfig {
  /// Features kept per image (OpenVINS's default 200).
  int max_features = 200;
  /// Least distance between features (pixels): spreads them over the image.
  double min_distance_px = 20.0;
  /// Shi-Tomasi corner strength relative to the strongest in its cell, and to the image's strongest.
  double quality_level = 0.01;
  double min_image_quality = 0.001;
  /// Detection grid: each of the cells gets max_features / cells new features at most.
  int grid_columns = 8;
  int grid_rows = 5;
  /// Lucas-Kanade window (pixels, odd) and pyramid levels above the image.
  int window_px = 21;
  int pyramid_levels = 3;
  /// RANSAC fundamental-matrix threshold between frames (pixels of the undistorted image).
  double ransac_threshold_px = 1.0;
  /// Largest distance of a right-image match from the epipolar line (pixels).
  double stereo_epipolar_px = 2.0;
  /// New features from this detector's keypoints (their scores) instead of Shi-Tomasi corners,
  /// with the same grid, spacing and quality_level; null: Shi-Tomasi. A learned detector
  /// (ai::LearnedFeatureExtractor) finds corners ORB and Shi-Tomasi miss in dim or weakly textured
  /// images; its descriptors are not used (the tracks follow optical flow).
  std::shared_ptr<const FeatureExtractor> detector;
  /// With a detector: it runs only when fewer than this share of max_features are still
  /// tracked (a learned detector costs several times the optical flow). 1: whenever any is
  /// missing, the most accurate (the drone: 0.081 m real-time APE at 220 ms per frame; 0.8:
  /// 0.130 m at 116 ms; bench/RESULTS.md).
  double detector_refill_share = 1.0;
};

/// Checks every field; the error names the first field out of range.
Status validate(const FeatureTrackerConfig& config);

/// One image's (or stereo pair's) tracks.
struct TrackedFrame {
  std::vector<FeatureObservation> observations;
  int tracked = 0;           ///< left features continued from the previous image
  int new_features = 0;      ///< left features started in this image
  int rejected_ransac = 0;   ///< tracks ended by the fundamental-matrix check
  int stereo_matches = 0;    ///< left features also seen in the right image
  int masked = 0;            ///< tracks ended on a moving object (the static mask's zeros)
};

class FeatureTracker {
 public:
  /// Fails when the configuration is out of range, the focal lengths are not positive or the
  /// image is smaller than 32 x 32.
  static Result<std::unique_ptr<FeatureTracker>> create(const PinholeCamera& camera, cv::Size image_size, const FeatureTrackerConfig& config = {});
  /// A stereo rig: the right camera at T_left_right (right to left camera). Fails as create(),
  /// or when the cameras are less than 1 mm apart.
  static Result<std::unique_ptr<FeatureTracker>> create_stereo(const PinholeCamera& left, const PinholeCamera& right, const SE3& T_left_right,
                                                               cv::Size image_size, const FeatureTrackerConfig& config = {});
  ~FeatureTracker();
  FeatureTracker(const FeatureTracker&) = delete;
  FeatureTracker& operator=(const FeatureTracker&) = delete;

  /// Monocular (or a stereo tracker given only its left image: no right observations).
  /// static_mask (optional; static_mask.hpp): the (left) image's moving objects: tracks that
  /// land there end (TrackedFrame::masked) and no new feature starts there.
  Result<TrackedFrame> track(const cv::Mat& image, const StaticMask& static_mask = {});
  /// Stereo: the pair taken at the same time.
  Result<TrackedFrame> track(const cv::Mat& left, const cv::Mat& right, const StaticMask& static_mask = {});

 private:
  struct State;
  explicit FeatureTracker(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace hanzo::fusion::vision
