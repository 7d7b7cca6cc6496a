#include "hanzo/fusion/estimate/particle_filter.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>

namespace hanzo::fusion::estimate {

ParticleFilter::ParticleFilter(const FilterConfig& config, const ParticleFilterConfig& particles)
    : config_(config), particle_config_(particles), gate_(config.gate_probability), random_(particles.seed) {
  particle_config_.particles = std::max(1, particle_config_.particles);
}

Eigen::Vector3d ParticleFilter::normal3(double sigma) {
  const double x = normal_(random_);
  const double y = normal_(random_);
  const double z = normal_(random_);
  return sigma * Eigen::Vector3d(x, y, z);
}

void ParticleFilter::reset(const NavigationState& state, const ErrorCovariance& covariance) {
  const size_t count = static_cast<size_t>(particle_config_.particles);
  const Eigen::LLT<ErrorCovariance> llt(covariance + 1e-15 * ErrorCovariance::Identity());
  const ErrorCovariance root = llt.matrixL();
  particles_.assign(count, state);
  weights_.assign(count, 1.0 / static_cast<double>(count));
  clones_.clear();
  for (size_t i = 1; i < count; ++i) {  // particle 0 stays at the given state
    ErrorVector draw;
    // A state with zero variance (the wheel speed scale without wheels) is known: no draw.
    for (int k = 0; k < kErrorStateDimension; ++k) draw(k) = covariance(k, k) > 0.0 ? normal_(random_) : 0.0;
    particles_[i] = state.plus(root * draw);
  }
}

void ParticleFilter::predict(const ImuSample& sample, double dt) {
  if (dt <= 0.0) return;
  const ImuNoise& noise = config_.imu_noise;
  // A sample held for dt with white noise of density sigma^2 T_s has std sigma sqrt(T_s / dt).
  const double accel_sigma = noise.process_noise_accel * std::sqrt(noise.sample_interval / dt);
  const double gyro_sigma = noise.process_noise_gyro * std::sqrt(noise.sample_interval / dt);
  const double accel_walk = noise.accel_bias_random_walk * std::sqrt(dt);
  const double gyro_walk = noise.gyro_bias_random_walk * std::sqrt(dt);
  for (NavigationState& particle : particles_) {
    ImuSample noisy = sample;
    noisy.linear_acceleration += normal3(accel_sigma);
    noisy.angular_velocity += normal3(gyro_sigma);
    particle = propagate_state(particle, body_motion(particle, noisy, config_.imu_mounting), dt, config_.imu_mounting, nullptr);
    particle.accel_bias += normal3(accel_walk);
    particle.gyro_bias += normal3(gyro_walk);
  }
}

UpdateOutcome ParticleFilter::update(const MeasurementModel& model, bool apply_gate) {
  UpdateOutcome outcome;
  const int m = model.dimension();
  outcome.gate = gate_.threshold(m);
  const size_t count = particles_.size();
  std::vector<MeasurementVector> residuals(count);
  MeasurementVector mean = MeasurementVector::Zero(m);
  for (size_t i = 0; i < count; ++i) {
    residuals[i] = model.residual(particles_[i], nullptr);
    mean += weights_[i] * residuals[i];
  }
  const MeasurementCovariance noise = model.covariance();
  MeasurementCovariance S = noise;
  for (size_t i = 0; i < count; ++i) {
    const MeasurementVector d = residuals[i] - mean;
    S.noalias() += weights_[i] * d * d.transpose();
  }
  outcome.innovation = mean;
  const Eigen::LLT<MeasurementCovariance> noise_llt(noise);
  if (noise_llt.info() != Eigen::Success) {
    outcome.status = UpdateStatus::kNumericalFailure;
    return outcome;
  }
  if (!passes_gate(Eigen::LLT<MeasurementCovariance>(S), mean, apply_gate, outcome)) return outcome;
  // Log-weights, normalized with the log-sum-exp trick.
  std::vector<double> log_weights(count);
  double largest = -std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < count; ++i) {
    log_weights[i] = std::log(weights_[i]) - 0.5 * residuals[i].dot(noise_llt.solve(residuals[i]));
    largest = std::max(largest, log_weights[i]);
  }
  if (!std::isfinite(largest)) {
    outcome.status = UpdateStatus::kNumericalFailure;
    return outcome;
  }
  double total = 0.0;
  for (size_t i = 0; i < count; ++i) total += (weights_[i] = std::exp(log_weights[i] - largest));
  for (double& weight : weights_) weight /= total;
  if (effective_sample_size() < particle_config_.resample_threshold * static_cast<double>(count)) resample();
  return outcome;
}

void ParticleFilter::apply_world_transform(const SE3& T_correction) {
  for (NavigationState& particle : particles_) transform_in_world(T_correction, particle, nullptr);
  clones_.clear();  // the clone's frame moved: the next keyframe starts afresh
}

void ParticleFilter::clone_pose() {
  const NavigationState mean = state();
  clone_anchor_ = SE3(mean.R_world_body, mean.position);
  clones_.resize(particles_.size());
  for (size_t i = 0; i < particles_.size(); ++i) clones_[i] = SE3(particles_[i].R_world_body, particles_[i].position);
}

std::optional<PoseClone> ParticleFilter::pose_clone() const {
  if (clones_.empty()) return std::nullopt;
  using Vector6 = Eigen::Matrix<double, 6, 1>;
  std::vector<ErrorVector> deltas;
  const ErrorVector state_mean = mean_delta(&deltas);
  std::vector<Vector6> clone_deltas(clones_.size());
  Vector6 clone_mean = Vector6::Zero();
  for (size_t i = 0; i < clones_.size(); ++i) {
    clone_deltas[i].head<3>() = clones_[i].translation() - clone_anchor_.translation();
    clone_deltas[i].tail<3>() = (clone_anchor_.rotation().inverse() * clones_[i].rotation()).log();
    clone_mean += weights_[i] * clone_deltas[i];
  }
  PoseClone clone;
  clone.correction = clone_mean;
  for (size_t i = 0; i < clones_.size(); ++i) {
    const Vector6 c = clone_deltas[i] - clone_mean;
    clone.covariance.noalias() += weights_[i] * c * c.transpose();
    clone.cross.noalias() += weights_[i] * c * (deltas[i] - state_mean).transpose();
  }
  return clone;
}

double ParticleFilter::effective_sample_size() const {
  double sum_squares = 0.0;
  for (double weight : weights_) sum_squares += weight * weight;
  return 1.0 / sum_squares;
}

void ParticleFilter::resample() {
  // Systematic resampling: one uniform offset, N evenly spaced pointers into the CDF.
  const size_t count = particles_.size();
  const double step = 1.0 / static_cast<double>(count);
  const double offset = std::uniform_real_distribution<double>(0.0, step)(random_);
  std::vector<NavigationState> resampled;
  std::vector<SE3> resampled_clones;
  resampled.reserve(count);
  double cumulative = weights_[0];
  size_t source = 0;
  for (size_t i = 0; i < count; ++i) {
    const double pointer = offset + static_cast<double>(i) * step;
    while (pointer > cumulative && source + 1 < count) cumulative += weights_[++source];
    resampled.push_back(particles_[source]);
    if (!clones_.empty()) resampled_clones.push_back(clones_[source]);
  }
  particles_ = std::move(resampled);
  clones_ = std::move(resampled_clones);
  weights_.assign(count, step);
  ++resamplings_;
}

ErrorVector ParticleFilter::mean_delta(std::vector<ErrorVector>* deltas) const {
  const size_t heaviest = static_cast<size_t>(std::max_element(weights_.begin(), weights_.end()) - weights_.begin());
  ErrorVector mean = ErrorVector::Zero();
  deltas->resize(particles_.size());
  for (size_t i = 0; i < particles_.size(); ++i) {
    (*deltas)[i] = particles_[i].minus(particles_[heaviest]);
    mean += weights_[i] * (*deltas)[i];
  }
  return mean;
}

NavigationState ParticleFilter::state() const {
  const size_t heaviest = static_cast<size_t>(std::max_element(weights_.begin(), weights_.end()) - weights_.begin());
  std::vector<ErrorVector> deltas;
  return particles_[heaviest].plus(mean_delta(&deltas));
}

ErrorCovariance ParticleFilter::covariance() const {
  std::vector<ErrorVector> deltas;
  const ErrorVector mean = mean_delta(&deltas);
  ErrorCovariance covariance = ErrorCovariance::Zero();
  for (size_t i = 0; i < deltas.size(); ++i) {
    const ErrorVector d = deltas[i] - mean;
    covariance.noalias() += weights_[i] * d * d.transpose();
  }
  return covariance;
}

}  // namespace hanzo::fusion::estimate
