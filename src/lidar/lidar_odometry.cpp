#include "hanzo/fusion/lidar/lidar_odometry.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include "hanzo/fusion/cloud/parallel.hpp"
#include "hanzo/fusion/cloud/scan_normals.hpp"
#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::lidar {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

// Inverse of an information matrix that may be singular along degenerate directions: those
// get a variance of 1e9 times the best-constrained one (the registration says nothing there).
Matrix6d covariance_from(const Matrix6d& information) {
  const Eigen::SelfAdjointEigenSolver<Matrix6d> solver(0.5 * (information + information.transpose()));
  const double largest = std::max(solver.eigenvalues().maxCoeff(), 1e-300);
  const Eigen::Matrix<double, 6, 1> variances = solver.eigenvalues().cwiseMax(largest * 1e-9).cwiseInverse();
  return solver.eigenvectors() * variances.asDiagonal() * solver.eigenvectors().transpose();
}

}  // namespace

Status LidarOdometryConfig::validate() const {
  if (!(min_range >= 0)) return Error(fmt::format("min_range: {} < 0", min_range));
  if (!(max_range > min_range)) return Error(fmt::format("max_range: {} <= min_range {}", max_range, min_range));
  if (!(map.voxel_size > 0)) return Error(fmt::format("map.voxel_size: {} <= 0", map.voxel_size));
  if (map.max_points_per_voxel < 1) return Error(fmt::format("map.max_points_per_voxel: {} < 1", map.max_points_per_voxel));
  if (!(map.max_distance > 0)) return Error(fmt::format("map.max_distance: {} <= 0", map.max_distance));
  if (!(source_voxel_size > 0)) return Error(fmt::format("source_voxel_size: {} <= 0", source_voxel_size));
  if (!(degeneracy_ratio >= 0 && degeneracy_ratio < 1)) {
    return Error(fmt::format("degeneracy_ratio: {} outside [0, 1)", degeneracy_ratio));
  }
  if (min_points < 6) return Error(fmt::format("min_points: {} < 6", min_points));
  if (!(phantom_max_range >= 0)) return Error(fmt::format("phantom_max_range: {} < 0", phantom_max_range));
  if (!(phantom_max_gap > 0)) return Error(fmt::format("phantom_max_gap: {} <= 0", phantom_max_gap));
  if (!(weather_phantom_fraction >= 0)) return Error(fmt::format("weather_phantom_fraction: {} < 0", weather_phantom_fraction));
  if (!(deskew_translation_coupling >= 0 && deskew_translation_coupling < 2)) {
    return Error(fmt::format("deskew_translation_coupling: {} outside [0, 2)", deskew_translation_coupling));
  }
  if (!(deskew_rotation_coupling >= 0 && deskew_rotation_coupling < 2)) {
    return Error(fmt::format("deskew_rotation_coupling: {} outside [0, 2)", deskew_rotation_coupling));
  }
  if (!(weather_return_ratio >= 0 && weather_return_ratio <= 1)) {
    return Error(fmt::format("weather_return_ratio: {} outside [0, 1]", weather_return_ratio));
  }
  return with_context(registration.validate(), "registration");
}

LidarOdometry::LidarOdometry(LidarOdometryConfig config, const SE3& initial_pose)
    : config_(std::move(config)), map_(config_.map), pose_(initial_pose) {}

Result<LidarOdometryEstimate> LidarOdometry::add_scan(Timestamp time, const cloud::PointCloud& scan,
                                                      const std::optional<SE3>& predicted_motion,
                                                      const std::optional<SweepMotion>& sweep_motion) {
  HANZO_RETURN_IF_ERROR(with_context(config_.validate(), "lidar odometry config"));
  if (last_time_ && time <= *last_time_) {
    return Error(fmt::format("lidar odometry: scan time {:.6f} is not after the previous scan's {:.6f}", time.seconds(),
                             last_time_->seconds()));
  }
  HANZO_RETURN_IF_ERROR(with_context(scan.validate(), "lidar odometry scan"));
  if (predicted_motion && !predicted_motion->matrix().allFinite()) {
    return Error("lidar odometry: the predicted motion is not finite");
  }

  // 1. Prediction and the twist that deskews the sweep.
  SE3 prediction = pose_;
  SE3::Tangent twist_per_second = SE3::Tangent::Zero();
  const double interval = last_time_ ? (time - *last_time_).seconds() : 0.0;  // sweeps of equal length: also between middles
  if (last_time_) {
    if (predicted_motion) {
      prediction = pose_ * *predicted_motion;
    } else if (last_interval_ > 0) {
      prediction = pose_ * SE3::exp(last_motion_.log() * (interval / last_interval_));
    }
    twist_per_second = (pose_.inverse() * prediction).log() / interval;
  }

  using Clock = std::chrono::steady_clock;
  const auto started = Clock::now();
  // 2-3. Crop, keep one measured point per map spacing, their normals from the range image,
  // deskew; registration points are those downsampled again.
  const int threads = config_.num_threads;
  const cloud::ScanNormalEstimator range_image(scan, config_.normals, threads);
  const float min_squared = static_cast<float>(config_.min_range * config_.min_range);
  const float max_squared = static_cast<float>(config_.max_range * config_.max_range);
  const float phantom_squared = static_cast<float>(config_.phantom_max_range * config_.phantom_max_range);
  // The points within range that are not lone near returns, in sweep order (chunks of the sweep
  // on the odometry's threads, joined in order).
  std::vector<std::vector<uint32_t>> chunk_in_range(cloud::chunk_count(scan.size()));
  std::vector<std::size_t> chunk_phantoms(chunk_in_range.size(), 0);
  cloud::parallel_chunks(scan.size(), threads, [&](std::size_t chunk, std::size_t begin, std::size_t end) {
    std::vector<uint32_t>& kept_here = chunk_in_range[chunk];
    kept_here.reserve(end - begin);
    for (std::size_t i = begin; i < end; ++i) {
      const float squared = scan.positions[i].squaredNorm();
      if (squared < min_squared || squared > max_squared) continue;
      if (squared < phantom_squared && range_image.isolated(i, static_cast<float>(config_.phantom_max_gap))) {
        ++chunk_phantoms[chunk];
        continue;
      }
      kept_here.push_back(static_cast<uint32_t>(i));
    }
  });
  std::vector<uint32_t> in_range = std::move(chunk_in_range.front());
  for (std::size_t chunk = 1; chunk < chunk_in_range.size(); ++chunk) {
    in_range.insert(in_range.end(), chunk_in_range[chunk].begin(), chunk_in_range[chunk].end());
  }
  const std::size_t phantoms = std::accumulate(chunk_phantoms.begin(), chunk_phantoms.end(), std::size_t{0});
  if (in_range.size() < config_.min_points) {
    return Error(fmt::format("lidar odometry: {} points within {}-{} m (need {})", in_range.size(), config_.min_range,
                             config_.max_range, config_.min_points));
  }
  // Points closer than the map's spacing would be refused by it anyway (1 cm at least).
  const std::vector<uint32_t> kept = cloud::first_point_per_voxel(scan.positions, in_range, std::max(map_.point_spacing(), 0.01), threads);
  cloud::PointCloud map_points;
  map_points.positions.resize(kept.size());
  if (scan.has_times()) map_points.times.resize(kept.size());
  cloud::parallel_for(kept.size(), threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t n = begin; n < end; ++n) {
      map_points.positions[n] = scan.positions[kept[n]];
      if (scan.has_times()) map_points.times[n] = scan.times[kept[n]];
    }
  });
  // The estimate refers to the middle of the sweep: a velocity error then warps the sweep
  // symmetrically about the estimated pose instead of shifting it (referred to the sweep start,
  // the error feeds back through the constant-velocity model and grows).
  const float middle = scan.has_times() ? 0.5F * *std::max_element(scan.times.begin(), scan.times.end()) : 0.0F;
  const Timestamp pose_time = time + Duration::from_seconds(static_cast<double>(middle));
  // The constant twist follows the registration (from the third sweep: the last motion is known):
  // twist(T) = c Log(T_previous^-1 T) / interval - (c - 1) previous twist; at the prediction,
  // with the constant-velocity model, the previous twist itself.
  bool coupled = config_.deskew && !sweep_motion && (config_.deskew_translation_coupling > 0.0 || config_.deskew_rotation_coupling > 0.0) &&
                 map_points.has_times() && last_time_ && last_interval_ > 0.0;
  DeskewCoupling coupling{.times = {}, .translation_gain = config_.deskew_translation_coupling / std::max(interval, 1e-9),
                          .rotation_gain = config_.deskew_rotation_coupling / std::max(interval, 1e-9)};
  if (coupled) {
    // A point as far from the middle as |t| moves by 1 + gain t times the pose: a sweep longer
    // than about 1.2 intervals (overlapping sweeps, times that do not start at the stamp) would
    // have points move against the pose; it keeps the predicted twist.
    const auto [earliest, latest] = std::minmax_element(scan.times.begin(), scan.times.end());
    const double farthest = std::max(static_cast<double>(*latest - middle), static_cast<double>(middle - *earliest));
    if (std::max(coupling.translation_gain, coupling.rotation_gain) * farthest >= 0.9) {
      coupled = false;
      logger()->debug("lidar odometry at {:.6f} s: points {:.3f} s from the sweep's middle: deskewed with the predicted twist",
                      time.seconds(), farthest);
    }
  }
  SE3::Tangent coupling_factors;  // c per tangent component (0: that half keeps the predicted twist)
  coupling_factors << Eigen::Vector3d::Constant(config_.deskew_translation_coupling), Eigen::Vector3d::Constant(config_.deskew_rotation_coupling);
  if (coupled) {
    const SE3::Tangent previous_twist = last_motion_.log() / last_interval_;
    for (int k = 0; k < 6; ++k) {
      const double c = coupling_factors(k);
      if (c > 0.0) twist_per_second(k) = c * twist_per_second(k) - (c - 1.0) * previous_twist(k);
    }
  }
  if (config_.deskew) deskew(map_points, sweep_motion ? *sweep_motion : SweepMotion::constant_twist(twist_per_second, middle), threads);
  std::vector<uint32_t> all(map_points.size());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<uint32_t>(i);
  const std::vector<uint32_t> source_indices = cloud::first_point_per_voxel(map_points.positions, all, config_.source_voxel_size, threads);
  std::vector<Eigen::Vector3f> source;
  source.reserve(source_indices.size());
  for (const uint32_t i : source_indices) source.push_back(map_points.positions[i]);

  LidarOdometryEstimate estimate;
  estimate.phantom_points = phantoms;
  const double returns = static_cast<double>(in_range.size() + phantoms);
  estimate.return_ratio = average_returns_ > 0.0 ? returns / average_returns_ : 1.0;
  estimate.weather_degraded = static_cast<double>(phantoms) > config_.weather_phantom_fraction * returns ||
                              estimate.return_ratio < config_.weather_return_ratio;
  const auto registration_started = Clock::now();
  estimate.preprocess_seconds = std::chrono::duration<double>(registration_started - started).count();
  estimate.time = pose_time;
  estimate.source_points = source.size();
  SE3 T_world_lidar = prediction;
  if (map_.empty()) {
    estimate.first_scan = true;
    estimate.converged = true;
  } else {
    // 4. Registration.
    SurfaceRegistrationConfig registration = config_.registration;
    registration.num_threads = config_.num_threads;
    if (coupled) {
      coupling.times.reserve(source_indices.size());
      for (const uint32_t i : source_indices) coupling.times.push_back(map_points.times[i] - middle);
    }
    auto registered = align_to_surfaces(source, map_, prediction, prediction, registration, coupled ? &coupling : nullptr);
    if (!registered) return Error(fmt::format("lidar odometry at {:.6f} s: {}", time.seconds(), registered.error().message));
    if (coupled) {  // the map points follow the twist the registration ended at
      const SE3::Tangent twist_change = coupling_factors.cwiseProduct((prediction.inverse() * registered->T_map_source).log()) / interval;
      deskew(map_points, SweepMotion::constant_twist(twist_change, middle), threads);
    }
    T_world_lidar = registered->T_map_source;
    estimate.iterations = registered->iterations;
    estimate.associations = registered->associations;
    estimate.converged = registered->converged;
    estimate.correspondences = registered->correspondences;
    estimate.plane_correspondences = registered->plane_correspondences;
    estimate.line_correspondences = registered->line_correspondences;
    estimate.inlier_rmse = registered->inlier_rmse;
    estimate.covariance = covariance_from(registered->information);
    // 5. Degeneracy.
    estimate.constraint_ratio = translation_constraint_ratio(registered->information);
    estimate.degenerate = estimate.constraint_ratio < config_.degeneracy_ratio;
    if (estimate.degenerate) {
      ++degenerate_scans_;
      logger()->debug("lidar odometry: degenerate scan at {:.6f} s (constraint ratio {:.4f})", time.seconds(),
                      estimate.constraint_ratio);
    }
  }

  const auto map_started = Clock::now();
  map_points.times.clear();
  estimate.registration_seconds = std::chrono::duration<double>(map_started - registration_started).count();
  // 6. Map update (normals only for the points the map keeps; the few degrees a normal turns
  // during the sweep are not deskewed) and state.
  const Eigen::Matrix3f rotation = T_world_lidar.rotation().matrix().cast<float>();
  map_.add(cloud::transformed(map_points, T_world_lidar).positions, T_world_lidar.translation(),
           [&](std::size_t i) { return Eigen::Vector3f(rotation * range_image.normal(kept[i])); }, threads);
  if (estimate.weather_degraded) {
    ++weather_degraded_scans_;
  } else {
    average_returns_ = average_returns_ > 0.0 ? 0.9 * average_returns_ + 0.1 * returns : returns;
  }
  estimate.T_world_lidar = T_world_lidar;
  estimate.T_previous_current = last_time_ ? pose_.inverse() * T_world_lidar : SE3();
  estimate.map_points = map_.point_count();
  if (last_time_) {
    last_motion_ = estimate.T_previous_current;
    last_interval_ = interval;
  }
  pose_ = T_world_lidar;
  last_time_ = time;
  last_scan_points_ = std::move(map_points.positions);
  ++scans_;
  estimate.map_update_seconds = std::chrono::duration<double>(Clock::now() - map_started).count();
  return estimate;
}

}  // namespace hanzo::fusion::lidar
