#include "hanzo/fusion/vision/image_pair_matcher.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::vision {
namespace {

struct GeometryEstimate {
  bool found = false;
  GeometryModel model = GeometryModel::kHomography;
  cv::Matx33d matrix = cv::Matx33d::eye();
  int inliers = 0;
};

// Transfer error of a homography in image 2, or the larger of the two epipolar distances.
double geometry_error(GeometryModel model, const cv::Matx33d& matrix, const cv::Point2f& point1, const cv::Point2f& point2) {
  const cv::Vec3d x1(point1.x, point1.y, 1.0), x2(point2.x, point2.y, 1.0);
  if (model == GeometryModel::kHomography) {
    const cv::Vec3d mapped = matrix * x1;
    if (std::abs(mapped[2]) < 1e-12) return INFINITY;
    return std::hypot(mapped[0] / mapped[2] - point2.x, mapped[1] / mapped[2] - point2.y);
  }
  const cv::Vec3d line2 = matrix * x1, line1 = matrix.t() * x2;
  const double norm2 = std::hypot(line2[0], line2[1]), norm1 = std::hypot(line1[0], line1[1]);
  if (norm1 < 1e-12 || norm2 < 1e-12) return INFINITY;
  return std::max(std::abs(line2.dot(x2)) / norm2, std::abs(line1.dot(x1)) / norm1);
}

int count_inliers(const GeometryEstimate& estimate, const std::vector<PointMatch>& matches, double threshold_px) {
  int inliers = 0;
  for (const PointMatch& match : matches) inliers += geometry_error(estimate.model, estimate.matrix, match.point1, match.point2) <= threshold_px;
  return inliers;
}

GeometryEstimate estimate_model(GeometryModel model, const std::vector<PointMatch>& matches, double threshold_px, bool robust) {
  GeometryEstimate estimate;
  estimate.model = model;
  const std::size_t needed = model == GeometryModel::kHomography ? 4 : 8;
  if (matches.size() < needed) return estimate;
  std::vector<cv::Point2f> points1, points2;
  for (const PointMatch& match : matches) {
    points1.push_back(match.point1);
    points2.push_back(match.point2);
  }
  cv::Mat matrix;
  if (model == GeometryModel::kHomography) {
    matrix = robust ? cv::findHomography(points1, points2, cv::USAC_MAGSAC, threshold_px, cv::noArray(), 10000, 0.9999)
                    : cv::findHomography(points1, points2, 0);
  } else {
    matrix = cv::findFundamentalMat(points1, points2, robust ? static_cast<int>(cv::USAC_MAGSAC) : static_cast<int>(cv::FM_8POINT), threshold_px, 0.9999, 10000);
  }
  if (matrix.rows != 3 || matrix.cols != 3) return estimate;
  matrix.convertTo(matrix, CV_64F);
  estimate.matrix = cv::Matx33d(matrix.ptr<double>());
  estimate.inliers = count_inliers(estimate, matches, threshold_px);
  estimate.found = estimate.inliers >= static_cast<int>(needed);
  return estimate;
}

GeometryEstimate estimate_geometry(const std::vector<PointMatch>& matches, const ImagePairMatcherConfig& config) {
  const double threshold = config.ransac_threshold_px;
  if (config.geometry == PairGeometry::kHomography) return estimate_model(GeometryModel::kHomography, matches, threshold, true);
  if (config.geometry == PairGeometry::kFundamental) return estimate_model(GeometryModel::kFundamental, matches, threshold, true);
  GeometryEstimate homography = estimate_model(GeometryModel::kHomography, matches, threshold, true);
  GeometryEstimate fundamental = estimate_model(GeometryModel::kFundamental, matches, threshold, true);
  if (!fundamental.found) return homography;
  if (homography.found && homography.inliers >= config.homography_preference * fundamental.inliers) return homography;
  return fundamental;
}

// The model refitted by least squares on its inliers (homography) or kept (the fundamental
// matrix's 8-point refit on many inliers is not better than MAGSAC's own final fit).
GeometryEstimate refine(const GeometryEstimate& estimate, const std::vector<PointMatch>& matches, double threshold_px) {
  if (!estimate.found || estimate.model != GeometryModel::kHomography) return estimate;
  std::vector<PointMatch> inliers;
  for (const PointMatch& match : matches) {
    if (geometry_error(estimate.model, estimate.matrix, match.point1, match.point2) <= threshold_px) inliers.push_back(match);
  }
  GeometryEstimate refined = estimate_model(estimate.model, inliers, threshold_px, false);
  refined.inliers = count_inliers(refined, matches, threshold_px);
  return refined.found && refined.inliers >= estimate.inliers ? refined : estimate;
}

bool weak(const GeometryEstimate& estimate, std::size_t putative, const ImagePairMatcherConfig& config) {
  return !estimate.found || estimate.inliers < config.min_inliers ||
         estimate.inliers < config.min_inlier_ratio * static_cast<double>(putative);
}

std::vector<PointMatch> to_points(const std::vector<FeatureMatch>& matches, const ImageFeatures& features1, const ImageFeatures& features2) {
  std::vector<PointMatch> points;
  points.reserve(matches.size());
  for (const FeatureMatch& match : matches) {
    points.push_back({features1.keypoints[static_cast<std::size_t>(match.query)].pt,
                      features2.keypoints[static_cast<std::size_t>(match.train)].pt, match.distance, match.query, match.train});
  }
  return points;
}

// One simulated view: the image rotated by phi, blurred along x and compressed by the tilt
// (ASIFT), and the map from view pixels back to the original image.
struct AffineView {
  cv::Mat image, mask;
  cv::Matx23d view_to_original;
};

AffineView make_view(const cv::Mat& grey, double tilt, double phi_degrees) {
  const cv::Point2d centre((grey.cols - 1) / 2.0, (grey.rows - 1) / 2.0);
  cv::Matx23d rotation = cv::getRotationMatrix2D(centre, phi_degrees, 1.0);
  // Enlarge the canvas to hold the whole rotated image.
  const double c = std::abs(rotation(0, 0)), s = std::abs(rotation(0, 1));
  const cv::Size rotated_size(static_cast<int>(std::ceil(grey.cols * c + grey.rows * s)), static_cast<int>(std::ceil(grey.cols * s + grey.rows * c)));
  rotation(0, 2) += (rotated_size.width - 1) / 2.0 - centre.x;
  rotation(1, 2) += (rotated_size.height - 1) / 2.0 - centre.y;
  cv::Mat rotated, rotated_mask;
  cv::warpAffine(grey, rotated, rotation, rotated_size, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
  cv::warpAffine(cv::Mat(grey.size(), CV_8UC1, cv::Scalar(255)), rotated_mask, rotation, rotated_size, cv::INTER_NEAREST, cv::BORDER_CONSTANT, 0);
  // Anti-aliasing along x before the compression (ASIFT: sigma = 0.8 sqrt(t^2 - 1)).
  const double sigma = 0.8 * std::sqrt(tilt * tilt - 1.0);
  cv::GaussianBlur(rotated, rotated, cv::Size(0, 0), sigma, 0.01);
  AffineView view;
  const cv::Size view_size(std::max(1, static_cast<int>(std::lround(rotated_size.width / tilt))), rotated_size.height);
  cv::resize(rotated, view.image, view_size, 0, 0, cv::INTER_LINEAR);
  cv::resize(rotated_mask, view.mask, view_size, 0, 0, cv::INTER_NEAREST);
  // No corners on the canvas's edge: the rotated image's border is an artificial edge.
  cv::erode(view.mask, view.mask, cv::Mat(), cv::Point(-1, -1), 4);
  // Resize maps pixel centres as u_view = (u_rotated + 0.5) k - 0.5, k = view width / rotated width.
  const double k = static_cast<double>(view_size.width) / rotated_size.width;
  const cv::Matx33d compress(k, 0, 0.5 * k - 0.5, 0, 1, 0, 0, 0, 1);
  const cv::Matx33d rotate(rotation(0, 0), rotation(0, 1), rotation(0, 2), rotation(1, 0), rotation(1, 1), rotation(1, 2), 0, 0, 1);
  const cv::Matx33d back = (compress * rotate).inv();
  view.view_to_original = cv::Matx23d(back(0, 0), back(0, 1), back(0, 2), back(1, 0), back(1, 1), back(1, 2));
  return view;
}

cv::Point2f apply(const cv::Matx23d& affine, const cv::Point2f& point) {
  return {static_cast<float>(affine(0, 0) * point.x + affine(0, 1) * point.y + affine(0, 2)),
          static_cast<float>(affine(1, 0) * point.x + affine(1, 1) * point.y + affine(1, 2))};
}

cv::Mat to_grey(const cv::Mat& image) {
  if (image.channels() == 1) return image;
  cv::Mat grey;
  cv::cvtColor(image, grey, image.channels() == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
  return grey;
}

// Matches of every simulated view of `source` against the other image's features. swap: the
// source is image 2 (points go to point2).
Result<std::vector<PointMatch>> affine_view_matches(const cv::Mat& source, const ImageFeatures& other, bool swap,
                                                   const ImagePairMatcherConfig& config, const FeatureExtractor& extractor) {
  const cv::Mat grey = to_grey(source);
  std::vector<PointMatch> matches;
  for (double tilt : config.view_tilts) {
    const double step = 72.0 / tilt;
    for (double phi = 0.0; phi < 180.0 - 1e-9; phi += step) {
      const AffineView view = make_view(grey, tilt, phi);
      Result<ImageFeatures> view_features = extractor.extract(view.image, view.mask);
      if (!view_features) continue;  // a view too small for features: nothing to add
      for (const FeatureMatch& match : match_descriptors(view_features->descriptors, other.descriptors, config.descriptors)) {
        const cv::Point2f in_source = apply(view.view_to_original, view_features->keypoints[static_cast<std::size_t>(match.query)].pt);
        const cv::Point2f in_other = other.keypoints[static_cast<std::size_t>(match.train)].pt;
        matches.push_back(swap ? PointMatch{in_other, in_source, match.distance, match.train, -1}
                               : PointMatch{in_source, in_other, match.distance, -1, match.train});
      }
    }
  }
  return matches;
}

// Verified matches, each keypoint used once (the smallest descriptor distance wins); a point
// from an affine view is the same as a kept point within 1.5 pixels.
std::vector<PointMatch> verified_unique(std::vector<PointMatch> candidates, const GeometryEstimate& estimate, double threshold_px,
                                        std::size_t keypoints1, std::size_t keypoints2) {
  std::stable_sort(candidates.begin(), candidates.end(), [](const PointMatch& a, const PointMatch& b) { return a.distance < b.distance; });
  std::vector<bool> used1(keypoints1, false), used2(keypoints2, false);
  std::vector<PointMatch> kept;
  constexpr double kSamePointPx = 1.5;
  for (const PointMatch& candidate : candidates) {
    if (geometry_error(estimate.model, estimate.matrix, candidate.point1, candidate.point2) > threshold_px) continue;
    if (candidate.keypoint1 >= 0 && used1[static_cast<std::size_t>(candidate.keypoint1)]) continue;
    if (candidate.keypoint2 >= 0 && used2[static_cast<std::size_t>(candidate.keypoint2)]) continue;
    if (candidate.keypoint1 < 0 || candidate.keypoint2 < 0) {
      const bool seen = std::any_of(kept.begin(), kept.end(), [&](const PointMatch& other) {
        return candidate.keypoint1 < 0 ? cv::norm(other.point1 - candidate.point1) < kSamePointPx
                                       : cv::norm(other.point2 - candidate.point2) < kSamePointPx;
      });
      if (seen) continue;
    }
    if (candidate.keypoint1 >= 0) used1[static_cast<std::size_t>(candidate.keypoint1)] = true;
    if (candidate.keypoint2 >= 0) used2[static_cast<std::size_t>(candidate.keypoint2)] = true;
    kept.push_back(candidate);
  }
  return kept;
}

}  // namespace

Status validate(const ImagePairMatcherConfig& config) {
  if (Status features = validate(config.features); !features) return features;
  if (!(config.descriptors.ratio > 0.0 && config.descriptors.ratio <= 1.0) || !(config.guided.ratio > 0.0 && config.guided.ratio <= 1.0)) {
    return Error("ImagePairMatcherConfig: ratio tests must be in (0, 1]", "ratio");
  }
  if (!(config.ransac_threshold_px > 0.0) || !(config.guided.radius_px > 0.0)) {
    return Error("ImagePairMatcherConfig: ransac_threshold_px and guided.radius_px must be positive", "ransac_threshold_px");
  }
  for (double tilt : config.view_tilts) {
    if (!(tilt > 1.0 && tilt <= 8.0)) return Error(fmt::format("ImagePairMatcherConfig.view_tilts: {} is outside (1, 8]", tilt), "view_tilts");
  }
  return ok_status();
}

Result<ImagePairMatches> match_image_pair(const cv::Mat& image1, const cv::Mat& image2, const ImagePairMatcherConfig& config,
                                          const FeatureExtractor* features) {
  if (Status valid = validate(config); !valid) return valid.error();
  const OrbFeatureExtractor orb(config.features);
  const FeatureExtractor& extractor = features != nullptr ? *features : orb;
  Result<ImageFeatures> features1 = with_context(extractor.extract(image1), "image 1");
  if (!features1) return features1.error();
  Result<ImageFeatures> features2 = with_context(extractor.extract(image2), "image 2");
  if (!features2) return features2.error();

  ImagePairMatches result;
  result.features1 = std::move(features1).value();
  result.features2 = std::move(features2).value();
  if (config.putative_filter) {
    DescriptorMatcherConfig mutual_only = config.descriptors;
    mutual_only.ratio = 1.0;
    mutual_only.float_ratio = 1.0;
    result.putative = config.putative_filter->filter(match_descriptors(result.features1.descriptors, result.features2.descriptors, mutual_only),
                                                     result.features1, result.features2, config.putative_filter_threshold);
  } else {
    result.putative = match_descriptors(result.features1.descriptors, result.features2.descriptors, config.descriptors);
  }
  std::vector<PointMatch> seeds = to_points(result.putative, result.features1, result.features2);

  GeometryEstimate estimate = estimate_geometry(seeds, config);
  if (weak(estimate, seeds.size(), config) && !config.view_tilts.empty()) {
    std::vector<PointMatch> pooled = seeds;
    for (bool swap : {false, true}) {
      Result<std::vector<PointMatch>> views = swap ? affine_view_matches(image2, result.features1, true, config, extractor)
                                                   : affine_view_matches(image1, result.features2, false, config, extractor);
      if (views) pooled.insert(pooled.end(), views->begin(), views->end());
    }
    GeometryEstimate from_views = estimate_geometry(pooled, config);
    if (from_views.found && from_views.inliers > estimate.inliers) {
      result.affine_views_used = true;
      result.affine_view_matches = static_cast<int>(pooled.size() - seeds.size());
      estimate = from_views;
      seeds = std::move(pooled);
    }
  }
  if (!estimate.found) {
    result.matches = std::move(seeds);
    return result;
  }
  estimate = refine(estimate, seeds, config.ransac_threshold_px);
  std::vector<PointMatch> candidates = seeds;
  const std::vector<PointMatch> guided =
      to_points(match_guided(result.features1, result.features2, estimate.model, estimate.matrix, config.guided), result.features1, result.features2);
  candidates.insert(candidates.end(), guided.begin(), guided.end());
  estimate = refine(estimate, candidates, config.ransac_threshold_px);
  result.matches = verified_unique(std::move(candidates), estimate, config.ransac_threshold_px, result.features1.size(), result.features2.size());
  result.geometry_found = true;
  result.model = estimate.model;
  result.geometry = estimate.matrix;
  return result;
}

int count_correct_matches(const std::vector<PointMatch>& matches, const cv::Matx33d& homography_1_to_2, double threshold_px) {
  int correct = 0;
  for (const PointMatch& match : matches) {
    correct += geometry_error(GeometryModel::kHomography, homography_1_to_2, match.point1, match.point2) <= threshold_px;
  }
  return correct;
}

}  // namespace hanzo::fusion::vision
