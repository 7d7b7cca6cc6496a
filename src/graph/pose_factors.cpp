#include "hanzo/fusion/graph/pose_factors.hpp"

#include <type_traits>

#include <Eigen/Cholesky>

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
Result<Eigen::VectorXd> BetweenFactor<Pose>::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  Pose Ti, Tj;
  HANZO_ASSIGN_OR_RETURN(Ti, values.at<Pose>(keys()[0]));
  HANZO_ASSIGN_OR_RETURN(Tj, values.at<Pose>(keys()[1]));
  const Pose error = measured_inverse_ * (Ti.inverse() * Tj);
  const typename Pose::Tangent r = error.log();
  const Eigen::MatrixXd& U = noise_.sqrt_information();
  if (jacobians != nullptr) {
    const typename Pose::Jacobian Jr_inverse = Pose::right_jacobian_inverse(r);
    jacobians->resize(2);
    (*jacobians)[0] = -U * Jr_inverse * (Tj.inverse() * Ti).adjoint();
    (*jacobians)[1] = U * Jr_inverse;
  }
  return Eigen::VectorXd(U * r);
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

// Rotation, translation and the so(d) generators of a pose, as dynamic matrices.
struct PoseParts {
  Eigen::MatrixXd R;
  Eigen::VectorXd t;
  std::vector<Eigen::MatrixXd> generators;  // d(R Exp(phi))/d phi_k = R G_k
};
PoseParts parts(const SE2& pose) {
  Eigen::Matrix2d G;
  G << 0, -1, 1, 0;
  return {pose.rotation_matrix(), pose.translation(), {G}};
}
PoseParts parts(const SE3& pose) {
  return {pose.rotation().matrix(), pose.translation(),
          {SO3::hat(Eigen::Vector3d::UnitX()), SO3::hat(Eigen::Vector3d::UnitY()), SO3::hat(Eigen::Vector3d::UnitZ())}};
}
Eigen::VectorXd vectorized(const Eigen::MatrixXd& m) { return Eigen::Map<const Eigen::VectorXd>(m.data(), m.size()); }

}  // namespace

template <typename Pose>
int ChordalBetweenFactor<Pose>::dimension() const {
  const int d = std::is_same_v<Pose, SE2> ? 2 : 3;
  return d * d + d;
}

template <typename Pose>
Result<Eigen::VectorXd> ChordalBetweenFactor<Pose>::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  Pose Ti, Tj;
  HANZO_ASSIGN_OR_RETURN(Ti, values.at<Pose>(keys()[0]));
  HANZO_ASSIGN_OR_RETURN(Tj, values.at<Pose>(keys()[1]));
  const PoseParts i = parts(Ti), j = parts(Tj), z = parts(measured_);
  const int d = static_cast<int>(i.t.size());
  Eigen::VectorXd r(d * d + d);
  r.head(d * d) = sqrt_kappa_ * vectorized(j.R - i.R * z.R);
  r.tail(d) = sqrt_tau_ * (j.t - i.t - i.R * z.t);
  if (jacobians != nullptr) {
    // Tangent order: translation (d), then rotation (d == 2: 1, d == 3: 3); T Exp(rho, phi)
    // moves t by R rho and R by R [phi].
    const int rotations = static_cast<int>(i.generators.size());
    Eigen::MatrixXd Ji = Eigen::MatrixXd::Zero(d * d + d, d + rotations), Jj = Ji;
    Ji.bottomLeftCorner(d, d) = -sqrt_tau_ * i.R;
    Jj.bottomLeftCorner(d, d) = sqrt_tau_ * j.R;
    for (int k = 0; k < rotations; ++k) {
      const Eigen::MatrixXd& G = i.generators[static_cast<size_t>(k)];
      Ji.block(0, d + k, d * d, 1) = -sqrt_kappa_ * vectorized(i.R * G * z.R);
      Ji.block(d * d, d + k, d, 1) = -sqrt_tau_ * i.R * G * z.t;
      Jj.block(0, d + k, d * d, 1) = sqrt_kappa_ * vectorized(j.R * G);
    }
    *jacobians = {Ji, Jj};
  }
  return r;
}

template class ChordalBetweenFactor<SE2>;
template class ChordalBetweenFactor<SE3>;
template class BetweenFactor<SE2>;
template class BetweenFactor<SE3>;
template class PriorFactor<SE2>;
template class PriorFactor<SE3>;

}  // namespace hanzo::fusion::graph
