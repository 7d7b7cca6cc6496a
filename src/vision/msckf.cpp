#include "hanzo/fusion/vision/msckf.hpp"

#include <algorithm>
#include <cmath>
#include <set>

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <fmt/format.h>

#include "hanzo/fusion/estimate/chi_square.hpp"
#include "msckf_feature.hpp"
#include "msckf_invariant_error.hpp"

namespace hanzo::fusion::vision {
namespace {

constexpr int kImu = kMsckfImuDimension;
constexpr int kClone = kMsckfCloneDimension;

// The IMU is the body frame of the MSCKF (T_body_camera is the camera-IMU extrinsic).
const estimate::ImuMounting kImuIsBody{};

bool positive(double value) { return std::isfinite(value) && value > 0.0; }

// One observation's Jacobian block on 6 states starting at `offset` (counted after the IMU's).
struct StateBlock {
  Eigen::Index offset = 0;
  Eigen::Matrix<double, 2, 6> jacobian;
};

}  // namespace

Status validate(const MsckfConfig& config) {
  if (config.max_clones < 2) return Error("MsckfConfig.max_clones: must be at least 2", "max_clones");
  if (!positive(config.pixel_sigma)) return Error("MsckfConfig.pixel_sigma: must be positive", "pixel_sigma");
  if (!(config.chi_square_probability > 0.0 && config.chi_square_probability < 1.0))
    return Error("MsckfConfig.chi_square_probability: must be in (0, 1)", "chi_square_probability");
  if (!positive(config.min_depth)) return Error("MsckfConfig.min_depth: must be positive", "min_depth");
  if (!(std::isfinite(config.max_depth) && config.max_depth > config.min_depth))
    return Error("MsckfConfig.max_depth: must be finite and above min_depth", "max_depth");
  if (!(config.min_parallax_deg >= 0.0 && config.min_parallax_deg < 90.0)) return Error("MsckfConfig.min_parallax_deg: must be in [0, 90)", "min_parallax_deg");
  if (!positive(config.extrinsic_rotation_sigma) || !positive(config.extrinsic_translation_sigma) || !positive(config.time_offset_sigma))
    return Error("MsckfConfig: extrinsic_rotation_sigma, extrinsic_translation_sigma and time_offset_sigma must be positive", "extrinsic_rotation_sigma");
  if (!(config.zero_velocity_max_disparity_px >= 0.0) || !positive(config.zero_velocity_sigma))
    return Error("MsckfConfig: zero_velocity_max_disparity_px must not be negative, zero_velocity_sigma must be positive", "zero_velocity_sigma");
  if (config.triangulation_iterations < 0) return Error("MsckfConfig.triangulation_iterations: must not be negative", "triangulation_iterations");
  const estimate::ImuNoise& noise = config.imu_noise;
  if (!positive(noise.process_noise_accel) || !positive(noise.process_noise_gyro) || !positive(noise.sample_interval) ||
      !(noise.accel_bias_random_walk >= 0.0) || !(noise.gyro_bias_random_walk >= 0.0))
    return Error("MsckfConfig.imu_noise: noises and sample interval must be positive, random walks not negative", "imu_noise");
  return ok_status();
}

Result<Msckf> Msckf::create(const MsckfConfig& config, const std::vector<MsckfCamera>& cameras,
                            const estimate::NavigationState& initial_state, const Eigen::MatrixXd& initial_covariance,
                            Duration time_offset) {
  HANZO_RETURN_IF_ERROR(validate(config));
  if (cameras.empty() || cameras.size() > static_cast<size_t>(kMsckfMaxCameras))
    return Error(fmt::format("Msckf: {} cameras given; 1 to {} are supported", cameras.size(), kMsckfMaxCameras), "cameras");
  for (size_t i = 0; i < cameras.size(); ++i) {
    if (!positive(cameras[i].focal_length_px)) return Error(fmt::format("Msckf: camera {} focal_length_px must be positive", i), "cameras");
    if (!cameras[i].T_body_camera.translation().allFinite() || !cameras[i].T_body_camera.rotation().quaternion().coeffs().allFinite())
      return Error(fmt::format("Msckf: camera {} T_body_camera is not finite", i), "cameras");
  }
  if (!initial_state.all_finite()) return Error("Msckf: the initial state is not finite", "initial_state");
  if (initial_covariance.rows() != kImu || initial_covariance.cols() != kImu || !initial_covariance.allFinite() ||
      !initial_covariance.isApprox(initial_covariance.transpose(), 1e-9) || !(initial_covariance.diagonal().array() > 0.0).all())
    return Error("Msckf: the initial covariance must be a finite symmetric 15 x 15 matrix with a positive diagonal", "initial_covariance");
  return Msckf(config, cameras, initial_state, initial_covariance, time_offset.seconds());
}

Msckf::Msckf(const MsckfConfig& config, std::vector<MsckfCamera> cameras, const estimate::NavigationState& state,
             const Eigen::MatrixXd& imu_covariance, double time_offset)
    : config_(config), cameras_(std::move(cameras)), state_(state), time_offset_(time_offset) {
  const Eigen::Index calibration =
      (config_.calibrate_time_offset ? 1 : 0) + (config_.calibrate_extrinsics ? 6 * static_cast<Eigen::Index>(cameras_.size()) : 0);
  first_clone_ = kImu + calibration;
  covariance_ = Eigen::MatrixXd::Zero(first_clone_, first_clone_);
  const ImuMatrix to_invariant = invariant_from_imu_error(state_);
  covariance_.topLeftCorner<kImu, kImu>() = to_invariant * imu_covariance * to_invariant.transpose();
  if (config_.calibrate_time_offset) covariance_(time_offset_index(), time_offset_index()) = config_.time_offset_sigma * config_.time_offset_sigma;
  if (config_.calibrate_extrinsics) {
    for (int camera = 0; camera < static_cast<int>(cameras_.size()); ++camera) {
      const Eigen::Index at = extrinsic_index(camera);
      covariance_.block<3, 3>(at, at).diagonal().setConstant(config_.extrinsic_translation_sigma * config_.extrinsic_translation_sigma);
      covariance_.block<3, 3>(at + 3, at + 3).diagonal().setConstant(config_.extrinsic_rotation_sigma * config_.extrinsic_rotation_sigma);
    }
  }
}

Eigen::Matrix<double, kMsckfImuDimension, kMsckfImuDimension> Msckf::imu_covariance() const {
  // Body-frame error at the interval's start (the last frame's state), then the interval's
  // body-frame transition and noise.
  const ImuMatrix at_start = imu_error_from_invariant(interval_empty_ ? state_ : interval_start_);
  const ImuMatrix transition = interval_transition_ * at_start;
  return transition * covariance_.topLeftCorner<kImu, kImu>() * transition.transpose() + interval_noise_;
}

Eigen::MatrixXd Msckf::body_error_from_invariant() const {
  const Eigen::Index n = covariance_.rows();
  Eigen::MatrixXd T = Eigen::MatrixXd::Identity(n, n);
  T.topLeftCorner<kImu, kImu>() = imu_error_from_invariant(state_);
  for (size_t i = 0; i < clones_.size(); ++i) {
    const SE3& pose = clones_[i].T_world_body;
    T.block<kClone, kClone>(clone_index(i), clone_index(i)) = pose_error_from_invariant(pose.rotation(), pose.translation());
  }
  return T;
}

Eigen::MatrixXd Msckf::covariance() const {
  const Eigen::MatrixXd T = body_error_from_invariant();
  Eigen::MatrixXd body = T * covariance_ * T.transpose();
  return 0.5 * (body + body.transpose());
}

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
  if (interval_empty_) {
    interval_start_ = state_;
    interval_empty_ = false;
  }
  const estimate::BodyMotion motion = estimate::body_motion(state_, reading, kImuIsBody);
  estimate::ImuTransition transition;
  state_ = estimate::propagate_state(state_, motion, dt, kImuIsBody, &transition);
  const ImuMatrix phi = estimate::transition_matrix(transition).topLeftCorner<kImu, kImu>();
  const ImuMatrix noise = estimate::process_noise(config_.imu_noise, dt).topLeftCorner<kImu, kImu>();
  interval_transition_ = phi * interval_transition_;
  interval_noise_ = phi * interval_noise_ * phi.transpose() + noise;
}

void Msckf::apply_interval_propagation() {
  if (interval_empty_) return;
  // The body-frame transition between the interval's two states in invariant coordinates:
  // Phi_xi = T(x_now)^-1 Phi T(x_start). Its rotation / velocity / position block is the
  // state-independent one of the invariant filter; only the bias columns depend on the estimate.
  const ImuMatrix to_invariant = invariant_from_imu_error(state_);
  const ImuMatrix phi = to_invariant * interval_transition_ * imu_error_from_invariant(interval_start_);
  const ImuMatrix noise = to_invariant * interval_noise_ * to_invariant.transpose();
  const Eigen::Index n = covariance_.rows();
  covariance_.topLeftCorner<kImu, kImu>() = phi * covariance_.topLeftCorner<kImu, kImu>() * phi.transpose() + noise;
  if (n > kImu) {
    covariance_.topRightCorner(kImu, n - kImu) = phi * covariance_.topRightCorner(kImu, n - kImu);
    covariance_.bottomLeftCorner(n - kImu, kImu) = covariance_.topRightCorner(kImu, n - kImu).transpose();
  }
  interval_transition_.setIdentity();
  interval_noise_.setZero();
  interval_empty_ = true;
}

void Msckf::augment(Timestamp time) {
  // The clone's error is the IMU's (xi_p, phi), plus, with the time offset estimated, the
  // motion over an error dt of it (OpenVINS's clone Jacobian): (v, w_body) dt in body-frame
  // error, (v + [p]x R w_body, R w_body) dt in invariant error.
  const Eigen::Vector3d angular_velocity_world = state_.R_world_body * (last_sample_->angular_velocity - state_.gyro_bias);
  Eigen::Matrix<double, 6, 1> rates;
  rates << state_.velocity + state_.position.cross(angular_velocity_world), angular_velocity_world;
  const Eigen::Index n = covariance_.rows();
  Eigen::MatrixXd rows = covariance_.topRows(kClone);  // J P
  if (config_.calibrate_time_offset) rows += rates * covariance_.row(time_offset_index());
  Eigen::Matrix<double, kClone, kClone> corner = rows.leftCols<kClone>();  // J P J^T
  if (config_.calibrate_time_offset) corner += rows.col(time_offset_index()) * rates.transpose();
  Eigen::MatrixXd grown(n + kClone, n + kClone);
  grown.topLeftCorner(n, n) = covariance_;
  grown.bottomLeftCorner(kClone, n) = rows;
  grown.topRightCorner(n, kClone) = rows.transpose();
  grown.bottomRightCorner<kClone, kClone>() = 0.5 * (corner + corner.transpose());
  covariance_ = std::move(grown);
  clones_.push_back({time, SE3(state_.R_world_body, state_.position)});
}

void Msckf::marginalize_oldest_clone() {
  const Eigen::Index n = covariance_.rows();
  const Eigen::Index rest = n - first_clone_ - kClone;
  Eigen::MatrixXd reduced(n - kClone, n - kClone);
  reduced.topLeftCorner(first_clone_, first_clone_) = covariance_.topLeftCorner(first_clone_, first_clone_);
  reduced.topRightCorner(first_clone_, rest) = covariance_.topRightCorner(first_clone_, rest);
  reduced.bottomLeftCorner(rest, first_clone_) = covariance_.bottomLeftCorner(rest, first_clone_);
  reduced.bottomRightCorner(rest, rest) = covariance_.bottomRightCorner(rest, rest);
  covariance_ = std::move(reduced);
  clones_.pop_front();
}

Result<MsckfUpdateSummary> Msckf::process_frame(Timestamp time, const std::vector<FeatureObservation>& observations,
                                                const std::vector<int>& rigs) {
  if (diverged_) return Error("Msckf: the covariance is no longer finite; the filter must be initialized again", "state");
  if (!last_sample_) return Error("Msckf: a frame before any IMU sample", "imu");
  if (last_frame_time_ && time <= *last_frame_time_)
    return Error(fmt::format("Msckf: frame at {:.6f} s is not after the previous frame ({:.6f} s)", time.seconds(),
                             last_frame_time_->seconds()), "time");
  const Timestamp frame_body_time = body_time(time);
  if (frame_body_time < state_.timestamp)
    return Error(fmt::format("Msckf: frame at {:.6f} s (body time {:.6f} s) is older than the IMU state ({:.6f} s); process frames before "
                             "later IMU samples", time.seconds(), frame_body_time.seconds(), state_.timestamp.seconds()), "time");
  std::set<std::pair<uint64_t, int>> in_frame;
  for (const FeatureObservation& observation : observations) {
    if (!in_frame.insert({observation.feature_id, observation.camera}).second)
      return Error(fmt::format("Msckf: feature {} is observed twice by camera {} in one frame", observation.feature_id, observation.camera),
                   "feature_id");
    if (observation.camera < 0 || observation.camera >= static_cast<int>(cameras_.size()))
      return Error(fmt::format("Msckf: feature {} names camera {}; the rig has {}", observation.feature_id, observation.camera, cameras_.size()),
                   "camera");
    if (!observation.normalized.allFinite()) return Error(fmt::format("Msckf: feature {} is not finite", observation.feature_id), "normalized");
  }

  if (frame_body_time > state_.timestamp) propagate_interval(*last_sample_, (frame_body_time - state_.timestamp).seconds());
  apply_interval_propagation();
  const auto imaged = [&rigs](int rig) { return rigs.empty() || std::find(rigs.begin(), rigs.end(), rig) != rigs.end(); };
  const bool camera0_imaged = imaged(cameras_[0].rig);
  const bool standing = config_.zero_velocity_update && camera0_imaged && standing_still(observations);
  last_frame_time_ = time;
  if (standing && update_zero_velocity()) {
    MsckfUpdateSummary summary;
    summary.zero_velocity = true;
    summary.clones = static_cast<int>(clones_.size());
    if (!covariance_.allFinite() || !state_.all_finite()) diverged_ = true;
    return summary;
  }
  // Moving: the next frames' displacements count from this one.
  if (camera0_imaged) standing_reference_.clear();
  for (const FeatureObservation& observation : observations) {
    if (observation.camera == 0) standing_reference_[observation.feature_id] = observation.normalized;
  }
  augment(time);
  std::set<uint64_t> seen;
  for (const FeatureObservation& observation : observations) {
    tracks_[observation.feature_id].push_back({time, observation.camera, observation.normalized});
    seen.insert(observation.feature_id);
  }

  // Tracks that ended (in a rig this frame images), and with a full window every track the
  // oldest clone saw.
  const bool window_full = static_cast<int>(clones_.size()) > config_.max_clones;
  std::vector<uint64_t> to_update;
  for (const auto& [id, track] : tracks_) {
    const bool ended = !seen.count(id) && imaged(cameras_[static_cast<size_t>(track.back().camera)].rig);
    if (ended || (window_full && track.front().clone_time == clones_.front().timestamp)) to_update.push_back(id);
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
  const Eigen::Index other_states = n - kImu;  // calibration and clones: what H touches
  std::map<Timestamp, int> clone_of_time;
  for (size_t i = 0; i < clones_.size(); ++i) clone_of_time[clones_[i].timestamp] = static_cast<int>(i);
  const FeatureTriangulationConfig triangulation{config_.min_depth, config_.max_depth, config_.triangulation_iterations,
                                                 config_.min_parallax_deg * M_PI / 180.0};

  // The accepted rows, accumulated as information over the states after the IMU's: J = sum
  // H0^T H0 and g = sum H0^T r0 (whitened rows; H0 touches clones and extrinsics only).
  Eigen::MatrixXd information = Eigen::MatrixXd::Zero(other_states, other_states);
  Eigen::VectorXd information_vector = Eigen::VectorXd::Zero(other_states);
  for (uint64_t id : feature_ids) {
    const std::vector<TrackObservation>& track = tracks_.at(id);
    if (track.size() < 2) continue;
    ++summary.features_offered;
    std::vector<FeatureView> views;
    std::vector<int> view_clones;
    for (const TrackObservation& observation : track) {
      const int index = clone_of_time.at(observation.clone_time);
      views.push_back({clones_[index].T_world_body, cameras_[observation.camera].T_body_camera, observation.normalized});
      view_clones.push_back(index);
    }
    const std::optional<Eigen::Vector3d> point = triangulate_feature(views, triangulation);
    if (!point) {
      ++summary.rejected_triangulation;
      continue;
    }
    // Whitened residual r and Jacobians: H_c (2 x 6 blocks per observation: on its clone and,
    // when calibrated, on its camera's extrinsics) and H_f (2m x 3).
    const Eigen::Index m = 2 * static_cast<Eigen::Index>(views.size());
    std::vector<std::vector<StateBlock>> blocks(views.size());
    Eigen::MatrixXd by_point(m, 3);
    Eigen::VectorXd residual(m);
    for (size_t k = 0; k < views.size(); ++k) {
      const FeatureLinearization linear = linearize_observation(views[k], *point);
      const double inverse_sigma = cameras_[track[k].camera].focal_length_px / config_.pixel_sigma;
      const Eigen::Index row = 2 * static_cast<Eigen::Index>(k);
      const SE3& clone = clones_[static_cast<size_t>(view_clones[k])].T_world_body;
      blocks[k].push_back({clone_index(static_cast<size_t>(view_clones[k])) - kImu,
                           inverse_sigma * linear.by_clone * pose_error_from_invariant(clone.rotation(), clone.translation())});
      if (config_.calibrate_extrinsics) blocks[k].push_back({extrinsic_index(track[k].camera) - kImu, inverse_sigma * linear.by_extrinsic});
      by_point.middleRows<2>(row) = inverse_sigma * linear.by_point;
      residual.segment<2>(row) = inverse_sigma * linear.residual;
    }
    // Q = [Q1 N] from the QR decomposition of H_f: N spans its left null space (eq. 23-24), and
    // r0 = N^T r, H0 = N^T H_c no longer depend on the feature's error.
    const Eigen::HouseholderQR<Eigen::MatrixXd> qr(by_point);
    const Eigen::MatrixXd q = qr.householderQ() * Eigen::MatrixXd::Identity(m, m);
    const auto range = q.leftCols(3);
    const auto null_space = q.rightCols(m - 3);

    // Chi-square gate: r0^T (N^T (H_c P H_c^T + I) N)^-1 r0, with H_c P H_c^T built block by
    // block from the 6 x 6 covariance blocks (H_c is block-sparse).
    Eigen::MatrixXd projected_covariance = Eigen::MatrixXd::Identity(m, m);
    for (size_t k = 0; k < views.size(); ++k) {
      for (size_t l = k; l < views.size(); ++l) {
        Eigen::Matrix2d block = Eigen::Matrix2d::Zero();
        for (const StateBlock& a : blocks[k]) {
          for (const StateBlock& b : blocks[l]) {
            block += a.jacobian * covariance_.block<kClone, kClone>(kImu + a.offset, kImu + b.offset) * b.jacobian.transpose();
          }
        }
        projected_covariance.block<2, 2>(2 * static_cast<Eigen::Index>(k), 2 * static_cast<Eigen::Index>(l)) += block;
        if (l != k) projected_covariance.block<2, 2>(2 * static_cast<Eigen::Index>(l), 2 * static_cast<Eigen::Index>(k)) += block.transpose();
      }
    }
    const Eigen::VectorXd projected_residual = null_space.transpose() * residual;
    const Eigen::MatrixXd innovation = null_space.transpose() * projected_covariance * null_space;
    const double chi_square = projected_residual.dot(innovation.ldlt().solve(projected_residual));
    if (!(chi_square <= estimate::chi_square_quantile(config_.chi_square_probability, static_cast<int>(m - 3)))) {
      ++summary.rejected_chi_square;
      continue;
    }
    ++summary.features_used;
    summary.residual_rows += static_cast<int>(m - 3);

    // H0^T H0 = H_c^T (I - Q1 Q1^T) H_c and H0^T r0 = H_c^T (r - Q1 Q1^T r).
    const Eigen::VectorXd orthogonal_residual = residual - range * (range.transpose() * residual);
    Eigen::MatrixXd by_range = Eigen::MatrixXd::Zero(other_states, 3);  // H_c^T Q1
    for (size_t k = 0; k < views.size(); ++k) {
      const Eigen::Index row = 2 * static_cast<Eigen::Index>(k);
      for (const StateBlock& a : blocks[k]) {
        for (const StateBlock& b : blocks[k]) information.block<kClone, kClone>(a.offset, b.offset) += a.jacobian.transpose() * b.jacobian;
        by_range.middleRows<kClone>(a.offset) += a.jacobian.transpose() * range.middleRows<2>(row);
        information_vector.segment<kClone>(a.offset) += a.jacobian.transpose() * orthogonal_residual.segment<2>(row);
      }
    }
    information.noalias() -= by_range * by_range.transpose();
  }
  if (summary.features_used == 0) return summary;

  // The EKF update with all rows at once (the measurement compression of eq. 26-28 in
  // information form): P+ = (P^-1 + J)^-1, dx = P+ g. With P = F F^T (pivoted LDLT: P is
  // singular right after a clone is added), P+ = F (I + F^T J F)^-1 F^T, which needs no inverse
  // of P and stays symmetric positive semi-definite.
  const Eigen::LDLT<Eigen::MatrixXd> factor(covariance_);
  Eigen::MatrixXd root = factor.matrixL();
  root = factor.transpositionsP().transpose() * (root * factor.vectorD().cwiseMax(0.0).cwiseSqrt().asDiagonal());
  const Eigen::MatrixXd clone_root = root.bottomRows(other_states);  // J and g touch these rows only
  Eigen::MatrixXd gain_system = clone_root.transpose() * information * clone_root;
  gain_system.diagonal().array() += 1.0;
  const Eigen::LLT<Eigen::MatrixXd> gain_factor(gain_system);
  apply_correction(root * gain_factor.solve(clone_root.transpose() * information_vector));
  covariance_ = root * gain_factor.solve(root.transpose());
  covariance_ = 0.5 * (covariance_ + covariance_.transpose()).eval();
  return summary;
}

bool Msckf::standing_still(const std::vector<FeatureObservation>& observations) const {
  std::vector<double> disparities;
  for (const FeatureObservation& observation : observations) {
    if (observation.camera != 0) continue;
    const auto reference = standing_reference_.find(observation.feature_id);
    if (reference != standing_reference_.end()) disparities.push_back((observation.normalized - reference->second).norm() * cameras_[0].focal_length_px);
  }
  if (disparities.size() < 10) return false;
  std::nth_element(disparities.begin(), disparities.begin() + static_cast<long>(disparities.size() / 2), disparities.end());
  // The median displacement of a feature that did not move: two observations with pixel_sigma
  // per axis each differ by a Rayleigh(sqrt(2) sigma) length, median 2 sqrt(ln 2) sigma.
  const double noise_median = 2.0 * std::sqrt(std::log(2.0)) * config_.pixel_sigma;
  return disparities[disparities.size() / 2] < config_.zero_velocity_max_disparity_px + noise_median;
}

bool Msckf::update_zero_velocity() {
  // z = 0 = v + n with dv = xi_v - [v]x phi: H = [-[v]x on phi, I on xi_v]; r = -v,
  // S = H P H^T + sigma^2 I.
  const Eigen::Vector3d residual = -state_.velocity;
  const Eigen::Matrix3d by_orientation = -SO3::hat(state_.velocity);
  const Eigen::MatrixXd velocity_rows =
      covariance_.middleRows<3>(estimate::kVelocityIndex) + by_orientation * covariance_.middleRows<3>(estimate::kOrientationIndex);  // H P
  Eigen::Matrix3d innovation = velocity_rows.middleCols<3>(estimate::kVelocityIndex) +
                               velocity_rows.middleCols<3>(estimate::kOrientationIndex) * by_orientation.transpose();
  innovation.diagonal().array() += config_.zero_velocity_sigma * config_.zero_velocity_sigma;
  const Eigen::LDLT<Eigen::Matrix3d> innovation_ldlt(innovation);
  if (!(residual.dot(innovation_ldlt.solve(residual)) <= estimate::chi_square_quantile(config_.chi_square_probability, 3))) return false;
  const Eigen::MatrixXd gain = innovation_ldlt.solve(velocity_rows).transpose();
  apply_correction(gain * residual);
  covariance_ -= gain * velocity_rows;
  covariance_ = 0.5 * (covariance_ + covariance_.transpose()).eval();
  return true;
}

void Msckf::apply_correction(const Eigen::VectorXd& correction) {
  state_ = apply_invariant_error(state_, correction.head<kImu>());
  if (config_.calibrate_time_offset) time_offset_ += correction(time_offset_index());
  if (config_.calibrate_extrinsics) {
    // Extrinsics keep their body-frame error: R_body_camera Exp(dphi), p_body_camera + dq.
    auto correct = [](SE3& pose, const Eigen::Matrix<double, 6, 1>& delta) {
      pose = SE3(pose.rotation() * SO3::exp(delta.tail<3>()), pose.translation() + delta.head<3>());
    };
    for (int camera = 0; camera < static_cast<int>(cameras_.size()); ++camera) {
      correct(cameras_[static_cast<size_t>(camera)].T_body_camera, correction.segment<6>(extrinsic_index(camera)));
    }
  }
  for (size_t i = 0; i < clones_.size(); ++i) clones_[i].T_world_body = apply_invariant_error(clones_[i].T_world_body, correction.segment<kClone>(clone_index(i)));
}

}  // namespace hanzo::fusion::vision
