#pragma once
// ParticleFilter (frontend.type: particle): a bootstrap particle filter over the full
// NavigationState, for multimodal beliefs (global localization against a map, symmetric
// environments) where a Gaussian cannot represent the uncertainty.
//
//  - predict: every particle is propagated with its own noisy copy of the IMU sample (white
//    noise of the configured density, bias random walks), so the cloud spreads like the EKF's
//    covariance does.
//  - update: weight_i *= exp(-1/2 r_i^T R^-1 r_i) with r_i = z (-) h(particle_i), in log space.
//    Gating uses the cloud's predicted innovation r = sum w_i r_i and
//    S = sum w_i (r_i - r)(r_i - r)^T + R, as the Kalman filters do.
//  - resampling: systematic (Kitagawa 1996), when the effective sample size
//    1 / sum w_i^2 falls below resample_threshold * particles.
//  - state(): weighted mean on the manifold (around the heaviest particle); covariance():
//    weighted spread of the particles in the error state.
// Deterministic for a seed: the random generator is part of the filter (and of its clones).

#include <random>
#include <vector>

#include "hanzo/fusion/estimate/filter.hpp"

namespace hanzo::fusion::estimate {

struct ParticleFilterConfig {
  int particles = 1000;             // >= 1; 500-5000 typical
  double resample_threshold = 0.5;  // fraction of particles, (0, 1]
  uint64_t seed = 1;
};

class ParticleFilter final : public Filter {
 public:
  ParticleFilter(const FilterConfig& config, const ParticleFilterConfig& particles);

  std::string_view name() const override { return "particle"; }
  /// Draws the particles from N(state, covariance).
  void reset(const NavigationState& state, const ErrorCovariance& covariance) override;
  void predict(const ImuSample& sample, double dt) override;
  UpdateOutcome update(const MeasurementModel& model, bool apply_gate = true) override;
  NavigationState state() const override;
  ErrorCovariance covariance() const override;
  std::unique_ptr<Filter> clone() const override { return std::make_unique<ParticleFilter>(*this); }
  void apply_world_transform(const SE3& T_correction) override;
  /// Every particle keeps its own copy of its pose at the clone (carried through resampling);
  /// pose_clone() gives their weighted statistics against the current particles: exact for the
  /// cloud, no linearization.
  void clone_pose() override;
  std::optional<PoseClone> pose_clone() const override;

  const std::vector<NavigationState>& particles() const { return particles_; }
  /// Normalized weights (sum 1).
  const std::vector<double>& weights() const { return weights_; }
  double effective_sample_size() const;
  uint64_t resamplings() const { return resamplings_; }

 private:
  void resample();
  Eigen::Vector3d normal3(double sigma);
  /// Deltas of every particle from the heaviest one and their weighted mean.
  ErrorVector mean_delta(std::vector<ErrorVector>* deltas) const;

  FilterConfig config_;
  ParticleFilterConfig particle_config_;
  ChiSquareGate gate_;
  std::mt19937_64 random_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::vector<NavigationState> particles_;
  std::vector<double> weights_;
  uint64_t resamplings_ = 0;
  std::vector<SE3> clones_;  // per particle: its pose at clone_pose(), empty when none
  SE3 clone_anchor_;         // the cloud's mean pose at clone_pose()
};

}  // namespace hanzo::fusion::estimate
