#include "hanzo/fusion/lidar/surface_registration.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include "hanzo/fusion/cloud/parallel.hpp"
#include "hanzo/fusion/core/so3.hpp"
#include "registration_costs.hpp"

namespace hanzo::fusion::lidar {
namespace {

// The surface near one source point, fitted from its map neighbours.
enum class Shape : uint8_t { kNone, kPlane, kLine };
struct LocalSurface {
  Shape shape = Shape::kNone;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction = Eigen::Vector3d::Zero();  // plane: unit normal; line: unit direction
};


// The normal equations (registration_costs.hpp; hessian = sum rho' J^T J with weights
// 1 / width^2, cost = sum rho' r^2 / width^2, squared_distance_sum in m^2) and how many of the
// correspondences were point-to-line (the rest point-to-plane).
struct SurfaceEquations {
  NormalEquations normal;
  std::size_t lines = 0;

  void add(const SurfaceEquations& other) {
    normal.add(other.normal);
    lines += other.lines;
  }
  std::size_t correspondences() const { return normal.correspondences; }
};

LocalSurface fit_surface(const std::vector<cloud::MapPoint>& neighbours, const SurfaceRegistrationConfig& config,
                         double min_vertical_cosine) {
  LocalSurface surface;
  if (neighbours.size() < config.min_neighbours) return surface;
  // The nearest point's measured normal, averaged with the neighbours that agree with it.
  const Eigen::Vector3f& nearest_normal = neighbours.front().normal;
  if (!nearest_normal.isZero()) {
    Eigen::Vector3d normal_sum = Eigen::Vector3d::Zero();
    Eigen::Vector3d position_sum = Eigen::Vector3d::Zero();
    std::size_t agreeing = 0;
    for (const cloud::MapPoint& point : neighbours) {
      if (point.normal.dot(nearest_normal) < config.normal_agreement) continue;
      normal_sum += point.normal.cast<double>();
      position_sum += point.position.cast<double>();
      ++agreeing;
    }
    if (agreeing >= config.min_neighbours / 2 + 1) {
      surface.shape = Shape::kPlane;
      surface.direction = normal_sum.normalized();
      surface.mean = position_sum / static_cast<double>(agreeing);
      return surface;
    }
  }
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const cloud::MapPoint& point : neighbours) mean += point.position.cast<double>();
  mean /= static_cast<double>(neighbours.size());
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const cloud::MapPoint& point : neighbours) {
    const Eigen::Vector3d d = point.position.cast<double>() - mean;
    covariance.noalias() += d * d.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(covariance / static_cast<double>(neighbours.size()));
  const Eigen::Vector3d eigenvalues = solver.eigenvalues().cwiseMax(0.0);
  surface.mean = mean;
  if (eigenvalues(1) < config.line_ratio * eigenvalues(2)) {
    surface.direction = solver.eigenvectors().col(2).normalized();
    if (std::abs(surface.direction.z()) >= min_vertical_cosine) surface.shape = Shape::kLine;
  } else if (eigenvalues(0) < config.plane_ratio * eigenvalues(1)) {
    surface.direction = solver.eigenvectors().col(0).normalized();
    surface.shape = Shape::kPlane;
  }
  return surface;
}

// Fits the surface of source points [first, last) at pose T (parallel; one result per point).
void associate(const std::vector<Eigen::Vector3f>& source, std::size_t first, std::size_t last, const cloud::VoxelHashMap& map,
               const SE3& T, const SurfaceRegistrationConfig& config, std::vector<LocalSurface>& surfaces) {
  const Eigen::Matrix3f rotation = T.rotation().matrix().cast<float>();
  const Eigen::Vector3f translation = T.translation().cast<float>();
  const double min_vertical_cosine = std::cos(config.vertical_line_angle);
  const float max_distance = static_cast<float>(config.max_neighbour_distance);
  cloud::parallel_for(last - first, config.num_threads, [&](std::size_t begin, std::size_t end) {
    std::vector<cloud::MapPoint> neighbours;
    for (std::size_t i = first + begin; i < first + end; ++i) {
      map.nearest_k(rotation * source[i] + translation, config.neighbours, max_distance, &neighbours);
      surfaces[i] = fit_surface(neighbours, config, min_vertical_cosine);
    }
  });
}

// The normal equations of source points [0, count); scales (optional): each point's factors on
// the translation and rotation halves of its Jacobian (1 + gain t_i under a coupled deskew, where
// a pose step moves the point that much).
SurfaceEquations linearize(const std::vector<Eigen::Vector3f>& source, std::size_t count, const std::vector<LocalSurface>& surfaces,
                           const SE3& T, double kernel_width, double gate, const Eigen::Vector2f* scales, int num_threads) {
  const Eigen::Matrix3d rotation = T.rotation().matrix();
  const Eigen::Vector3d translation = T.translation();
  const double inverse_width = 1.0 / kernel_width;
  std::vector<SurfaceEquations> partial(cloud::chunk_count(count));
  cloud::parallel_chunks(count, num_threads, [&](std::size_t chunk, std::size_t begin, std::size_t end) {
    SurfaceEquations local;
    for (std::size_t i = begin; i < end; ++i) {
      const LocalSurface& surface = surfaces[i];
      if (surface.shape == Shape::kNone) continue;
      const Eigen::Vector3d p = source[i].cast<double>();
      const Eigen::Vector3d offset = rotation * p + translation - surface.mean;
      const Eigen::Vector3d& direction = surface.direction;
      const bool plane = surface.shape == Shape::kPlane;
      // m: the offset's part normal to the surface (a plane's signed distance, a line's 3-vector).
      const double plane_distance = plane ? direction.dot(offset) : 0.0;
      const Eigen::Vector3d line_residual = plane ? Eigen::Vector3d::Zero() : Eigen::Vector3d(offset - direction * direction.dot(offset));
      const double distance = plane ? std::abs(plane_distance) : line_residual.norm();
      if (distance > gate) continue;
      const double scaled = distance * inverse_width;
      const double s = 1.0 + scaled * scaled;
      const double weight = inverse_width * inverse_width / (s * s);  // Geman-McClure, residuals in units of the width
      const Eigen::Vector2d scale = scales != nullptr ? Eigen::Vector2d(scales[i].cast<double>()) : Eigen::Vector2d(1.0, 1.0);
      if (plane) {
        accumulate_plane_row(p, rotation.transpose() * direction, plane_distance, weight, local.normal, scale(0), scale(1));
      } else {
        // d q / d delta = [R, -R hat(p)]; the projection P = I - d d^T is fixed.
        const Eigen::Matrix3d projection = Eigen::Matrix3d::Identity() - direction * direction.transpose();
        Eigen::Matrix<double, 3, 6> J;
        J.leftCols<3>() = scale(0) * projection * rotation;
        J.rightCols<3>() = -scale(1) * projection * rotation * SO3::hat(p);
        local.normal.hessian.noalias() += weight * J.transpose() * J;
        local.normal.gradient.noalias() += weight * J.transpose() * line_residual;
        local.normal.cost += weight * distance * distance;
        ++local.lines;
      }
      local.normal.squared_distance_sum += distance * distance;
      ++local.normal.correspondences;
    }
    partial[chunk] = local;
  });
  SurfaceEquations total;
  for (const SurfaceEquations& chunk : partial) total.add(chunk);
  return total;
}

// Below this many points in the coarse subset, registration uses every point from the start.
constexpr std::size_t kMinCoarsePoints = 1000;

// The points with index i % stride == 0 first (the coarse subset), then the others, each part in
// its original order.
template <typename T>
std::vector<T> coarse_first_order(const std::vector<T>& source, std::size_t stride) {
  if (stride <= 1) return source;
  std::vector<T> ordered;
  ordered.reserve(source.size());
  for (std::size_t i = 0; i < source.size(); i += stride) ordered.push_back(source[i]);
  for (std::size_t i = 0; i < source.size(); ++i) {
    if (i % stride != 0) ordered.push_back(source[i]);
  }
  return ordered;
}

// moved[i] = Exp(times[i] * twist) given[i] for i < count, to second order in the angle
// (|times[i] * rotation| is a few hundredths of a radian: the third-order term is under 0.1 mm
// at 50 m).
void move_by_twist(const std::vector<Eigen::Vector3f>& given, const std::vector<float>& times, std::size_t count, const Vector6d& twist,
                   int num_threads, std::vector<Eigen::Vector3f>& moved) {
  const Eigen::Vector3f translation_rate = twist.head<3>().cast<float>();
  const Eigen::Vector3f rotation_rate = twist.tail<3>().cast<float>();
  cloud::parallel_for(count, num_threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const Eigen::Vector3f angle = times[i] * rotation_rate;
      const Eigen::Vector3f offset = times[i] * translation_rate;
      const Eigen::Vector3f turned = angle.cross(given[i]);
      moved[i] = given[i] + turned + 0.5F * angle.cross(turned) + offset + 0.5F * angle.cross(offset);
    }
  });
}

}  // namespace

Status SurfaceRegistrationConfig::validate() const {
  if (max_iterations < 1) return Error(fmt::format("max_iterations: {} < 1", max_iterations));
  if (!(translation_tolerance > 0)) return Error(fmt::format("translation_tolerance: {} <= 0", translation_tolerance));
  if (!(rotation_tolerance > 0)) return Error(fmt::format("rotation_tolerance: {} <= 0", rotation_tolerance));
  if (!(max_correspondence_distance > 0)) {
    return Error(fmt::format("max_correspondence_distance: {} <= 0", max_correspondence_distance));
  }
  if (!(kernel_width > 0)) return Error(fmt::format("kernel_width: {} <= 0", kernel_width));
  if (!(initial_kernel_width >= 0)) return Error(fmt::format("initial_kernel_width: {} < 0", initial_kernel_width));
  if (!std::isfinite(prior_translation_sigma)) return Error("prior_translation_sigma: not finite");
  if (!std::isfinite(prior_rotation_sigma)) return Error("prior_rotation_sigma: not finite");
  if (!(vertical_line_angle >= 0 && vertical_line_angle <= M_PI / 2)) {
    return Error(fmt::format("vertical_line_angle: {} outside [0, pi/2]", vertical_line_angle));
  }
  if (neighbours < 3) return Error(fmt::format("neighbours: {} < 3", neighbours));
  if (min_neighbours < 3 || min_neighbours > neighbours) {
    return Error(fmt::format("min_neighbours: {} outside [3, neighbours = {}]", min_neighbours, neighbours));
  }
  if (!(max_neighbour_distance > 0)) return Error(fmt::format("max_neighbour_distance: {} <= 0", max_neighbour_distance));
  if (!(line_ratio > 0 && line_ratio < 1)) return Error(fmt::format("line_ratio: {} outside (0, 1)", line_ratio));
  if (!(plane_ratio > 0 && plane_ratio < 1)) return Error(fmt::format("plane_ratio: {} outside (0, 1)", plane_ratio));
  if (!(reassociation_translation >= 0)) return Error(fmt::format("reassociation_translation: {} < 0", reassociation_translation));
  if (!(reassociation_rotation >= 0)) return Error(fmt::format("reassociation_rotation: {} < 0", reassociation_rotation));
  if (min_correspondences < 6) return Error(fmt::format("min_correspondences: {} < 6", min_correspondences));
  if (coarse_stride < 1) return Error(fmt::format("coarse_stride: {} < 1", coarse_stride));
  return ok_status();
}

double translation_constraint_ratio(const Eigen::Matrix<double, 6, 6>& information) {
  const Eigen::LDLT<Eigen::Matrix3d> rotation_block(information.bottomRightCorner<3, 3>());
  if (rotation_block.info() != Eigen::Success || !(rotation_block.vectorD().minCoeff() > 0)) return 0.0;
  const Eigen::Matrix3d marginal = information.topLeftCorner<3, 3>() -
                                   information.topRightCorner<3, 3>() * rotation_block.solve(information.bottomLeftCorner<3, 3>());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(0.5 * (marginal + marginal.transpose()), Eigen::EigenvaluesOnly);
  const Eigen::Vector3d eigenvalues = solver.eigenvalues();
  if (!(eigenvalues(2) > 0)) return 0.0;
  return std::max(0.0, eigenvalues(0)) / eigenvalues(2);
}

Result<SurfaceRegistrationResult> align_to_surfaces(const std::vector<Eigen::Vector3f>& source,
                                                    const cloud::VoxelHashMap& map, const SE3& guess,
                                                    const SE3& T_prior, const SurfaceRegistrationConfig& config,
                                                    const DeskewCoupling* deskew) {
  HANZO_RETURN_IF_ERROR(with_context(config.validate(), "surface registration"));
  if (source.empty()) return Error("surface registration: the source has no points");
  const bool coupled = deskew != nullptr && (deskew->translation_gain != 0.0 || deskew->rotation_gain != 0.0);
  if (coupled) {
    if (!std::isfinite(deskew->translation_gain) || !std::isfinite(deskew->rotation_gain)) {
      return Error("surface registration: a deskew coupling gain is not finite");
    }
    if (deskew->times.size() != source.size()) {
      return Error(fmt::format("surface registration: {} deskew times for {} source points", deskew->times.size(), source.size()));
    }
    const double larger_gain = std::max(std::abs(deskew->translation_gain), std::abs(deskew->rotation_gain));
    for (std::size_t i = 0; i < source.size(); ++i) {
      if (!(larger_gain * std::abs(static_cast<double>(deskew->times[i])) < 1.0)) {
        return Error(fmt::format("surface registration: deskew time {} s of point {} with gains {} and {} /s: |gain * time| must be < 1",
                                 deskew->times[i], i, deskew->translation_gain, deskew->rotation_gain));
      }
    }
  }
  // The residuals' weights are 1 / kernel_width^2 (times the kernel), the prior's 1 / sigma^2.
  Vector6d prior_information = Vector6d::Zero();
  if (config.prior_translation_sigma > 0) {
    prior_information.head<3>().setConstant(1.0 / (config.prior_translation_sigma * config.prior_translation_sigma));
  }
  if (config.prior_rotation_sigma > 0) {
    prior_information.tail<3>().setConstant(1.0 / (config.prior_rotation_sigma * config.prior_rotation_sigma));
  }
  const SE3 T_prior_inverse = T_prior.inverse();
  SurfaceRegistrationResult result;
  result.T_map_source = guess;
  SurfaceEquations equations;
  // The coarse subset (every coarse_stride-th point) first, then the rest: the points are
  // reordered so that the points in use are always a prefix.
  double width = std::max(config.kernel_width, config.initial_kernel_width);
  std::vector<Eigen::Vector3f> ordered = coarse_first_order(source, config.coarse_stride);
  // Coupled deskew: the points as given (deskewed at T_prior), their times, and the factors
  // 1 + gain t_i by which a pose step moves each (its Jacobian's scales).
  std::vector<Eigen::Vector3f> ordered_given;
  std::vector<float> ordered_times;
  std::vector<Eigen::Vector2f> scales;
  Vector6d gains = Vector6d::Zero();
  if (coupled) {
    ordered_given = ordered;
    ordered_times = coarse_first_order(deskew->times, config.coarse_stride);
    const Eigen::Vector2f gain(static_cast<float>(deskew->translation_gain), static_cast<float>(deskew->rotation_gain));
    scales.resize(ordered_times.size());
    for (std::size_t i = 0; i < scales.size(); ++i) scales[i] = Eigen::Vector2f::Ones() + ordered_times[i] * gain;
    gains << Eigen::Vector3d::Constant(deskew->translation_gain), Eigen::Vector3d::Constant(deskew->rotation_gain);
  }
  const std::size_t coarse_count = (source.size() + config.coarse_stride - 1) / config.coarse_stride;
  std::size_t active = coarse_count >= kMinCoarsePoints && width > config.kernel_width ? coarse_count : ordered.size();
  std::size_t associated = 0;  // prefix of `ordered` whose surfaces are fitted
  std::vector<LocalSurface> surfaces(ordered.size());
  SE3 associated_at;
  double mean_range = 0.0;  // m: turns a rotation step into the points' displacement
  for (const Eigen::Vector3f& point : source) mean_range += static_cast<double>(point.norm());
  mean_range /= static_cast<double>(source.size());
  for (int iteration = 1; iteration <= config.max_iterations; ++iteration) {
    if (coupled) {
      const Vector6d twist_change = gains.cwiseProduct((T_prior_inverse * result.T_map_source).log());
      move_by_twist(ordered_given, ordered_times, active, twist_change, config.num_threads, ordered);
    }
    const SE3::Tangent moved = (associated_at.inverse() * result.T_map_source).log();
    if (iteration == 1 || moved.head<3>().norm() > config.reassociation_translation ||
        moved.tail<3>().norm() > config.reassociation_rotation) {
      associated = 0;
      associated_at = result.T_map_source;
      ++result.associations;
    }
    // Points taken into use since the last fit join it (the estimate is within the
    // re-association thresholds of where it was made).
    if (associated < active) {
      associate(ordered, associated, active, map, result.T_map_source, config, surfaces);
      associated = active;
    }
    // Coarse to fine: the kernel starts wide (a poor prediction, e.g. the constant-velocity
    // model at the start of a turn, still finds its correspondences) and halves down to
    // kernel_width once a step moves the points by less than half the width (a step still
    // moving them further means the estimate is that far off: a narrower kernel would
    // down-weight the correspondences that pull it there and crawl); the gate follows at three
    // widths.
    const bool finest = width <= config.kernel_width;
    equations = linearize(ordered, active, surfaces, result.T_map_source, width, std::max(config.max_correspondence_distance, 3.0 * width),
                          coupled ? scales.data() : nullptr, config.num_threads);
    if (equations.correspondences() < config.min_correspondences && active < ordered.size()) {
      active = ordered.size();  // too few on the subset: all points from here on
      --iteration;
      continue;
    }
    if (equations.correspondences() < config.min_correspondences) {
      return Error(fmt::format("surface registration: {} of {} points matched a map surface within {} m {}(need {}); "
                               "the map does not overlap the scan at this pose",
                               equations.correspondences(), source.size(), config.max_correspondence_distance,
                               iteration == 1 ? "at the guess " : fmt::format("after {} iterations ", iteration - 1),
                               config.min_correspondences));
    }
    // Prior residual e = Log(T_prior^-1 T); d e / d delta ~ identity near the prior.
    const Vector6d prior_error = (T_prior_inverse * result.T_map_source).log();
    Matrix6d hessian = equations.normal.hessian;
    hessian.diagonal() += prior_information;
    hessian.diagonal().array() += 1e-9 * std::max(1.0, equations.normal.hessian.diagonal().maxCoeff());
    const Vector6d gradient = equations.normal.gradient + prior_information.cwiseProduct(prior_error);
    const Vector6d delta = hessian.ldlt().solve(-gradient);
    if (!delta.allFinite()) {
      return Error(fmt::format("surface registration: the normal equations are singular at iteration {}", iteration));
    }
    result.T_map_source = result.T_map_source * SE3::exp(delta);
    result.iterations = iteration;
    if (active < ordered.size()) ++result.coarse_iterations;
    const double displacement = delta.head<3>().norm() + delta.tail<3>().norm() * mean_range;
    if (!finest && displacement < 0.5 * width) {
      width = std::max(config.kernel_width, 0.5 * width);
      if (width <= config.kernel_width) active = ordered.size();  // coarse to fine is over: every point from here on
    }
    if (finest && delta.head<3>().norm() < config.translation_tolerance && delta.tail<3>().norm() < config.rotation_tolerance) {
      result.converged = true;
      break;
    }
  }
  result.correspondences = equations.correspondences();
  result.plane_correspondences = equations.correspondences() - equations.lines;
  result.line_correspondences = equations.lines;
  result.inlier_rmse = std::sqrt(equations.normal.squared_distance_sum / static_cast<double>(equations.correspondences()));
  const double dof = std::max(1.0, static_cast<double>(equations.correspondences()) - 6.0);
  // information = (sum rho' J^T J) / sigma^2, sigma^2 = (sum rho' r^2) / dof the a-posteriori
  // residual variance; the kernel width cancels.
  result.information = equations.normal.hessian / std::max(equations.normal.cost / dof, 1e-12);
  return result;
}

}  // namespace hanzo::fusion::lidar
