#include "hanzo/fusion/graph/pose_factors.hpp"

#include <array>
#include <type_traits>

#include <Eigen/Cholesky>
#include <fmt/format.h>

namespace hanzo::fusion::graph {

Result<GaussianNoise> GaussianNoise::from_information(const Eigen::MatrixXd& information) {
  if (information.rows() != information.cols() || information.rows() == 0 || !information.allFinite()) {
    return Error("noise model: the information matrix must be square, non-empty and finite");
  }
  if ((information - information.transpose()).cwiseAbs().maxCoeff() > 1e-9 * (1.0 + information.cwiseAbs().maxCoeff())) {
    return Error("noise model: the information matrix is not symmetric");
  }
  const Eigen::LLT<Eigen::MatrixXd> llt(information);
  if (llt.info() != Eigen::Success) return Error("noise model: the information matrix is not positive definite");
  GaussianNoise noise;
  noise.sqrt_information_ = llt.matrixU();
  return noise;
}

Result<GaussianNoise> GaussianNoise::from_covariance(const Eigen::MatrixXd& covariance) {
  const Eigen::LLT<Eigen::MatrixXd> llt(covariance);
  if (covariance.rows() != covariance.cols() || !covariance.allFinite() || llt.info() != Eigen::Success) {
    return Error("noise model: the covariance must be square, finite and positive definite");
  }
  return from_information(llt.solve(Eigen::MatrixXd::Identity(covariance.rows(), covariance.cols())));
}

Result<GaussianNoise> GaussianNoise::from_sigmas(const Eigen::VectorXd& sigmas) {
  if (sigmas.size() == 0 || !sigmas.allFinite() || (sigmas.array() <= 0.0).any()) {
    return Error("noise model: sigmas must be finite and > 0");
  }
  return from_information(sigmas.array().inverse().square().matrix().asDiagonal());
}

template <typename Pose>
typename Pose::Tangent BetweenFactor<Pose>::whitened_error(const Pose& Ti, const Pose& Tj, typename Pose::Jacobian* jacobian_i,
                                                           typename Pose::Jacobian* jacobian_j) const {
  const Pose error = measured_inverse_ * (Ti.inverse() * Tj);
  const typename Pose::Tangent r = error.log();
  const typename Pose::Jacobian U = noise_.sqrt_information();
  if (jacobian_i != nullptr || jacobian_j != nullptr) {
    const typename Pose::Jacobian U_Jr_inverse = U * Pose::right_jacobian_inverse(r);
    if (jacobian_i != nullptr) *jacobian_i = -U_Jr_inverse * (Tj.inverse() * Ti).adjoint();
    if (jacobian_j != nullptr) *jacobian_j = U_Jr_inverse;
  }
  return U * r;
}

template <typename Pose>
Result<Eigen::VectorXd> BetweenFactor<Pose>::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  Pose Ti, Tj;
  HANZO_ASSIGN_OR_RETURN(Ti, values.at<Pose>(keys()[0]));
  HANZO_ASSIGN_OR_RETURN(Tj, values.at<Pose>(keys()[1]));
  if (noise_.dimension() != Pose::Tangent::RowsAtCompileTime) {
    return Error(fmt::format("between factor: noise dimension {} != pose tangent dimension {}", noise_.dimension(), Pose::Tangent::RowsAtCompileTime));
  }
  typename Pose::Jacobian jacobian_i, jacobian_j;
  const typename Pose::Tangent r = whitened_error(Ti, Tj, jacobians ? &jacobian_i : nullptr, jacobians ? &jacobian_j : nullptr);
  if (jacobians != nullptr) *jacobians = {jacobian_i, jacobian_j};
  return Eigen::VectorXd(r);
}

template <typename Pose>
Result<Eigen::VectorXd> PriorFactor<Pose>::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  Pose T;
  HANZO_ASSIGN_OR_RETURN(T, values.at<Pose>(keys()[0]));
  const typename Pose::Tangent r = (prior_inverse_ * T).log();
  const Eigen::MatrixXd& U = noise_.sqrt_information();
  if (jacobians != nullptr) {
    jacobians->resize(1);
    (*jacobians)[0] = U * Pose::right_jacobian_inverse(r);
  }
  return Eigen::VectorXd(U * r);
}

namespace {

Eigen::Matrix2d rotation_of(const SE2& pose) { return pose.rotation_matrix(); }
Eigen::Matrix3d rotation_of(const SE3& pose) { return pose.rotation().matrix(); }

// The so(d) generators G_k: d(R Exp(phi))/d phi_k = R G_k.
std::array<Eigen::Matrix2d, 1> generators(const SE2&) { return {(Eigen::Matrix2d() << 0, -1, 1, 0).finished()}; }
std::array<Eigen::Matrix3d, 3> generators(const SE3&) {
  return {SO3::hat(Eigen::Vector3d::UnitX()), SO3::hat(Eigen::Vector3d::UnitY()), SO3::hat(Eigen::Vector3d::UnitZ())};
}

template <typename Matrix>
auto vectorized(const Matrix& m) {
  return Eigen::Map<const Eigen::Matrix<double, Matrix::SizeAtCompileTime, 1>>(m.data());
}

}  // namespace

template <typename Pose>
typename ChordalBetweenFactor<Pose>::Residual ChordalBetweenFactor<Pose>::whitened_error(const Pose& Ti, const Pose& Tj, PoseJacobian* jacobian_i,
                                                                                       PoseJacobian* jacobian_j) const {
  constexpr int d = kSpace;
  using Rotation = Eigen::Matrix<double, d, d>;
  const Rotation Ri = rotation_of(Ti), Rj = rotation_of(Tj), Rz = rotation_of(measured_);
  Residual r;
  r.template head<d * d>() = sqrt_kappa_ * vectorized(Rotation(Rj - Ri * Rz));
  r.template tail<d>() = sqrt_tau_ * (Tj.translation() - Ti.translation() - Ri * measured_.translation());
  if (jacobian_i != nullptr || jacobian_j != nullptr) {
    // Tangent order: translation (d), then rotation (d == 2: 1, d == 3: 3); T Exp(rho, phi)
    // moves t by R rho and R by R [phi].
    PoseJacobian Ji = PoseJacobian::Zero(), Jj = PoseJacobian::Zero();
    Ji.template bottomLeftCorner<d, d>() = -sqrt_tau_ * Ri;
    Jj.template bottomLeftCorner<d, d>() = sqrt_tau_ * Rj;
    const auto G = generators(measured_);
    for (size_t k = 0; k < G.size(); ++k) {
      const int column = d + static_cast<int>(k);
      Ji.template block<d * d, 1>(0, column) = -sqrt_kappa_ * vectorized(Rotation(Ri * G[k] * Rz));
      Ji.template block<d, 1>(d * d, column) = -sqrt_tau_ * Ri * G[k] * measured_.translation();
      Jj.template block<d * d, 1>(0, column) = sqrt_kappa_ * vectorized(Rotation(Rj * G[k]));
    }
    if (jacobian_i != nullptr) *jacobian_i = Ji;
    if (jacobian_j != nullptr) *jacobian_j = Jj;
  }
  return r;
}

template <typename Pose>
Result<Eigen::VectorXd> ChordalBetweenFactor<Pose>::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  Pose Ti, Tj;
  HANZO_ASSIGN_OR_RETURN(Ti, values.at<Pose>(keys()[0]));
  HANZO_ASSIGN_OR_RETURN(Tj, values.at<Pose>(keys()[1]));
  PoseJacobian jacobian_i, jacobian_j;
  const Residual r = whitened_error(Ti, Tj, jacobians ? &jacobian_i : nullptr, jacobians ? &jacobian_j : nullptr);
  if (jacobians != nullptr) *jacobians = {jacobian_i, jacobian_j};
  return Eigen::VectorXd(r);
}

template class ChordalBetweenFactor<SE2>;
template class ChordalBetweenFactor<SE3>;
template class BetweenFactor<SE2>;
template class BetweenFactor<SE3>;
template class PriorFactor<SE2>;
template class PriorFactor<SE3>;

}  // namespace hanzo::fusion::graph
