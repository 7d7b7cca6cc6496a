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
  if (last_time_) {
    const double interval = (time - *last_time_).seconds();  // sweeps of equal length: also between middles
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
  std::vector<std::vector<uint32_t>> chunk_in_range(cloud::chunk_count(scan.size(), threads));
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
  // The kept points as measured (again before a second deskew).
  const auto copy_measured = [&] {
    map_points.positions.resize(kept.size());
    if (scan.has_times()) map_points.times.resize(kept.size());
    cloud::parallel_for(kept.size(), threads, [&](std::size_t begin, std::size_t end) {
      for (std::size_t n = begin; n < end; ++n) {
        map_points.positions[n] = scan.positions[kept[n]];
        if (scan.has_times()) map_points.times[n] = scan.times[kept[n]];
      }
    });
  };
  copy_measured();
  // The estimate refers to the middle of the sweep: a velocity error then warps the sweep
  // symmetrically about the estimated pose instead of shifting it (referred to the sweep start,
  // the error feeds back through the constant-velocity model and grows).
  const float middle = scan.has_times() ? 0.5F * *std::max_element(scan.times.begin(), scan.times.end()) : 0.0F;
  const Timestamp pose_time = time + Duration::from_seconds(static_cast<double>(middle));
  // A second deskew with a corrected twist (constant-twist mode only).
  const bool may_redeskew = config_.deskew && !sweep_motion && config_.redeskew_threshold > 0.0 && map_points.has_times() &&
                            last_time_ && last_interval_ > 0.0;
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
    SurfaceAssociations associations;
    auto registered = align_to_surfaces(source, map_, prediction, prediction, registration, may_redeskew ? &associations : nullptr);
    if (!registered) return Error(fmt::format("lidar odometry at {:.6f} s: {}", time.seconds(), registered.error().message));
    if (may_redeskew) {
      // The twist at the sweep's middle under constant acceleration: the last interval's mean
      // twist plus half its change from the interval before.
      const double interval = (time - *last_time_).seconds();
      const SE3::Tangent measured_twist = (pose_.inverse() * registered->T_map_source).log() / interval;
      const SE3::Tangent previous_twist = last_motion_.log() / last_interval_;
      const SE3::Tangent corrected_twist = measured_twist + 0.5 * (measured_twist - previous_twist);
      const SE3::Tangent change = (corrected_twist - twist_per_second) * static_cast<double>(middle);
      if (change.head<3>().norm() + 10.0 * change.tail<3>().norm() > config_.redeskew_threshold) {
        copy_measured();
        deskew(map_points, SweepMotion::constant_twist(corrected_twist, middle), threads);
        for (std::size_t n = 0; n < source_indices.size(); ++n) source[n] = map_points.positions[source_indices[n]];
        // From the first estimate, already within centimetres: at the final kernel width, on the
        // surfaces the first pass matched (the points moved by centimetres), and at most a third
        // of the iterations (the sweeps that need it most are a turn onset's, already the
        // slowest: seen 29 + 18 iterations uncapped).
        SurfaceRegistrationConfig refine = registration;
        refine.initial_kernel_width = refine.kernel_width;
        refine.max_iterations = std::max(5, registration.max_iterations / 3);
        auto again = align_to_surfaces(source, map_, registered->T_map_source, prediction, refine, &associations);
        if (again) {
          again->iterations += registered->iterations;
          again->associations += registered->associations;
          registered = std::move(again);
          estimate.redeskewed = true;
        } else {  // keeps the first pass (and its deskew)
          logger()->debug("lidar odometry at {:.6f} s: the second deskew's registration failed: {}", time.seconds(), again.error().message);
          copy_measured();
          deskew(map_points, SweepMotion::constant_twist(twist_per_second, middle), threads);
        }
      }
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
    last_interval_ = (time - *last_time_).seconds();
  }
  pose_ = T_world_lidar;
  last_time_ = time;
  last_scan_points_ = std::move(map_points.positions);
  ++scans_;
  estimate.map_update_seconds = std::chrono::duration<double>(Clock::now() - map_started).count();
  return estimate;
}

}  // namespace hanzo::fusion::lidar
