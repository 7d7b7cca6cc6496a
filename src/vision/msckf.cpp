#include "hanzo/fusion/vision/msckf.hpp"

#include <cmath>
#include <set>

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <fmt/format.h>

#include "hanzo/fusion/estimate/chi_square.hpp"
#include "msckf_feature.hpp"

namespace hanzo::fusion::vision {
namespace {

constexpr int kImu = kMsckfImuDimension;
constexpr int kClone = kMsckfCloneDimension;

// The IMU is the body frame of the MSCKF (T_body_camera is the camera-IMU extrinsic).
const estimate::ImuMounting kImuIsBody{};

bool positive(double value) { return std::isfinite(value) && value > 0.0; }

}  // namespace

Status validate(const MsckfConfig& config) {
  if (config.max_clones < 2) return Error("MsckfConfig.max_clones: must be at least 2", "max_clones");
  if (!positive(config.pixel_sigma)) return Error("MsckfConfig.pixel_sigma: must be positive", "pixel_sigma");
  if (!(config.chi_square_probability > 0.0 && config.chi_square_probability < 1.0))
    return Error("MsckfConfig.chi_square_probability: must be in (0, 1)", "chi_square_probability");
  if (!positive(config.min_depth)) return Error("MsckfConfig.min_depth: must be positive", "min_depth");
  if (!(std::isfinite(config.max_depth) && config.max_depth > config.min_depth))
    return Error("MsckfConfig.max_depth: must be finite and above min_depth", "max_depth");
  if (config.triangulation_iterations < 0) return Error("MsckfConfig.triangulation_iterations: must not be negative", "triangulation_iterations");
  const estimate::ImuNoise& noise = config.imu_noise;
  if (!positive(noise.process_noise_accel) || !positive(noise.process_noise_gyro) || !positive(noise.sample_interval) ||
      !(noise.accel_bias_random_walk >= 0.0) || !(noise.gyro_bias_random_walk >= 0.0))
    return Error("MsckfConfig.imu_noise: noises and sample interval must be positive, random walks not negative", "imu_noise");
  return ok_status();
}

Result<Msckf> Msckf::create(const MsckfConfig& config, const std::vector<MsckfCamera>& cameras,
                            const estimate::NavigationState& initial_state, const Eigen::MatrixXd& initial_covariance) {
  HANZO_RETURN_IF_ERROR(validate(config));
  if (cameras.empty() || cameras.size() > 2) return Error(fmt::format("Msckf: {} cameras given; one or two are supported", cameras.size()), "cameras");
  for (size_t i = 0; i < cameras.size(); ++i) {
    if (!positive(cameras[i].focal_length_px)) return Error(fmt::format("Msckf: camera {} focal_length_px must be positive", i), "cameras");
    if (!cameras[i].T_body_camera.translation().allFinite() || !cameras[i].T_body_camera.rotation().quaternion().coeffs().allFinite())
      return Error(fmt::format("Msckf: camera {} T_body_camera is not finite", i), "cameras");
  }
  if (!initial_state.all_finite()) return Error("Msckf: the initial state is not finite", "initial_state");
  if (initial_covariance.rows() != kImu || initial_covariance.cols() != kImu || !initial_covariance.allFinite() ||
      !initial_covariance.isApprox(initial_covariance.transpose(), 1e-9) || !(initial_covariance.diagonal().array() > 0.0).all())
    return Error("Msckf: the initial covariance must be a finite symmetric 15 x 15 matrix with a positive diagonal", "initial_covariance");
  return Msckf(config, cameras, initial_state, initial_covariance);
}

Msckf::Msckf(const MsckfConfig& config, std::vector<MsckfCamera> cameras, const estimate::NavigationState& state,
             const Eigen::MatrixXd& covariance)
    : config_(config), cameras_(std::move(cameras)), state_(state), covariance_(covariance) {}

Status Msckf::propagate(const estimate::ImuSample& sample) {
  if (!sample.angular_velocity.allFinite() || !sample.linear_acceleration.allFinite())
    return Error(fmt::format("Msckf: IMU sample at {:.6f} s is not finite", sample.timestamp.seconds()), "imu");
  if (sample.timestamp < state_.timestamp)
    return Error(fmt::format("Msckf: IMU sample at {:.6f} s is older than the state ({:.6f} s)", sample.timestamp.seconds(),
                             state_.timestamp.seconds()), "imu");
  estimate::ImuSample reading = sample;
  if (last_sample_) {
    reading.angular_velocity = 0.5 * (last_sample_->angular_velocity + sample.angular_velocity);
    reading.linear_acceleration = 0.5 * (last_sample_->linear_acceleration + sample.linear_acceleration);
  }
  const double dt = (sample.timestamp - state_.timestamp).seconds();
  if (dt > 0.0) propagate_interval(reading, dt);
  last_sample_ = sample;
  return ok_status();
}

void Msckf::propagate_interval(const estimate::ImuSample& reading, double dt) {
  const estimate::BodyMotion motion = estimate::body_motion(state_, reading, kImuIsBody);
  estimate::ImuTransition transition;
  state_ = estimate::propagate_state(state_, motion, dt, kImuIsBody, &transition);
  const Eigen::Matrix<double, kImu, kImu> phi = estimate::transition_matrix(transition).topLeftCorner<kImu, kImu>();
  const Eigen::Matrix<double, kImu, kImu> noise = estimate::process_noise(config_.imu_noise, dt).topLeftCorner<kImu, kImu>();
  const Eigen::Index n = covariance_.rows();
  covariance_.topLeftCorner<kImu, kImu>() = phi * covariance_.topLeftCorner<kImu, kImu>() * phi.transpose() + noise;
  if (n > kImu) {
    covariance_.topRightCorner(kImu, n - kImu) = phi * covariance_.topRightCorner(kImu, n - kImu);
    covariance_.bottomLeftCorner(n - kImu, kImu) = covariance_.topRightCorner(kImu, n - kImu).transpose();
  }
}

void Msckf::augment(Timestamp time) {
  const Eigen::Index n = covariance_.rows();
  Eigen::MatrixXd grown(n + kClone, n + kClone);
  grown.topLeftCorner(n, n) = covariance_;
  grown.bottomLeftCorner(kClone, n) = covariance_.topRows(kClone);  // the clone's error is the IMU's (dp, dtheta)
  grown.topRightCorner(n, kClone) = covariance_.leftCols(kClone);
  grown.bottomRightCorner<kClone, kClone>() = covariance_.topLeftCorner<kClone, kClone>();
  covariance_ = std::move(grown);
  clones_.push_back({time, SE3(state_.R_world_body, state_.position)});
}

void Msckf::marginalize_oldest_clone() {
  const Eigen::Index n = covariance_.rows();
  const Eigen::Index rest = n - kImu - kClone;
  Eigen::MatrixXd reduced(n - kClone, n - kClone);
  reduced.topLeftCorner<kImu, kImu>() = covariance_.topLeftCorner<kImu, kImu>();
  reduced.topRightCorner(kImu, rest) = covariance_.topRightCorner(kImu, rest);
  reduced.bottomLeftCorner(rest, kImu) = covariance_.bottomLeftCorner(rest, kImu);
  reduced.bottomRightCorner(rest, rest) = covariance_.bottomRightCorner(rest, rest);
  covariance_ = std::move(reduced);
  clones_.pop_front();
}

Result<MsckfUpdateSummary> Msckf::process_frame(Timestamp time, const std::vector<FeatureObservation>& observations) {
  if (diverged_) return Error("Msckf: the covariance is no longer finite; the filter must be initialized again", "state");
  if (!last_sample_) return Error("Msckf: a frame before any IMU sample", "imu");
  if (!clones_.empty() && time <= clones_.back().timestamp)
    return Error(fmt::format("Msckf: frame at {:.6f} s is not after the previous frame ({:.6f} s)", time.seconds(),
                             clones_.back().timestamp.seconds()), "time");
  if (time < state_.timestamp)
    return Error(fmt::format("Msckf: frame at {:.6f} s is older than the IMU state ({:.6f} s); process frames before later IMU samples",
                             time.seconds(), state_.timestamp.seconds()), "time");
  for (const FeatureObservation& observation : observations) {
    if (observation.camera < 0 || observation.camera >= static_cast<int>(cameras_.size()))
      return Error(fmt::format("Msckf: feature {} names camera {}; the rig has {}", observation.feature_id, observation.camera, cameras_.size()),
                   "camera");
    if (!observation.normalized.allFinite()) return Error(fmt::format("Msckf: feature {} is not finite", observation.feature_id), "normalized");
  }

  if (time > state_.timestamp) propagate_interval(*last_sample_, (time - state_.timestamp).seconds());
  augment(time);
  std::set<uint64_t> seen;
  for (const FeatureObservation& observation : observations) {
    tracks_[observation.feature_id].push_back({time, observation.camera, observation.normalized});
    seen.insert(observation.feature_id);
  }

  // Tracks that ended, and with a full window every track the oldest clone saw.
  const bool window_full = static_cast<int>(clones_.size()) > config_.max_clones;
  std::vector<uint64_t> to_update;
  for (const auto& [id, track] : tracks_) {
    if (!seen.count(id) || (window_full && track.front().clone_time == clones_.front().timestamp)) to_update.push_back(id);
  }
  MsckfUpdateSummary summary = update(to_update);
  for (uint64_t id : to_update) tracks_.erase(id);
  if (window_full) marginalize_oldest_clone();
  summary.clones = static_cast<int>(clones_.size());
  if (!covariance_.allFinite() || !state_.all_finite()) diverged_ = true;
  return summary;
}

MsckfUpdateSummary Msckf::update(const std::vector<uint64_t>& feature_ids) {
  MsckfUpdateSummary summary;
  const Eigen::Index n = covariance_.rows();
  std::map<Timestamp, int> clone_index;
  for (size_t i = 0; i < clones_.size(); ++i) clone_index[clones_[i].timestamp] = static_cast<int>(i);
  const FeatureTriangulationConfig triangulation{config_.min_depth, config_.max_depth, config_.triangulation_iterations};

  std::vector<Eigen::MatrixXd> accepted_jacobians;
  std::vector<Eigen::VectorXd> accepted_residuals;
  Eigen::Index rows = 0;
  for (uint64_t id : feature_ids) {
    const std::vector<TrackObservation>& track = tracks_.at(id);
    if (track.size() < 2) continue;
    ++summary.features_offered;
    std::vector<FeatureView> views;
    std::vector<int> view_clones;
    for (const TrackObservation& observation : track) {
      const int index = clone_index.at(observation.clone_time);
      views.push_back({clones_[index].T_world_body, cameras_[observation.camera].T_body_camera, observation.normalized});
      view_clones.push_back(index);
    }
    const std::optional<Eigen::Vector3d> point = triangulate_feature(views, triangulation);
    if (!point) {
      ++summary.rejected_triangulation;
      continue;
    }
    // Whitened (each row divided by its noise) stacked residual and Jacobians.
    const Eigen::Index m = 2 * static_cast<Eigen::Index>(views.size());
    Eigen::MatrixXd by_state = Eigen::MatrixXd::Zero(m, n + 1);  // last column: the residual
    Eigen::MatrixXd by_point(m, 3);
    for (size_t k = 0; k < views.size(); ++k) {
      const FeatureLinearization linear = linearize_observation(views[k], *point);
      const double inverse_sigma = cameras_[track[k].camera].focal_length_px / config_.pixel_sigma;
      const Eigen::Index row = 2 * static_cast<Eigen::Index>(k);
      by_state.block<2, kClone>(row, kImu + kClone * view_clones[k]) = inverse_sigma * linear.by_clone;
      by_state.block<2, 1>(row, n) = inverse_sigma * linear.residual;
      by_point.middleRows<2>(row) = inverse_sigma * linear.by_point;
    }
    // Left null space of by_point: the last m - 3 rows after applying Q^T (eq. 23-24).
    const Eigen::HouseholderQR<Eigen::MatrixXd> qr(by_point);
    by_state.applyOnTheLeft(qr.householderQ().transpose());
    const Eigen::MatrixXd projected_jacobian = by_state.bottomLeftCorner(m - 3, n);
    const Eigen::VectorXd projected_residual = by_state.bottomRightCorner(m - 3, 1);

    Eigen::MatrixXd innovation = projected_jacobian * covariance_ * projected_jacobian.transpose();
    innovation.diagonal().array() += 1.0;
    const double chi_square = projected_residual.dot(innovation.ldlt().solve(projected_residual));
    if (!(chi_square <= estimate::chi_square_quantile(config_.chi_square_probability, static_cast<int>(m - 3)))) {
      ++summary.rejected_chi_square;
      continue;
    }
    ++summary.features_used;
    rows += m - 3;
    accepted_jacobians.push_back(projected_jacobian);
    accepted_residuals.push_back(projected_residual);
  }
  if (rows == 0) return summary;

  Eigen::MatrixXd jacobian(rows, n);
  Eigen::VectorXd residual(rows);
  Eigen::Index row = 0;
  for (size_t i = 0; i < accepted_jacobians.size(); ++i) {
    jacobian.middleRows(row, accepted_jacobians[i].rows()) = accepted_jacobians[i];
    residual.segment(row, accepted_residuals[i].rows()) = accepted_residuals[i];
    row += accepted_jacobians[i].rows();
  }
  // Measurement compression (eq. 26-28): with more rows than states, H = Q1 T_H and only
  // T_H dx + Q1^T r are kept (the noise stays identity after the orthonormal Q1^T).
  if (rows > n) {
    Eigen::MatrixXd stacked(rows, n + 1);
    stacked << jacobian, residual;
    const Eigen::HouseholderQR<Eigen::MatrixXd> qr(jacobian);
    stacked.applyOnTheLeft(qr.householderQ().transpose());
    jacobian = stacked.topLeftCorner(n, n).triangularView<Eigen::Upper>();
    residual = stacked.topRightCorner(n, 1);
  }
  summary.residual_rows = static_cast<int>(rows);

  // K = P H^T S^-1 with S = H P H^T + I; P <- P - K S K^T = P - K (H P).
  const Eigen::MatrixXd jacobian_covariance = jacobian * covariance_;
  Eigen::MatrixXd innovation = jacobian_covariance * jacobian.transpose();
  innovation.diagonal().array() += 1.0;
  const Eigen::LDLT<Eigen::MatrixXd> innovation_ldlt(innovation);
  const Eigen::MatrixXd gain = innovation_ldlt.solve(jacobian_covariance).transpose();
  apply_correction(gain * residual);
  covariance_ -= gain * jacobian_covariance;
  covariance_ = 0.5 * (covariance_ + covariance_.transpose()).eval();
  return summary;
}

void Msckf::apply_correction(const Eigen::VectorXd& correction) {
  estimate::ErrorVector imu_correction = estimate::ErrorVector::Zero();
  imu_correction.head<kImu>() = correction.head<kImu>();
  state_ = state_.plus(imu_correction);
  for (size_t i = 0; i < clones_.size(); ++i) {
    const Eigen::Matrix<double, kClone, 1> delta = correction.segment<kClone>(kImu + kClone * static_cast<Eigen::Index>(i));
    SE3& pose = clones_[i].T_world_body;
    pose = SE3(pose.rotation() * SO3::exp(delta.tail<3>()), pose.translation() + delta.head<3>());
  }
}

}  // namespace hanzo::fusion::vision
