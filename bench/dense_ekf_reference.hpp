#pragma once
// The "straightforward" EKF the frontend is compared with: the same state and models, but
// written the way a first implementation usually is: the full 18x18 transition matrix
// multiplied densely (Phi P Phi^T + Q) and the textbook Joseph-form update with dense
// (I - K H) products. Benchmarks only; the engine uses estimate::ErrorStateEkf.

#include <Eigen/Cholesky>

#include "hanzo/fusion/estimate/imu_propagation.hpp"
#include "hanzo/fusion/estimate/measurement_model.hpp"

namespace hanzo::fusion::bench {

class DenseEkfReference {
 public:
  using Matrix = Eigen::Matrix<double, estimate::kErrorStateDimension, estimate::kErrorStateDimension>;

  DenseEkfReference(const estimate::ImuMounting& mounting, const estimate::ImuNoise& noise) : mounting_(mounting), noise_(noise) {}
  void reset(const estimate::NavigationState& state, const Matrix& covariance) {
    state_ = state;
    covariance_ = covariance;
  }
  void predict(const estimate::ImuSample& sample, double dt) {
    estimate::ImuTransition transition;
    state_ = estimate::propagate_state(state_, estimate::body_motion(state_, sample, mounting_), dt, mounting_, &transition);
    const Matrix phi = estimate::transition_matrix(transition);
    covariance_ = phi * covariance_ * phi.transpose() + estimate::process_noise(noise_, dt);
  }
  void update(const estimate::MeasurementModel& model) {
    estimate::MeasurementJacobian H;
    const estimate::MeasurementVector r = model.residual(state_, &H);
    const Eigen::MatrixXd Hd = H;
    const Eigen::MatrixXd R = model.covariance();
    const Eigen::MatrixXd S = Hd * covariance_ * Hd.transpose() + R;
    const Eigen::MatrixXd K = covariance_ * Hd.transpose() * S.inverse();
    state_ = state_.plus(K * r);
    const Matrix I_KH = Matrix::Identity() - K * Hd;
    covariance_ = I_KH * covariance_ * I_KH.transpose() + K * R * K.transpose();
  }
  const estimate::NavigationState& state() const { return state_; }
  const Matrix& covariance() const { return covariance_; }

 private:
  estimate::ImuMounting mounting_;
  estimate::ImuNoise noise_;
  estimate::NavigationState state_;
  Matrix covariance_ = Matrix::Identity();
};

}  // namespace hanzo::fusion::bench
