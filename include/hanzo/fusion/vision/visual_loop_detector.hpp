#pragma once
// VisualLoopDetector: loop closures for an odometry that keeps no map of its own (the MSCKF's
// features live only while they are tracked). The caller adds "places": camera images a short
// distance apart, each with the odometry's pose of the camera.
//
//   1. Each place's ORB features (vision/orb_extractor.hpp) are matched by descriptor (mutual,
//      ratio 0.8) with triangulation_neighbours places on each side and triangulated from all views
//      (linear, Hartley and Zisserman 12.2) with the odometry's relative poses (accurate over
//      the short distances between places; its drift does not matter here): points with at
//      least min_parallax_degrees between two rays, in front of every camera and within the
//      chi-square 95 % bound of every keypoint are kept, in the place's camera frame. A place
//      gets its points when its last neighbour is added.
//   2. A new place's bag of words (vision/place_database.hpp) queries the places at least
//      min_place_gap older, above the score it has with its own recent places (DBoW2's
//      normalization, Galvez-Lopez and Tardos 2012, section V); the `candidates` best are tried.
//   3. A candidate's points (with its two neighbours', moved into its frame) are matched to the new place's keypoints by descriptor and the new
//      camera placed by PnP RANSAC (EPnP), then refined on the reprojection errors (Huber,
//      chi-square rounds; vision/pose_refinement). The loop is accepted with min_inliers inliers
//      making at least min_inlier_share of the matches, when the refinement barely moved the
//      PnP pose (a shifted fit on a repeating texture moves).
//
// Frames: cameras are optical frames (x right, y down, z forward); T_odometry_camera is any
// consistent odometry world (only relative poses of consecutive places are used); a loop is
// T_place_current: the new place's camera in the earlier place's camera frame, metric.
// Failures: create() fails without the vocabulary or with a camera without positive focal
// lengths; add() fails on an empty image or a non-finite pose, and then adds no place.
// Use from one thread.

#include <memory>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/vision/static_mask.hpp"
#include "hanzo/fusion/vision/orb_extractor.hpp"
#include "hanzo/fusion/vision/place_database.hpp"
#include "hanzo/fusion/vision/vocabulary.hpp"

namespace hanzo::fusion::vision {

struct VisualLoopDetectorConfig {
  OrbExtractorConfig features;       ///< per place (1000 features)
  /// Places on each side whose views triangulate a place's points (its points come when the
  /// last of them is added). Two: baselines up to twice the place spacing each way.
  int triangulation_neighbours = 2;
  /// Views a point needs (the place's own included): with three, a keypoint matched to a
  /// look-alike on its epipolar line (a checker floor, a tiled wall) is not triangulated, since
  /// the second neighbour's epipolar line crosses the first's.
  int min_views = 3;
  int min_place_gap = 15;            ///< places between a candidate and the new place (> 2 triangulation_neighbours)
  int candidates = 3;                ///< best bag-of-words candidates verified per place
  int min_inliers = 40;              ///< refined PnP inliers to accept a loop
  double min_inlier_share = 0.5;     ///< of the candidate's descriptor matches
  /// Between two rays of a triangulated point: far points seen over the short distance
  /// between places are mostly off along their ray (1 degree: loops off by up to 1 m on the
  /// drone's flight; 3 degrees: 0.16 m).
  double min_parallax_degrees = 3.0;
  /// The loop's standard deviations (covariance of VisualLoop): a floor, plus a share of the
  /// distance between the two cameras (its points, triangulated over a short baseline, place a
  /// camera seen from further away less well). On the drone's flight the loops were off by
  /// 1-14 cm and 0.1-0.8 degrees at 0.2-4 m apart, inside one sigma of these; half these
  /// sigmas made the Session's loop-closed trajectory worse than none (bench/RESULTS.md).
  double translation_sigma = 0.1;               ///< m
  double translation_sigma_per_metre = 0.06;    ///< m per m apart
  double rotation_sigma = 0.01;                 ///< rad
  double rotation_sigma_per_metre = 0.006;      ///< rad per m apart
  double pixel_sigma = 1.0;          ///< keypoint noise at octave 0 (pixels)
  int cooldown_places = 3;           ///< places after a loop before the next one is searched
  /// A place offered within this distance (m) and covered_place_angle (rad) of a place at least
  /// min_place_gap older, by the odometry's poses, is a view the database already has (a
  /// revisit): it is searched for a loop like any other but not kept, so that flying the same
  /// rounds again and again does not grow the database. 0 keeps every place.
  double covered_place_distance = 0.5;
  double covered_place_angle = 0.2;
  /// Null: the default vocabulary (Vocabulary::load_default).
  std::shared_ptr<const Vocabulary> vocabulary;
};

Status validate(const VisualLoopDetectorConfig& config);

struct VisualLoop {
  int place = -1;    ///< the earlier place
  int current = -1;  ///< the place just added; -1 when it was not kept (covered_place_distance)
  SE3 T_place_current;
  /// Over the tangent (rho, phi) of T_place_current, right perturbation: the configured
  /// standard deviations at the distance between the two cameras.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();
  int inliers = 0;
  int matches = 0;   ///< descriptor matches the PnP started from
  double score = 0;  ///< bag-of-words score of the candidate
};

class VisualLoopDetector {
 public:
  static Result<VisualLoopDetector> create(const PinholeCamera& camera, VisualLoopDetectorConfig config = {});

  /// Adds an 8-bit grey (or BGR) image as place size() at the odometry's T_odometry_camera,
  /// triangulates the previous place's points with it, and looks for a loop closing here. A
  /// place covered by an older one (covered_place_distance) is only searched, not added.
  /// static_mask (optional): the image's moving objects, where no keypoint of the place is taken.
  Result<std::optional<VisualLoop>> add(const cv::Mat& image, const SE3& T_odometry_camera, const StaticMask& static_mask = {});

  int size() const { return static_cast<int>(places_.size()); }
  int candidates_checked() const { return candidates_checked_; }
  int loops() const { return loops_; }
  /// Places offered but not kept: views the database already had.
  int covered_places() const { return covered_places_; }
  /// The triangulated points of a place (its camera frame); empty until its last neighbour.
  std::vector<Eigen::Vector3d> points(int place) const;

 private:
  struct Place {
    ImageFeatures features;
    std::vector<std::optional<Eigen::Vector2d>> normalized;  // undistorted, per keypoint
    SE3 T_odometry_camera;
    std::vector<Eigen::Vector3d> points;  // camera frame
    cv::Mat point_descriptors;             // one row per point
  };
  VisualLoopDetector(const PinholeCamera& camera, VisualLoopDetectorConfig config, std::shared_ptr<const Vocabulary> vocabulary);
  void triangulate_points(std::size_t index);  // with its neighbours' views
  std::optional<VisualLoop> verify(int candidate, const Place& current) const;
  double keypoint_sigma(const cv::KeyPoint& keypoint) const;

  PinholeCamera camera_;
  VisualLoopDetectorConfig config_;
  OrbExtractor extractor_;
  std::shared_ptr<const Vocabulary> vocabulary_;
  PlaceDatabase database_;
  std::vector<Place> places_;
  int candidates_checked_ = 0;
  int loops_ = 0;
  int covered_places_ = 0;
  // Whether a place at least min_place_gap older lies within covered_place_distance / angle.
  bool covered(const SE3& T_odometry_camera) const;
  int places_since_loop_ = 1 << 20;
};

}  // namespace hanzo::fusion::vision
