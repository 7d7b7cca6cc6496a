#include "hanzo/fusion/calib/camera_lidar_calibration.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <random>
#include <unordered_map>

#include <Eigen/Dense>
#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <tbb/parallel_for.h>

#include "checkerboard_corners.hpp"
#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::calib {
namespace {

constexpr double kDegree = std::numbers::pi / 180.0;

// A plane n . x = offset with n towards the sensor that sees it (offset < 0).
struct Plane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset = 0.0;
  double distance(const Eigen::Vector3d& point) const { return normal.dot(point) - offset; }
};

// The board's outline in its own frame: centred on the pattern.
struct Outline {
  Eigen::Vector2d center;
  double half_width = 0.0, half_height = 0.0;
};

Outline outline_of(const CameraLidarCalibrationConfig& config) {
  const CheckerboardTarget& target = config.target;
  Outline outline;
  outline.center = {0.5 * (target.inner_corners_x - 1) * target.square_size, 0.5 * (target.inner_corners_y - 1) * target.square_size};
  outline.half_width = 0.5 * (config.board_width > 0.0 ? config.board_width : (target.inner_corners_x + 1) * target.square_size);
  outline.half_height = 0.5 * (config.board_height > 0.0 ? config.board_height : (target.inner_corners_y + 1) * target.square_size);
  return outline;
}

// ---- camera ----------------------------------------------------------------------------------

Result<SE3> board_pose(const std::vector<cv::Point2f>& corners, const std::vector<cv::Point3f>& object, const msgs::CameraIntrinsics& intrinsics,
                       const msgs::DistortionModel& distortion) {
  const cv::Matx33d K(intrinsics.fx, 0.0, intrinsics.cx, 0.0, intrinsics.fy, intrinsics.cy, 0.0, 0.0, 1.0);
  cv::Mat coefficients(distortion.coefficients, true);
  std::vector<cv::Point2f> points = corners;
  cv::Matx33d camera_matrix = K;
  cv::Mat pnp_coefficients = distortion.type == msgs::DistortionType::kRadtan ? coefficients : cv::Mat();
  if (distortion.type == msgs::DistortionType::kEquidistant) {
    cv::fisheye::undistortPoints(corners, points, K, coefficients);  // normalized coordinates
    camera_matrix = cv::Matx33d::eye();
  }
  cv::Vec3d rotation_vector, translation;
  if (!cv::solvePnP(object, points, camera_matrix, pnp_coefficients, rotation_vector, translation, false, cv::SOLVEPNP_IPPE)) {
    return Error("solvePnP found no board pose");
  }
  cv::solvePnPRefineLM(object, points, camera_matrix, pnp_coefficients, rotation_vector, translation);
  cv::Matx33d rotation;
  cv::Rodrigues(rotation_vector, rotation);
  Eigen::Matrix3d R;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R(r, c) = rotation(r, c);
  }
  return SE3(SO3::from_matrix(R), Eigen::Vector3d(translation[0], translation[1], translation[2]));
}

double mean_corner_motion(const std::vector<Eigen::Vector2f>& a, const std::vector<Eigen::Vector2f>& b) {
  if (a.size() != b.size() || a.empty()) return std::numeric_limits<double>::infinity();
  double sum = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) sum += (a[i] - b[i]).norm();
  return sum / static_cast<double>(a.size());
}

// ---- LiDAR -----------------------------------------------------------------------------------

Plane fit_plane(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) centroid += p;
  centroid /= static_cast<double>(points.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : points) scatter += (p - centroid) * (p - centroid).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(scatter);
  Plane plane;
  plane.normal = solver.eigenvectors().col(0);
  if (plane.normal.dot(centroid) > 0.0) plane.normal = -plane.normal;
  plane.offset = plane.normal.dot(centroid);
  return plane;
}

// RANSAC over three-point planes (deterministic seed), refit on the inliers of the best.
std::vector<std::size_t> ransac_plane(const std::vector<Eigen::Vector3d>& points, double threshold, std::mt19937& random) {
  std::vector<std::size_t> best;
  if (points.size() < 3) return best;
  std::uniform_int_distribution<std::size_t> pick(0, points.size() - 1);
  const auto inliers_of = [&](const Plane& plane) {
    std::vector<std::size_t> inliers;
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (std::abs(plane.distance(points[i])) <= threshold) inliers.push_back(i);
    }
    return inliers;
  };
  for (int iteration = 0; iteration < 200; ++iteration) {
    const Eigen::Vector3d& a = points[pick(random)];
    const Eigen::Vector3d& b = points[pick(random)];
    const Eigen::Vector3d& c = points[pick(random)];
    const Eigen::Vector3d normal = (b - a).cross(c - a);
    if (normal.norm() < 1e-9) continue;
    Plane plane;
    plane.normal = normal.normalized();
    plane.offset = plane.normal.dot(a);
    std::vector<std::size_t> inliers = inliers_of(plane);
    if (inliers.size() > best.size()) best = std::move(inliers);
  }
  if (best.size() < 3) return best;
  std::vector<Eigen::Vector3d> chosen;
  for (std::size_t i : best) chosen.push_back(points[i]);
  return inliers_of(fit_plane(chosen));
}

// The board as the LiDAR saw it in one scan.
struct LidarBoard {
  Plane plane;
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector3d> edges;  // on the plane, half a step out
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
};

struct Scan {
  std::vector<Eigen::Vector3d> points;
  std::vector<uint32_t> rings;  // ring_ids, or elevation bins of 0.1 deg
};

Scan scan_of(const msgs::PointCloudMessage& cloud) {
  Scan scan;
  scan.points.reserve(cloud.points.size());
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    const Eigen::Vector3d p = cloud.points[i].cast<double>();
    if (!p.allFinite() || p.norm() < 1e-3) continue;
    scan.points.push_back(p);
    if (cloud.ring_ids.size() == cloud.points.size()) {
      scan.rings.push_back(cloud.ring_ids[i]);
    } else {
      const double elevation = std::atan2(p.z(), p.head<2>().norm()) / kDegree;
      scan.rings.push_back(static_cast<uint32_t>(std::lround((elevation + 90.0) * 10.0)));
    }
  }
  return scan;
}

// Edge points: the ends of each ring on the board, moved onto the plane along their rays and
// out by half the ring's median point spacing.
std::vector<Eigen::Vector3d> ring_ends(const std::vector<Eigen::Vector3d>& points, const std::vector<uint32_t>& rings, const Plane& plane) {
  std::map<uint32_t, std::vector<Eigen::Vector3d>> by_ring;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d ray = points[i].normalized();
    const double along = ray.dot(plane.normal);
    if (std::abs(along) < 0.05) continue;  // grazing: the intersection is unstable
    by_ring[rings[i]].push_back(ray * (plane.offset / along));
  }
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) mean += p;
  const double reference = std::atan2(mean.y(), mean.x());
  std::vector<Eigen::Vector3d> edges;
  for (auto& [ring, on_plane] : by_ring) {
    if (on_plane.size() < 3) continue;
    const auto azimuth = [reference](const Eigen::Vector3d& p) { return std::remainder(std::atan2(p.y(), p.x()) - reference, 2.0 * std::numbers::pi); };
    std::sort(on_plane.begin(), on_plane.end(), [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return azimuth(a) < azimuth(b); });
    std::vector<double> steps;
    for (std::size_t i = 1; i < on_plane.size(); ++i) steps.push_back((on_plane[i] - on_plane[i - 1]).norm());
    std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2), steps.end());
    const double step = steps[steps.size() / 2];
    const Eigen::Vector3d direction = (on_plane.back() - on_plane.front()).normalized();
    edges.push_back(on_plane.front() - 0.5 * step * direction);
    edges.push_back(on_plane.back() + 0.5 * step * direction);
  }
  return edges;
}

LidarBoard board_from_inliers(const Scan& scan, const std::vector<std::size_t>& indices) {
  LidarBoard board;
  std::vector<uint32_t> rings;
  for (std::size_t i : indices) {
    board.points.push_back(scan.points[i]);
    rings.push_back(scan.rings[i]);
  }
  board.plane = fit_plane(board.points);
  for (const Eigen::Vector3d& p : board.points) board.centroid += p;
  board.centroid /= static_cast<double>(board.points.size());
  board.edges = ring_ends(board.points, rings, board.plane);
  return board;
}

// Connected patches of points on one plane: a 2D grid of `cell` m, 8-neighbourhood.
std::vector<std::vector<std::size_t>> patches_on_plane(const std::vector<Eigen::Vector3d>& points, const std::vector<std::size_t>& indices,
                                                       const Plane& plane, double cell) {
  const Eigen::Vector3d u = plane.normal.unitOrthogonal(), v = plane.normal.cross(u);
  std::unordered_map<int64_t, std::vector<std::size_t>> cells;
  const auto key = [](int64_t x, int64_t y) { return (x << 32) ^ (y & 0xFFFFFFFF); };
  std::vector<std::pair<int64_t, int64_t>> coordinates;
  for (std::size_t k = 0; k < indices.size(); ++k) {
    const Eigen::Vector3d& p = points[indices[k]];
    const auto x = static_cast<int64_t>(std::floor(p.dot(u) / cell)), y = static_cast<int64_t>(std::floor(p.dot(v) / cell));
    coordinates.emplace_back(x, y);
    cells[key(x, y)].push_back(k);
  }
  std::vector<int> label(indices.size(), -1);
  std::vector<std::vector<std::size_t>> patches;
  for (std::size_t seed = 0; seed < indices.size(); ++seed) {
    if (label[seed] >= 0) continue;
    const int id = static_cast<int>(patches.size());
    std::vector<std::size_t>& patch = patches.emplace_back();
    std::vector<std::size_t> stack{seed};
    label[seed] = id;
    while (!stack.empty()) {
      const std::size_t k = stack.back();
      stack.pop_back();
      patch.push_back(indices[k]);
      for (int64_t dx = -1; dx <= 1; ++dx) {
        for (int64_t dy = -1; dy <= 1; ++dy) {
          const auto found = cells.find(key(coordinates[k].first + dx, coordinates[k].second + dy));
          if (found == cells.end()) continue;
          for (std::size_t other : found->second) {
            if (label[other] < 0) {
              label[other] = id;
              stack.push_back(other);
            }
          }
        }
      }
    }
  }
  return patches;
}

// Without an estimate: the one plane patch of the board's size in the range shell where the
// board must be. nullopt when there is none or more than one.
std::optional<LidarBoard> find_board_by_size(const Scan& scan, const SE3& T_camera_board, const Outline& outline,
                                             const CameraLidarCalibrationConfig& config, std::mt19937& random) {
  double near = std::numeric_limits<double>::infinity(), far = 0.0;
  for (const double sx : {-1.0, 1.0}) {
    for (const double sy : {-1.0, 1.0}) {
      const Eigen::Vector3d corner(outline.center.x() + sx * outline.half_width, outline.center.y() + sy * outline.half_height, 0.0);
      const double range = (T_camera_board * corner).norm();
      near = std::min(near, range);
      far = std::max(far, range);
    }
  }
  std::vector<std::size_t> shell;
  for (std::size_t i = 0; i < scan.points.size(); ++i) {
    const double range = scan.points[i].norm();
    if (range >= near - config.max_sensor_offset && range <= far + config.max_sensor_offset) shell.push_back(i);
  }
  const double width = 2.0 * outline.half_width, height = 2.0 * outline.half_height;
  const double diagonal = std::hypot(width, height), tolerance = config.board_size_tolerance;
  const double cell = 0.05 + 0.04 * 0.5 * (near + far);  // > the ring spacing of a 2 deg LiDAR at that range
  std::vector<LidarBoard> candidates;
  std::vector<std::size_t> remaining = shell;
  for (int plane_count = 0; plane_count < 5 && remaining.size() >= config.min_board_points; ++plane_count) {
    std::vector<Eigen::Vector3d> points;
    for (std::size_t i : remaining) points.push_back(scan.points[i]);
    const std::vector<std::size_t> inliers_local = ransac_plane(points, config.plane_inlier_threshold, random);
    if (inliers_local.size() < config.min_board_points) break;
    std::vector<std::size_t> inliers;
    std::vector<Eigen::Vector3d> inlier_points;
    std::vector<bool> taken(remaining.size(), false);
    for (std::size_t k : inliers_local) {
      inliers.push_back(remaining[k]);
      inlier_points.push_back(points[k]);
      taken[k] = true;
    }
    for (const std::vector<std::size_t>& patch : patches_on_plane(scan.points, inliers, fit_plane(inlier_points), cell)) {
      if (patch.size() < config.min_board_points) continue;
      LidarBoard board = board_from_inliers(scan, patch);
      // In-plane extents along the patch's principal axes.
      Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
      for (const Eigen::Vector3d& p : board.points) scatter += (p - board.centroid) * (p - board.centroid).transpose();
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(scatter);
      std::array<double, 2> extent{};
      for (int axis = 0; axis < 2; ++axis) {
        const Eigen::Vector3d direction = solver.eigenvectors().col(2 - axis);
        double low = std::numeric_limits<double>::infinity(), high = -low;
        for (const Eigen::Vector3d& p : board.points) {
          low = std::min(low, direction.dot(p));
          high = std::max(high, direction.dot(p));
        }
        extent[axis] = high - low;
      }
      const bool fits = extent[0] <= (1.0 + tolerance) * diagonal && extent[0] >= (1.0 - tolerance) * std::min(width, height) &&
                        extent[1] <= (1.0 + tolerance) * std::max(width, height) && extent[1] >= 0.25 * std::min(width, height);
      if (fits) candidates.push_back(std::move(board));
    }
    std::vector<std::size_t> rest;
    for (std::size_t k = 0; k < remaining.size(); ++k) {
      if (!taken[k]) rest.push_back(remaining[k]);
    }
    remaining = std::move(rest);
  }
  if (candidates.size() != 1) return std::nullopt;
  return std::move(candidates.front());
}

// With an estimate: the points near the predicted board, refit by RANSAC.
std::optional<LidarBoard> find_board_near(const Scan& scan, const SE3& T_lidar_board, const Outline& outline, const CameraLidarCalibrationConfig& config,
                                          std::mt19937& random) {
  const SE3 T_board_lidar = T_lidar_board.inverse();
  std::vector<std::size_t> near;
  std::vector<Eigen::Vector3d> points;
  for (std::size_t i = 0; i < scan.points.size(); ++i) {
    const Eigen::Vector3d q = T_board_lidar * scan.points[i];
    if (std::abs(q.z()) > config.plane_gate) continue;
    if (std::abs(q.x() - outline.center.x()) > outline.half_width + config.edge_margin) continue;
    if (std::abs(q.y() - outline.center.y()) > outline.half_height + config.edge_margin) continue;
    near.push_back(i);
    points.push_back(scan.points[i]);
  }
  if (near.size() < config.min_board_points) return std::nullopt;
  std::vector<std::size_t> inliers;
  for (std::size_t k : ransac_plane(points, config.plane_inlier_threshold, random)) inliers.push_back(near[k]);
  if (inliers.size() < config.min_board_points) return std::nullopt;
  return board_from_inliers(scan, inliers);
}

// ---- solve -----------------------------------------------------------------------------------

struct ViewData {
  std::size_t scan = 0;
  std::size_t station = 0;
  Timestamp image_time;
  SE3 T_camera_board;
  std::optional<LidarBoard> board;
};

struct Constraint {
  Eigen::Vector3d point;      // LiDAR frame
  Eigen::Vector3d direction;  // camera frame, unit
  double offset = 0.0;
};

// The plane constraint of a view: n_c . x = n_c . t_camera_board.
Constraint plane_constraint(const SE3& T_camera_board, const Eigen::Vector3d& point) {
  const Eigen::Vector3d normal = T_camera_board.rotation() * Eigen::Vector3d::UnitZ();
  return {point, normal, normal.dot(T_camera_board.translation())};
}

// The edge of the outline nearest to the point (board frame), as a constraint within the
// plane; nullopt when the point is off every edge's extent or far from all.
std::optional<Constraint> edge_constraint(const SE3& T_camera_board, const Outline& outline, const Eigen::Vector3d& point_lidar,
                                          const SE3& T_camera_lidar, double margin) {
  const Eigen::Vector3d q = T_camera_board.inverse() * (T_camera_lidar * point_lidar);
  const double x = q.x() - outline.center.x(), y = q.y() - outline.center.y();
  // (distance, board-frame direction, board-frame offset, along-edge coordinate, half length)
  struct Candidate {
    double distance;
    Eigen::Vector3d direction;
    double offset, along, half_length;
  };
  // Directions point out of the board, so that a residual is the distance outside the edge.
  const std::array<Candidate, 4> edges{{
      {std::abs(x - outline.half_width), Eigen::Vector3d::UnitX(), outline.center.x() + outline.half_width, y, outline.half_height},
      {std::abs(x + outline.half_width), -Eigen::Vector3d::UnitX(), -(outline.center.x() - outline.half_width), y, outline.half_height},
      {std::abs(y - outline.half_height), Eigen::Vector3d::UnitY(), outline.center.y() + outline.half_height, x, outline.half_width},
      {std::abs(y + outline.half_height), -Eigen::Vector3d::UnitY(), -(outline.center.y() - outline.half_height), x, outline.half_width},
  }};
  const Candidate& nearest = *std::min_element(edges.begin(), edges.end(), [](const Candidate& a, const Candidate& b) { return a.distance < b.distance; });
  if (nearest.distance > margin || std::abs(nearest.along) > nearest.half_length + 0.02) return std::nullopt;
  const Eigen::Vector3d direction = T_camera_board.rotation() * nearest.direction;
  return Constraint{point_lidar, direction, nearest.offset + direction.dot(T_camera_board.translation())};
}

struct Solution {
  SE3 T_camera_lidar;
  double plane_sigma = 0.02, edge_sigma = 0.005;  // m
};

double rms(const std::vector<double>& values) {
  double sum = 0.0;
  for (double value : values) sum += value * value;
  return values.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(values.size()));
}

double robust_sigma(std::vector<double> residuals, double fallback) {
  if (residuals.size() < 10) return fallback;
  for (double& r : residuals) r = std::abs(r);
  std::nth_element(residuals.begin(), residuals.begin() + static_cast<std::ptrdiff_t>(residuals.size() / 2), residuals.end());
  return std::max(1.4826 * residuals[residuals.size() / 2], 1e-4);
}

// Gauss-Newton on T_camera_lidar (right perturbation), Huber at 2 sigma per kind; edge
// associations redone every iteration. `skip_station` leaves one station out (jackknife).
Solution solve(const std::vector<ViewData>& views, const Outline& outline, Solution start, std::optional<std::size_t> skip_station, int iterations) {
  Solution solution = start;
  for (int iteration = 0; iteration < iterations; ++iteration) {
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
    std::vector<double> plane_residuals, edge_residuals;
    const auto add = [&](const Constraint& c, double sigma, std::vector<double>* residuals) {
      Eigen::Matrix<double, 1, 6> J;
      const double r = point_constraint_residual(solution.T_camera_lidar, c.point, c.direction, c.offset, &J);
      residuals->push_back(r);
      const double scaled = std::abs(r) / sigma;
      const double weight = (scaled <= 2.0 ? 1.0 : 2.0 / scaled) / (sigma * sigma);
      H += weight * J.transpose() * J;
      g += weight * J.transpose() * r;
    };
    for (const ViewData& view : views) {
      if (!view.board || (skip_station && view.station == *skip_station)) continue;
      for (const Eigen::Vector3d& p : view.board->points) add(plane_constraint(view.T_camera_board, p), solution.plane_sigma, &plane_residuals);
      for (const Eigen::Vector3d& p : view.board->edges) {
        const auto edge = edge_constraint(view.T_camera_board, outline, p, solution.T_camera_lidar, 0.15);
        if (edge) add(*edge, solution.edge_sigma, &edge_residuals);
      }
    }
    const Eigen::Matrix<double, 6, 1> delta = -H.ldlt().solve(g);
    if (!delta.allFinite()) break;
    solution.T_camera_lidar = solution.T_camera_lidar * SE3::exp(delta);
    solution.plane_sigma = robust_sigma(plane_residuals, solution.plane_sigma);
    solution.edge_sigma = robust_sigma(edge_residuals, solution.edge_sigma);
    if (delta.norm() < 1e-9) break;
  }
  return solution;
}

// Closed form from the planes (and, weakly, the board centres): n_c = R n_l (Kabsch), then
// n_c . t = d_c - d_l.
SE3 planes_closed_form(const std::vector<ViewData>& views, const Outline& outline) {
  Eigen::Matrix3d correlation = Eigen::Matrix3d::Zero();
  for (const ViewData& view : views) {
    if (!view.board) continue;
    Eigen::Vector3d normal_camera = view.T_camera_board.rotation() * Eigen::Vector3d::UnitZ();
    if (normal_camera.dot(view.T_camera_board.translation()) > 0.0) normal_camera = -normal_camera;
    correlation += view.board->plane.normal * normal_camera.transpose();
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(correlation, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d sign = Eigen::Matrix3d::Identity();
  sign(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  const Eigen::Matrix3d R = svd.matrixV() * sign * svd.matrixU().transpose();
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  constexpr double kCentreWeight = 0.04;  // (0.2)^2: the LiDAR's centroid is only near the board's centre
  for (const ViewData& view : views) {
    if (!view.board) continue;
    Eigen::Vector3d normal_camera = view.T_camera_board.rotation() * Eigen::Vector3d::UnitZ();
    if (normal_camera.dot(view.T_camera_board.translation()) > 0.0) normal_camera = -normal_camera;
    const double d_camera = normal_camera.dot(view.T_camera_board.translation());
    A += normal_camera * normal_camera.transpose();
    b += normal_camera * (d_camera - view.board->plane.offset);
    const Eigen::Vector3d centre_camera = view.T_camera_board * Eigen::Vector3d(outline.center.x(), outline.center.y(), 0.0);
    A += kCentreWeight * Eigen::Matrix3d::Identity();
    b += kCentreWeight * (centre_camera - R * view.board->centroid);
  }
  return SE3(SO3::from_matrix(R), A.ldlt().solve(b));
}

}  // namespace

double point_constraint_residual(const SE3& T_camera_lidar, const Eigen::Vector3d& point_lidar, const Eigen::Vector3d& direction_camera,
                                 double offset, Eigen::Matrix<double, 1, 6>* jacobian) {
  Eigen::Matrix<double, 3, 6> J_point;
  const Eigen::Vector3d point_camera = T_camera_lidar.act(point_lidar, jacobian != nullptr ? &J_point : nullptr);
  if (jacobian != nullptr) *jacobian = direction_camera.transpose() * J_point;
  return direction_camera.dot(point_camera) - offset;
}

Status CameraLidarCalibrationConfig::validate() const {
  if (target.inner_corners_x < 2 || target.inner_corners_y < 2 || !(target.square_size > 0.0)) {
    return Error(fmt::format("target: expected at least 2 x 2 inner corners and a square > 0 m, got {} x {}, {} m", target.inner_corners_x,
                             target.inner_corners_y, target.square_size),
                 "target");
  }
  const double pattern_width = (target.inner_corners_x + 1) * target.square_size, pattern_height = (target.inner_corners_y + 1) * target.square_size;
  if (board_width != 0.0 && !(board_width >= pattern_width - 1e-9)) {
    return Error(fmt::format("board_width: {} m is narrower than the pattern ({} m)", board_width, pattern_width), "board_width");
  }
  if (board_height != 0.0 && !(board_height >= pattern_height - 1e-9)) {
    return Error(fmt::format("board_height: {} m is lower than the pattern ({} m)", board_height, pattern_height), "board_height");
  }
  const auto positive = [](double value, const char* name) -> Status {
    if (!(value > 0.0)) return Error(fmt::format("{}: expected > 0, got {}", name, value), name);
    return ok_status();
  };
  HANZO_RETURN_IF_ERROR(positive(max_sensor_offset, "max_sensor_offset"));
  HANZO_RETURN_IF_ERROR(positive(max_corner_motion_px, "max_corner_motion_px"));
  HANZO_RETURN_IF_ERROR(positive(plane_inlier_threshold, "plane_inlier_threshold"));
  HANZO_RETURN_IF_ERROR(positive(plane_gate, "plane_gate"));
  HANZO_RETURN_IF_ERROR(positive(edge_margin, "edge_margin"));
  HANZO_RETURN_IF_ERROR(positive(max_position_sigma, "max_position_sigma"));
  HANZO_RETURN_IF_ERROR(positive(max_rotation_sigma_deg, "max_rotation_sigma_deg"));
  HANZO_RETURN_IF_ERROR(positive(max_edge_bias, "max_edge_bias"));
  if (!(board_size_tolerance > 0.0 && board_size_tolerance < 1.0)) return Error("board_size_tolerance: expected in (0, 1)", "board_size_tolerance");
  if (min_board_points < 10) return Error("min_board_points: expected >= 10", "min_board_points");
  if (min_stations < 3) return Error("min_stations: expected >= 3 (the jackknife leaves one out)", "min_stations");
  if (!(min_normal_spread_deg >= 0.0)) return Error("min_normal_spread_deg: expected >= 0", "min_normal_spread_deg");
  return ok_status();
}

Result<std::vector<BoardObservation>> observe_board(const std::vector<msgs::ImageMessage>& images, const msgs::CameraIntrinsics& intrinsics,
                                                    const msgs::DistortionModel& distortion, const CheckerboardTarget& target) {
  if (!(intrinsics.fx > 0.0 && intrinsics.fy > 0.0) || !std::isfinite(intrinsics.cx) || !std::isfinite(intrinsics.cy)) {
    return Error(fmt::format("intrinsics: expected fx, fy > 0, got {}, {}", intrinsics.fx, intrinsics.fy), "intrinsics");
  }
  const std::vector<cv::Point3f> object = board_points(target);
  std::vector<BoardObservation> boards(images.size());
  std::vector<cv::Mat> greys(images.size());
  for (std::size_t i = 0; i < images.size(); ++i) {
    HANZO_ASSIGN_OR_RETURN(greys[i], grey_of(images[i], i));
    boards[i].time = images[i].timestamp;
  }
  tbb::parallel_for(std::size_t{0}, images.size(), [&](std::size_t i) {
    std::vector<cv::Point2f> corners;
    if (!find_checkerboard_corners(greys[i], target, &corners)) return;
    const Result<SE3> pose = board_pose(corners, object, intrinsics, distortion);
    if (!pose) return;
    boards[i].found = true;
    boards[i].T_camera_board = *pose;
    for (const cv::Point2f& corner : corners) boards[i].corners.emplace_back(corner.x, corner.y);
  });
  return boards;
}

Result<CameraLidarCalibrationResult> calibrate_camera_lidar(const std::vector<msgs::ImageMessage>& images, const msgs::CameraIntrinsics& intrinsics,
                                                            const msgs::DistortionModel& distortion,
                                                            const std::vector<msgs::PointCloudMessage>& scans,
                                                            const CameraLidarCalibrationConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  if (images.empty()) return Error("images: none given", "images");
  std::vector<BoardObservation> boards;
  HANZO_ASSIGN_OR_RETURN(boards, observe_board(images, intrinsics, distortion, config.target));
  return calibrate_camera_lidar(boards, scans, config);
}

Result<CameraLidarCalibrationResult> calibrate_camera_lidar(const std::vector<BoardObservation>& observed,
                                                            const std::vector<msgs::PointCloudMessage>& scans,
                                                            const CameraLidarCalibrationConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  if (observed.empty()) return Error("images: none given", "images");
  if (scans.empty()) return Error("scans: none given", "scans");
  CameraLidarCalibrationResult result;
  result.images = observed.size();
  result.scans = scans.size();
  const Outline outline = outline_of(config);
  std::vector<BoardObservation> boards = observed;
  for (const BoardObservation& board : boards) result.images_with_board += board.found ? 1 : 0;
  std::stable_sort(boards.begin(), boards.end(), [](const BoardObservation& a, const BoardObservation& b) { return a.time < b.time; });

  // 2. Static scans and their board poses.
  std::vector<const msgs::PointCloudMessage*> ordered;
  for (const msgs::PointCloudMessage& scan : scans) ordered.push_back(&scan);
  std::stable_sort(ordered.begin(), ordered.end(), [](const auto* a, const auto* b) { return a->timestamp < b->timestamp; });
  std::vector<ViewData> views;
  for (std::size_t s = 0; s < ordered.size(); ++s) {
    const msgs::PointCloudMessage& scan = *ordered[s];
    if (scan.points.empty()) return Error(fmt::format("scans[{}]: no points", s), "scans");
    const Timestamp start = scan.point_timestamps.size() == scan.points.size() ? scan.point_timestamps.front() : scan.timestamp;
    Timestamp end = scan.point_timestamps.size() == scan.points.size() ? scan.point_timestamps.back()
                    : s + 1 < ordered.size()                          ? ordered[s + 1]->timestamp
                    : s > 0                                           ? scan.timestamp + (scan.timestamp - ordered[s - 1]->timestamp)
                                                                      : scan.timestamp;
    const auto before = std::upper_bound(boards.begin(), boards.end(), start, [](Timestamp t, const BoardObservation& b) { return t < b.time; });
    const auto after = std::lower_bound(boards.begin(), boards.end(), end, [](const BoardObservation& b, Timestamp t) { return b.time < t; });
    if (before == boards.begin() || after == boards.end()) {
      ++result.scans_board_moving;
      continue;
    }
    const auto first = std::prev(before);
    bool still = true;
    for (auto it = first; it <= after && still; ++it) still = it->found && mean_corner_motion(it->corners, first->corners) <= config.max_corner_motion_px;
    if (!still) {
      ++result.scans_board_moving;
      continue;
    }
    const Timestamp middle = start + Duration::from_nanoseconds((end - start).nanoseconds() / 2);
    auto nearest = first;
    for (auto it = first; it <= after; ++it) {
      if (std::abs((it->time - middle).nanoseconds()) < std::abs((nearest->time - middle).nanoseconds())) nearest = it;
    }
    ViewData& view = views.emplace_back();
    view.scan = s;
    view.image_time = nearest->time;
    view.T_camera_board = nearest->T_camera_board;
  }
  result.scans_static = views.size();
  // Stations: consecutive static views whose board poses agree.
  for (std::size_t v = 1; v < views.size(); ++v) {
    const SE3 change = views[v - 1].T_camera_board.inverse() * views[v].T_camera_board;
    const bool same = change.translation().norm() < 0.02 && change.rotation().angle() < 1.0 * kDegree;
    views[v].station = views[v - 1].station + (same ? 0 : 1);
  }

  // 3. The board in the LiDAR: by size (or near the guess), solved, then near the solution.
  std::vector<Scan> lidar_scans;
  for (const ViewData& view : views) lidar_scans.push_back(scan_of(*ordered[view.scan]));
  std::mt19937 random(17);
  const auto select_near = [&](const SE3& T_camera_lidar) {
    for (std::size_t v = 0; v < views.size(); ++v) {
      views[v].board = find_board_near(lidar_scans[v], T_camera_lidar.inverse() * views[v].T_camera_board, outline, config, random);
    }
  };
  Solution solution;
  if (config.initial_T_camera_lidar) {
    solution.T_camera_lidar = *config.initial_T_camera_lidar;
    select_near(solution.T_camera_lidar);
  } else {
    for (std::size_t v = 0; v < views.size(); ++v) views[v].board = find_board_by_size(lidar_scans[v], views[v].T_camera_board, outline, config, random);
  }
  const auto count_stations = [&] {
    std::vector<std::size_t> seen;
    for (const ViewData& view : views) {
      if (view.board && (seen.empty() || seen.back() != view.station)) seen.push_back(view.station);
    }
    std::sort(seen.begin(), seen.end());
    return static_cast<std::size_t>(std::unique(seen.begin(), seen.end()) - seen.begin());
  };
  const auto refuse_few = [&](std::size_t stations) {
    std::size_t no_board = 0;
    for (const ViewData& view : views) no_board += view.board ? 0 : 1;
    return Error(fmt::format("the board was seen by both sensors at {} station(s); {} are needed ({} scans: {} with the board moving or not in the "
                             "images before and after them, {} without the board found in the LiDAR; the board found in {} of {} images)",
                             stations, config.min_stations, result.scans, result.scans_board_moving, no_board, result.images_with_board,
                             result.images),
                 "scans");
  };
  if (count_stations() < config.min_stations) return refuse_few(count_stations());
  if (!config.initial_T_camera_lidar) solution.T_camera_lidar = planes_closed_form(views, outline);
  for (int pass = 0; pass < 3; ++pass) {
    solution = solve(views, outline, solution, std::nullopt, 30);
    select_near(solution.T_camera_lidar);
  }
  const std::size_t stations = count_stations();
  if (stations < config.min_stations) return refuse_few(stations);
  solution = solve(views, outline, solution, std::nullopt, 30);

  // Normal spread: the largest angle between two used board normals.
  std::vector<Eigen::Vector3d> normals;
  for (const ViewData& view : views) {
    if (view.board) normals.push_back(view.T_camera_board.rotation() * Eigen::Vector3d::UnitZ());
  }
  double spread = 0.0;
  for (std::size_t a = 0; a < normals.size(); ++a) {
    for (std::size_t b = a + 1; b < normals.size(); ++b) spread = std::max(spread, std::acos(std::clamp(normals[a].dot(normals[b]), -1.0, 1.0)));
  }
  result.normal_spread_deg = spread / kDegree;
  if (result.normal_spread_deg < config.min_normal_spread_deg) {
    return Error(fmt::format("the board's normals span {:.1f} deg, under {:.1f}: turn the board (or the rig) further between stations", result.normal_spread_deg,
                             config.min_normal_spread_deg),
                 "scans");
  }

  // 6. Jackknife over the stations.
  std::vector<std::size_t> station_ids;
  for (const ViewData& view : views) {
    if (view.board && (station_ids.empty() || station_ids.back() != view.station)) station_ids.push_back(view.station);
  }
  std::vector<Eigen::Matrix<double, 6, 1>> deltas;
  for (std::size_t station : station_ids) {
    const Solution left_out = solve(views, outline, solution, station, 15);
    deltas.push_back((solution.T_camera_lidar.inverse() * left_out.T_camera_lidar).log());
  }
  Eigen::Matrix<double, 6, 1> mean = Eigen::Matrix<double, 6, 1>::Zero();
  for (const auto& delta : deltas) mean += delta;
  mean /= static_cast<double>(deltas.size());
  const double n = static_cast<double>(deltas.size());
  for (const auto& delta : deltas) result.covariance += (n - 1.0) / n * (delta - mean) * (delta - mean).transpose();

  result.T_camera_lidar = solution.T_camera_lidar;
  result.stations = station_ids.size();
  result.scans_used = 0;
  std::vector<double> plane_all, edge_all;
  for (const ViewData& view : views) {
    if (!view.board) {
      ++result.scans_board_not_in_lidar;
      continue;
    }
    ++result.scans_used;
    CameraLidarView& out = result.views.emplace_back();
    out.scan_time = ordered[view.scan]->timestamp;
    out.image_time = view.image_time;
    out.station = view.station;
    out.T_camera_board = view.T_camera_board;
    out.board_points = view.board->points.size();
    std::vector<double> plane_residuals, edge_residuals;
    for (const Eigen::Vector3d& p : view.board->points) {
      const Constraint c = plane_constraint(view.T_camera_board, p);
      plane_residuals.push_back(point_constraint_residual(solution.T_camera_lidar, c.point, c.direction, c.offset));
    }
    for (const Eigen::Vector3d& p : view.board->edges) {
      const auto c = edge_constraint(view.T_camera_board, outline, p, solution.T_camera_lidar, 0.15);
      if (c) edge_residuals.push_back(point_constraint_residual(solution.T_camera_lidar, c->point, c->direction, c->offset));
    }
    out.edge_points = edge_residuals.size();
    out.plane_rms_m = rms(plane_residuals);
    out.edge_rms_m = rms(edge_residuals);
    plane_all.insert(plane_all.end(), plane_residuals.begin(), plane_residuals.end());
    edge_all.insert(edge_all.end(), edge_residuals.begin(), edge_residuals.end());
  }
  result.plane_rms_m = rms(plane_all);
  result.edge_rms_m = rms(edge_all);
  for (double r : edge_all) result.edge_bias_m += r / static_cast<double>(edge_all.size());

  // Certification: one sigma per camera-frame axis.
  const Eigen::Matrix3d R = result.T_camera_lidar.rotation().matrix();
  const Eigen::Matrix3d position = R * result.covariance.topLeftCorner<3, 3>() * R.transpose();
  const Eigen::Matrix3d rotation = R * result.covariance.bottomRightCorner<3, 3>() * R.transpose();
  Eigen::Vector3d::Index position_axis = 0, rotation_axis = 0;
  const double position_sigma = std::sqrt(position.diagonal().maxCoeff(&position_axis));
  const double rotation_sigma_deg = std::sqrt(rotation.diagonal().maxCoeff(&rotation_axis)) / kDegree;
  static constexpr std::array<const char*, 3> kAxis{"x", "y", "z"};
  const bool position_weaker = position_sigma / config.max_position_sigma >= rotation_sigma_deg / config.max_rotation_sigma_deg;
  result.weakest = position_weaker ? fmt::format("position {} (camera frame) {:.4f} m", kAxis[position_axis], position_sigma)
                                   : fmt::format("rotation about {} (camera frame) {:.3f} deg", kAxis[rotation_axis], rotation_sigma_deg);
  if (position_sigma > config.max_position_sigma || rotation_sigma_deg > config.max_rotation_sigma_deg) {
    result.not_certified_reason = fmt::format("{} is above the bounds ({} m, {} deg): record more stations with the board turned and rolled",
                                              result.weakest, config.max_position_sigma, config.max_rotation_sigma_deg);
  }
  if (std::abs(result.edge_bias_m) > config.max_edge_bias) {
    result.not_certified_reason = fmt::format("the LiDAR sees the board's edges {:.3f} m {} its outline on average (over {} m): check the board size",
                                              std::abs(result.edge_bias_m), result.edge_bias_m > 0.0 ? "outside" : "inside", config.max_edge_bias);
  }
  result.certified = result.not_certified_reason.empty();
  logger()->info("camera-LiDAR calibration: {} scans of {} at {} stations, plane {:.4f} m, edges {:.4f} m rms, weakest {}", result.scans_used,
                 result.scans, result.stations, result.plane_rms_m, result.edge_rms_m, result.weakest);
  return result;
}

}  // namespace hanzo::fusion::calib
