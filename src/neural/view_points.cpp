#include "hanzo/fusion/neural/view_points.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <set>
#include <utility>

#include <Eigen/Dense>
#include <opencv2/features2d.hpp>

namespace hanzo::fusion::neural {

namespace {

struct ViewFeatures {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
};

ViewFeatures detect(const PosedView& view, cv::Ptr<cv::ORB>& orb) {
  const RgbImage& image = view.image;
  cv::Mat grey(image.height, image.width, CV_8UC1);
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      const float* rgb = &image.pixels[3 * (static_cast<std::size_t>(y) * image.width + x)];
      grey.at<uint8_t>(y, x) = static_cast<uint8_t>(std::clamp(255.0f * (0.299f * rgb[0] + 0.587f * rgb[1] + 0.114f * rgb[2]), 0.0f, 255.0f));
    }
  }
  cv::Mat mask;
  if (!view.mask.empty()) {
    mask = cv::Mat(image.height, image.width, CV_8UC1);
    for (int i = 0; i < image.width * image.height; ++i) mask.data[i] = view.mask[static_cast<std::size_t>(i)] > 0.5f ? 255 : 0;
  }
  ViewFeatures features;
  orb->detectAndCompute(grey, mask, features.keypoints, features.descriptors);
  return features;
}

/// Mutual best matches that pass the ratio test (query index, train index).
std::vector<std::pair<int, int>> match(const ViewFeatures& a, const ViewFeatures& b, double ratio) {
  if (a.descriptors.rows < 2 || b.descriptors.rows < 2) return {};
  cv::BFMatcher matcher(cv::NORM_HAMMING);
  std::vector<std::vector<cv::DMatch>> forward, backward;
  matcher.knnMatch(a.descriptors, b.descriptors, forward, 2);
  matcher.knnMatch(b.descriptors, a.descriptors, backward, 1);
  std::vector<std::pair<int, int>> matches;
  for (const auto& candidates : forward) {
    if (candidates.size() < 2 || candidates[0].distance > ratio * candidates[1].distance) continue;
    const cv::DMatch& best = candidates[0];
    if (backward[static_cast<std::size_t>(best.trainIdx)].empty() || backward[static_cast<std::size_t>(best.trainIdx)][0].trainIdx != best.queryIdx) continue;
    matches.emplace_back(best.queryIdx, best.trainIdx);
  }
  return matches;
}

Eigen::Matrix<double, 3, 4> projection(const SplatCamera& camera) {
  Eigen::Matrix3d k;
  k << camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1;
  Eigen::Matrix<double, 3, 4> rt;
  rt << camera.R_camera_world, camera.t_camera_world;
  return k * rt;
}

/// Pixel of `point` (world) in the camera; none behind it.
std::optional<Eigen::Vector2d> project(const SplatCamera& camera, const Eigen::Vector3d& point) {
  const Eigen::Vector3d p = camera.R_camera_world * point + camera.t_camera_world;
  if (p.z() <= 1e-9) return std::nullopt;
  return Eigen::Vector2d(camera.fx * p.x() / p.z() + camera.cx, camera.fy * p.y() / p.z() + camera.cy);
}

}  // namespace

std::vector<Eigen::Vector3f> triangulate_view_points(const std::vector<PosedView>& views, const ViewPointsConfig& config) {
  cv::Ptr<cv::ORB> orb = cv::ORB::create(config.features_per_view);
  std::vector<ViewFeatures> features;
  features.reserve(views.size());
  for (const PosedView& view : views) features.push_back(view.image.pixels.empty() ? ViewFeatures{} : detect(view, orb));
  const double cos_max_angle = std::cos(config.max_angle_degrees * M_PI / 180.0);
  const double sin_min_parallax = std::sin(config.min_parallax_degrees * M_PI / 180.0);
  std::set<std::pair<std::size_t, std::size_t>> pairs;
  for (std::size_t i = 0; i < views.size(); ++i) {
    const Eigen::Vector3d centre = views[i].camera.centre_world();
    const Eigen::Vector3d axis = views[i].camera.R_camera_world.row(2).transpose();
    std::vector<std::pair<double, std::size_t>> near;
    for (std::size_t j = 0; j < views.size(); ++j) {
      if (j == i || axis.dot(views[j].camera.R_camera_world.row(2).transpose()) < cos_max_angle) continue;
      near.emplace_back((views[j].camera.centre_world() - centre).norm(), j);
    }
    std::sort(near.begin(), near.end());
    for (std::size_t k = 0; k < near.size() && k < static_cast<std::size_t>(config.neighbours); ++k) pairs.emplace(std::min(i, near[k].second), std::max(i, near[k].second));
  }
  std::vector<Eigen::Vector3f> points;
  for (const auto& [a, b] : pairs) {
    const SplatCamera& camera_a = views[a].camera;
    const SplatCamera& camera_b = views[b].camera;
    const Eigen::Matrix<double, 3, 4> P_a = projection(camera_a), P_b = projection(camera_b);
    for (const auto& [ia, ib] : match(features[a], features[b], config.ratio)) {
      const cv::Point2f& u_a = features[a].keypoints[static_cast<std::size_t>(ia)].pt;
      const cv::Point2f& u_b = features[b].keypoints[static_cast<std::size_t>(ib)].pt;
      Eigen::Matrix4d system;
      system.row(0) = u_a.x * P_a.row(2) - P_a.row(0);
      system.row(1) = u_a.y * P_a.row(2) - P_a.row(1);
      system.row(2) = u_b.x * P_b.row(2) - P_b.row(0);
      system.row(3) = u_b.y * P_b.row(2) - P_b.row(1);
      const Eigen::Vector4d homogeneous = Eigen::JacobiSVD<Eigen::Matrix4d>(system, Eigen::ComputeFullV).matrixV().col(3);
      if (std::abs(homogeneous.w()) < 1e-12) continue;
      const Eigen::Vector3d point = homogeneous.head<3>() / homogeneous.w();
      const std::optional<Eigen::Vector2d> seen_a = project(camera_a, point), seen_b = project(camera_b, point);
      if (!seen_a || !seen_b) continue;
      if ((*seen_a - Eigen::Vector2d(u_a.x, u_a.y)).norm() > config.max_reprojection_px || (*seen_b - Eigen::Vector2d(u_b.x, u_b.y)).norm() > config.max_reprojection_px) continue;
      const Eigen::Vector3d ray_a = (point - camera_a.centre_world()).normalized(), ray_b = (point - camera_b.centre_world()).normalized();
      if (ray_a.cross(ray_b).norm() < sin_min_parallax) continue;
      points.push_back(point.cast<float>());
    }
  }
  return points;
}

}  // namespace hanzo::fusion::neural
