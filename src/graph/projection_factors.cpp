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

Result<CameraPoint> camera_point(const Values& values, Key pose_key, Key landmark_key, const SE3& T_body_camera) {
  SE3 T_world_body;
  Eigen::Vector3d p_world;
  HANZO_ASSIGN_OR_RETURN(T_world_body, values.at<SE3>(pose_key));
  HANZO_ASSIGN_OR_RETURN(p_world, values.at<Eigen::Vector3d>(landmark_key));
  const Eigen::Matrix3d R_world_body_transpose = T_world_body.rotation().matrix().transpose();
  const Eigen::Vector3d p_body = R_world_body_transpose * (p_world - T_world_body.translation());
  const Eigen::Matrix3d R_body_camera_transpose = T_body_camera.rotation().matrix().transpose();
  CameraPoint result;
  result.p_camera = R_body_camera_transpose * (p_body - T_body_camera.translation());
  result.d_pose << -R_body_camera_transpose, R_body_camera_transpose * SO3::hat(p_body);
  result.d_point = R_body_camera_transpose * R_world_body_transpose;
  return result;
}

Error behind_camera(Key pose, Key landmark, double depth) {
  return Error(fmt::format("{} is behind the camera of {} (depth {} m)", key_to_string(landmark), key_to_string(pose), depth));
}

}  // namespace

Result<Eigen::VectorXd> ProjectionFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  CameraPoint point;
  HANZO_ASSIGN_OR_RETURN(point, camera_point(values, keys()[0], keys()[1], T_body_camera_));
  Eigen::Matrix<double, 2, 3> d_pixel;
  const std::optional<Eigen::Vector2d> pixel = camera_.project(point.p_camera, jacobians != nullptr ? &d_pixel : nullptr);
  if (!pixel) return behind_camera(keys()[0], keys()[1], point.p_camera.z());
  const Eigen::MatrixXd& U = noise_.sqrt_information();
  if (jacobians != nullptr) *jacobians = {U * d_pixel * point.d_pose, U * d_pixel * point.d_point};
  return Eigen::VectorXd(U * (*pixel - measured_));
}

Result<Eigen::VectorXd> StereoProjectionFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  if (camera_.distortion != PinholeCamera::Distortion::kNone) return Error("stereo projection: the camera must be rectified (no distortion)");
  CameraPoint point;
  HANZO_ASSIGN_OR_RETURN(point, camera_point(values, keys()[0], keys()[1], T_body_camera_));
  const double X = point.p_camera.x(), Y = point.p_camera.y(), Z = point.p_camera.z();
  if (!(Z > camera_.min_depth)) return behind_camera(keys()[0], keys()[1], Z);
  const double fx = camera_.fx, fy = camera_.fy;
  const Eigen::Vector3d predicted(fx * X / Z + camera_.cx, fx * (X - baseline_) / Z + camera_.cx, fy * Y / Z + camera_.cy);
  const Eigen::MatrixXd& U = noise_.sqrt_information();
  if (jacobians != nullptr) {
    Eigen::Matrix3d d_pixel;
    d_pixel << fx / Z, 0.0, -fx * X / (Z * Z), fx / Z, 0.0, -fx * (X - baseline_) / (Z * Z), 0.0, fy / Z, -fy * Y / (Z * Z);
    *jacobians = {U * d_pixel * point.d_pose, U * d_pixel * point.d_point};
  }
  return Eigen::VectorXd(U * (predicted - measured_));
}

}  // namespace hanzo::fusion::graph
