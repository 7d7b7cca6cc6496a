#include "hanzo/fusion/graph/projection_factors.hpp"

#include <fmt/format.h>

namespace hanzo::fusion::graph {
namespace {

// The landmark in the camera frame and its Jacobians with respect to the pose and the point.
struct CameraPoint {
  Eigen::Vector3d p_camera;
  Eigen::Matrix<double, 3, 6> d_pose;
  Eigen::Matrix3d d_point;
};

CameraPoint camera_point(const SE3& T_world_body, const Eigen::Vector3d& p_world, const SE3& T_body_camera, bool with_jacobians) {
  const Eigen::Matrix3d R_world_body_transpose = T_world_body.rotation().matrix().transpose();
  const Eigen::Vector3d p_body = R_world_body_transpose * (p_world - T_world_body.translation());
  const Eigen::Matrix3d R_body_camera_transpose = T_body_camera.rotation().matrix().transpose();
  CameraPoint result;
  result.p_camera = R_body_camera_transpose * (p_body - T_body_camera.translation());
  if (with_jacobians) {
    result.d_pose << -R_body_camera_transpose, R_body_camera_transpose * SO3::hat(p_body);
    result.d_point = R_body_camera_transpose * R_world_body_transpose;
  }
  return result;
}

// evaluate() on top of whitened_error(): the Values lookup, the noise's size and the error
// message for a landmark behind the camera.
template <typename FactorType>
Result<Eigen::VectorXd> evaluate_projection(const FactorType& factor, const Values& values, std::vector<Eigen::MatrixXd>* jacobians) {
  constexpr int kResiduals = FactorType::Residual::RowsAtCompileTime;
  const Key pose_key = factor.keys()[0], landmark_key = factor.keys()[1];
  if (factor.dimension() != kResiduals) {
    return Error(fmt::format("projection of {}: the noise is {}x{}, not {}x{}", key_to_string(landmark_key), factor.dimension(), factor.dimension(),
                             kResiduals, kResiduals));
  }
  SE3 T_world_body;
  Eigen::Vector3d p_world;
  HANZO_ASSIGN_OR_RETURN(T_world_body, values.at<SE3>(pose_key));
  HANZO_ASSIGN_OR_RETURN(p_world, values.at<Eigen::Vector3d>(landmark_key));
  typename FactorType::PoseJacobian d_pose;
  typename FactorType::PointJacobian d_point;
  const std::optional<typename FactorType::Residual> residual =
      factor.whitened_error(T_world_body, p_world, jacobians ? &d_pose : nullptr, jacobians ? &d_point : nullptr);
  if (!residual) return Error(fmt::format("{} is behind the camera of {}", key_to_string(landmark_key), key_to_string(pose_key)));
  if (jacobians != nullptr) *jacobians = {d_pose, d_point};
  return Eigen::VectorXd(*residual);
}

}  // namespace

std::optional<ProjectionFactor::Residual> ProjectionFactor::whitened_error(const SE3& T_world_body, const Eigen::Vector3d& p_world, PoseJacobian* d_pose,
                                                                           PointJacobian* d_point) const {
  const bool with_jacobians = d_pose != nullptr || d_point != nullptr;
  const CameraPoint point = camera_point(T_world_body, p_world, T_body_camera_, with_jacobians);
  Eigen::Matrix<double, 2, 3> d_pixel;
  const std::optional<Eigen::Vector2d> pixel = camera_.project(point.p_camera, with_jacobians ? &d_pixel : nullptr);
  if (!pixel) return std::nullopt;
  const Eigen::Matrix2d U = noise_.sqrt_information();
  if (d_pose != nullptr) *d_pose = U * d_pixel * point.d_pose;
  if (d_point != nullptr) *d_point = U * d_pixel * point.d_point;
  return Residual(U * (*pixel - measured_));
}

Result<Eigen::VectorXd> ProjectionFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  return evaluate_projection(*this, values, jacobians);
}

std::optional<StereoProjectionFactor::Residual> StereoProjectionFactor::whitened_error(const SE3& T_world_body, const Eigen::Vector3d& p_world,
                                                                                       PoseJacobian* d_pose, PointJacobian* d_point) const {
  if (camera_.distortion != PinholeCamera::Distortion::kNone) return std::nullopt;
  const bool with_jacobians = d_pose != nullptr || d_point != nullptr;
  const CameraPoint point = camera_point(T_world_body, p_world, T_body_camera_, with_jacobians);
  const double X = point.p_camera.x(), Y = point.p_camera.y(), Z = point.p_camera.z();
  if (!(Z > camera_.min_depth)) return std::nullopt;
  const double fx = camera_.fx, fy = camera_.fy;
  const Eigen::Vector3d predicted(fx * X / Z + camera_.cx, fx * (X - baseline_) / Z + camera_.cx, fy * Y / Z + camera_.cy);
  const Eigen::Matrix3d U = noise_.sqrt_information();
  if (with_jacobians) {
    Eigen::Matrix3d d_pixel;
    d_pixel << fx / Z, 0.0, -fx * X / (Z * Z), fx / Z, 0.0, -fx * (X - baseline_) / (Z * Z), 0.0, fy / Z, -fy * Y / (Z * Z);
    if (d_pose != nullptr) *d_pose = U * d_pixel * point.d_pose;
    if (d_point != nullptr) *d_point = U * d_pixel * point.d_point;
  }
  return Residual(U * (predicted - measured_));
}

Result<Eigen::VectorXd> StereoProjectionFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  if (camera_.distortion != PinholeCamera::Distortion::kNone) return Error("stereo projection: the camera must be rectified (no distortion)");
  return evaluate_projection(*this, values, jacobians);
}

}  // namespace hanzo::fusion::graph
