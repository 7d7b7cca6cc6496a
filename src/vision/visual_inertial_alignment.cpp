#include "hanzo/fusion/vision/visual_inertial_alignment.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <fmt/format.h>
#include <opencv2/calib3d.hpp>

#include "hanzo/fusion/graph/imu_preintegration.hpp"
#include "pose_refinement.hpp"
#include "triangulation.hpp"

namespace hanzo::fusion::vision {
namespace {

constexpr double kDegree = M_PI / 180.0;
constexpr int kMinPnpPoints = 10;
constexpr double kMaxImuGapSeconds = 0.1;

using Track = std::map<int, Eigen::Vector2d>;  // frame -> camera 0's normalized coordinates

// The IMU between t0 and t1, each sample held until the next (the one at or before t0 first).
Result<graph::ImuPreintegration> preintegrate(const std::vector<estimate::ImuSample>& imu, Timestamp t0, Timestamp t1,
                                              const graph::ImuPreintegrationConfig& config, const Eigen::Vector3d& gyro_bias) {
  graph::ImuBias bias;
  bias.gyroscope = gyro_bias;
  graph::ImuPreintegration preintegration(config, bias);
  auto sample = std::upper_bound(imu.begin(), imu.end(), t0, [](Timestamp t, const estimate::ImuSample& s) { return t < s.timestamp; });
  if (sample == imu.begin()) return Error(fmt::format("no IMU sample at or before the frame at {:.3f} s", t0.seconds()));
  --sample;
  Timestamp t = t0;
  while (t < t1) {
    const auto next = std::next(sample);
    const Timestamp until = next != imu.end() ? std::min(next->timestamp, t1) : t1;
    if ((until - sample->timestamp).seconds() > kMaxImuGapSeconds) {
      return Error(fmt::format("IMU gap of {:.3f} s at {:.3f} s", (until - sample->timestamp).seconds(), sample->timestamp.seconds()));
    }
    if (until > t) HANZO_RETURN_IF_ERROR(preintegration.integrate(sample->linear_acceleration, sample->angular_velocity, (until - t).seconds()));
    t = until;
    if (next != imu.end() && next->timestamp <= t) sample = next;
  }
  return preintegration;
}

// Reprojection check in pixels (normalized coordinates scaled by the focal length).
bool reprojects(const SE3& T_camera_c0, const Eigen::Vector3d& point, const Eigen::Vector2d& normalized, double focal, double max_px) {
  const Eigen::Vector3d in_camera = T_camera_c0.act(point);
  if (in_camera.z() <= 0.0) return false;
  return focal * (in_camera.head<2>() / in_camera.z() - normalized).norm() <= max_px;
}

struct Structure {
  std::vector<std::optional<SE3>> T_camera_c0;  // per frame
  std::map<uint64_t, Eigen::Vector3d> points;   // c0 frame
};

// Two-view start: the pose of frame `other` relative to frame 0 from the essential matrix (unit
// baseline) and the points both see, when at least min_tracks agree and their median parallax
// reaches min_parallax_degrees.
Result<Structure> two_view_start(int frame_count, int other, const std::map<uint64_t, Track>& tracks, const VisualInertialAlignmentConfig& config) {
  std::vector<uint64_t> ids;
  std::vector<cv::Point2d> first_points, other_points;
  for (const auto& [id, track] : tracks) {
    if (!track.count(0) || !track.count(other)) continue;
    ids.push_back(id);
    first_points.emplace_back(track.at(0).x(), track.at(0).y());
    other_points.emplace_back(track.at(other).x(), track.at(other).y());
  }
  if (static_cast<int>(ids.size()) < config.min_tracks) return Error(fmt::format("frames 0 and {} share {} tracks", other, ids.size()));
  cv::Mat inliers;
  const cv::Mat essential = cv::findEssentialMat(first_points, other_points, 1.0, cv::Point2d(0.0, 0.0), cv::RANSAC, 0.999,
                                                 config.ransac_threshold_px / config.focal_length_px, inliers);
  if (essential.rows < 3 || essential.cols != 3) return Error(fmt::format("no essential matrix between frames 0 and {}", other));
  cv::Mat rotation, translation;
  const int agreeing = cv::recoverPose(essential.rowRange(0, 3), first_points, other_points, rotation, translation, 1.0, cv::Point2d(0.0, 0.0), inliers);
  if (agreeing < config.min_tracks) return Error(fmt::format("{} of {} tracks of frames 0 and {} agree with the essential matrix", agreeing, ids.size(), other));
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  for (int r = 0; r < 3; ++r) {
    t(r) = translation.at<double>(r);
    for (int c = 0; c < 3; ++c) R(r, c) = rotation.at<double>(r, c);
  }
  Structure structure;
  structure.T_camera_c0.assign(static_cast<std::size_t>(frame_count), std::nullopt);
  structure.T_camera_c0[0] = SE3();
  const SE3 T_other_c0(SO3::from_matrix(R), t);
  structure.T_camera_c0[static_cast<std::size_t>(other)] = T_other_c0;
  std::vector<double> parallax;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (!inliers.at<uchar>(static_cast<int>(i))) continue;
    const Track& track = tracks.at(ids[i]);
    const std::optional<Eigen::Vector3d> point = triangulate(SE3(), track.at(0), T_other_c0, track.at(other));
    if (!point || !reprojects(SE3(), *point, track.at(0), config.focal_length_px, 2.0 * config.ransac_threshold_px) ||
        !reprojects(T_other_c0, *point, track.at(other), config.focal_length_px, 2.0 * config.ransac_threshold_px)) {
      continue;
    }
    structure.points[ids[i]] = *point;
    parallax.push_back(triangulation_angle(SE3(), T_other_c0, *point));
  }
  if (static_cast<int>(structure.points.size()) < config.min_tracks) return Error(fmt::format("{} points triangulated", structure.points.size()));
  std::nth_element(parallax.begin(), parallax.begin() + static_cast<std::ptrdiff_t>(parallax.size() / 2), parallax.end());
  if (parallax[parallax.size() / 2] < config.min_parallax_degrees * kDegree) {
    return Error(fmt::format("too little parallax: {:.1f} degrees between frames 0 and {}", parallax[parallax.size() / 2] / kDegree, other));
  }
  return structure;
}

// The point of a track from all its posed views, when it reprojects into every one of them and
// its views span half the parallax the start needed.
std::optional<Eigen::Vector3d> triangulate_track(const Track& track, const Structure& structure, const VisualInertialAlignmentConfig& config) {
  std::vector<SE3> poses;
  std::vector<Eigen::Vector2d> normalized;
  for (const auto& [k, x] : track) {
    if (!structure.T_camera_c0[static_cast<std::size_t>(k)]) continue;
    poses.push_back(*structure.T_camera_c0[static_cast<std::size_t>(k)]);
    normalized.push_back(x);
  }
  if (poses.size() < 2) return std::nullopt;
  const std::optional<Eigen::Vector3d> point = triangulate_views(poses, normalized);
  if (!point) return std::nullopt;
  for (std::size_t v = 0; v < poses.size(); ++v) {
    if (!reprojects(poses[v], *point, normalized[v], config.focal_length_px, 2.0 * config.ransac_threshold_px)) return std::nullopt;
  }
  if (triangulation_angle(poses.front(), poses.back(), *point) < 0.5 * config.min_parallax_degrees * kDegree) return std::nullopt;
  return point;
}

// Frame k placed on the points it sees: PnP RANSAC (or from `start`), then refined.
Result<SE3> place_frame(int k, const std::optional<SE3>& start, const Structure& structure, const std::map<uint64_t, Track>& tracks,
                        const VisualInertialAlignmentConfig& config) {
  std::vector<cv::Point3d> points;
  std::vector<cv::Point2d> normalized;
  std::vector<PoseObservation> observations;
  for (const auto& [id, point] : structure.points) {
    const auto seen = tracks.at(id).find(k);
    if (seen == tracks.at(id).end()) continue;
    points.emplace_back(point.x(), point.y(), point.z());
    normalized.emplace_back(seen->second.x(), seen->second.y());
    observations.push_back({point, config.focal_length_px * seen->second, 1.0});
  }
  if (static_cast<int>(points.size()) < kMinPnpPoints) return Error(fmt::format("frame {} sees {} of the triangulated points", k, points.size()));
  SE3 initial;
  if (start) {
    initial = *start;
  } else {
    const std::optional<PnpSolution> pnp = solve_pnp_ransac(points, normalized, config.ransac_threshold_px / config.focal_length_px, 100);
    if (!pnp) return Error(fmt::format("frame {} could not be placed (PnP)", k));
    initial = pnp->T_camera_world;
  }
  PinholeCamera camera;
  camera.fx = camera.fy = config.focal_length_px;
  const PoseRefinement refined = refine_pose(initial, observations, camera);
  if (refined.inliers < kMinPnpPoints) return Error(fmt::format("frame {}: {} points agree with its pose", k, refined.inliers));
  return refined.T_camera_world;
}

// Step 1: the frames' camera poses in c0, up to scale (the start's baseline is 1). The start
// pair is frame 0 and the first frame with enough parallax; the other frames are placed in order
// by PnP, each adding the tracks it completes; at the end every point is re-triangulated from all
// its views and every frame placed again.
Result<Structure> structure_from_motion(const std::vector<AlignmentFrame>& frames, const std::map<uint64_t, Track>& tracks,
                                        const VisualInertialAlignmentConfig& config) {
  const int n = static_cast<int>(frames.size());
  std::optional<Structure> started;
  Error why("no frame pair");
  int other = 1;
  for (; other < n && !started; ++other) {
    Result<Structure> attempt = two_view_start(n, other, tracks, config);
    if (attempt) {
      started.emplace(std::move(attempt).value());
    } else {
      why = attempt.error();
    }
  }
  if (!started) return why;
  Structure& structure = *started;
  const auto add_points = [&] {
    for (const auto& [id, track] : tracks) {
      if (structure.points.count(id)) continue;
      if (const std::optional<Eigen::Vector3d> point = triangulate_track(track, structure, config)) structure.points[id] = *point;
    }
  };
  for (int k = 1; k < n; ++k) {
    if (structure.T_camera_c0[static_cast<std::size_t>(k)]) continue;
    SE3 placed;
    HANZO_ASSIGN_OR_RETURN(placed, place_frame(k, std::nullopt, structure, tracks, config));
    structure.T_camera_c0[static_cast<std::size_t>(k)] = placed;
    add_points();
  }
  structure.points.clear();
  add_points();
  for (int k = 1; k < n; ++k) {
    SE3 placed;
    HANZO_ASSIGN_OR_RETURN(placed, place_frame(k, structure.T_camera_c0[static_cast<std::size_t>(k)], structure, tracks, config));
    structure.T_camera_c0[static_cast<std::size_t>(k)] = placed;
  }
  return structure;
}

// Step 3/4's least squares: unknowns (v_0 .. v_{n-1}, gravity part, s); gravity either free
// (3 unknowns) or on the sphere around `gravity_direction` (2 tangent unknowns).
struct LinearSolution {
  std::vector<Eigen::Vector3d> velocities;
  Eigen::Vector3d gravity;
  double scale = 0.0;
};

LinearSolution solve_linear(const std::vector<graph::ImuPreintegration>& imu, const std::vector<SO3>& R_c0_imu, const std::vector<Eigen::Vector3d>& p_c0_camera,
                            const Eigen::Vector3d& t_imu_camera, const std::optional<Eigen::Vector3d>& gravity_direction, double gravity_magnitude) {
  const int n = static_cast<int>(R_c0_imu.size());
  const int gravity_unknowns = gravity_direction ? 2 : 3;
  const int unknowns = 3 * n + gravity_unknowns + 1;
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(6 * (n - 1), unknowns);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(6 * (n - 1));
  Eigen::Matrix<double, 3, 2> tangent = Eigen::Matrix<double, 3, 2>::Zero();
  Eigen::Vector3d gravity_fixed = Eigen::Vector3d::Zero();
  if (gravity_direction) {
    const Eigen::Vector3d direction = gravity_direction->normalized();
    const Eigen::Vector3d helper = std::abs(direction.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    tangent.col(0) = direction.cross(helper).normalized();
    tangent.col(1) = direction.cross(tangent.col(0));
    gravity_fixed = gravity_magnitude * direction;
  }
  const int g = 3 * n, s = 3 * n + gravity_unknowns;
  for (int k = 0; k + 1 < n; ++k) {
    const graph::ImuPreintegration& delta = imu[static_cast<std::size_t>(k)];
    const double dt = delta.delta_time();
    const Eigen::Matrix3d Rk = R_c0_imu[static_cast<std::size_t>(k)].matrix(), Rk1 = R_c0_imu[static_cast<std::size_t>(k + 1)].matrix();
    const int row = 6 * k;
    // Position: s (p_{k+1} - p_k) - v_k dt - 1/2 g dt^2 = R_k alpha + (R_{k+1} - R_k) t_bc.
    A.block<3, 3>(row, 3 * k) = -dt * Eigen::Matrix3d::Identity();
    A.block<3, 1>(row, s) = p_c0_camera[static_cast<std::size_t>(k + 1)] - p_c0_camera[static_cast<std::size_t>(k)];
    b.segment<3>(row) = Rk * delta.deltas().position + (Rk1 - Rk) * t_imu_camera;
    // Velocity: v_{k+1} - v_k - g dt = R_k beta.
    A.block<3, 3>(row + 3, 3 * k) = -Eigen::Matrix3d::Identity();
    A.block<3, 3>(row + 3, 3 * (k + 1)) = Eigen::Matrix3d::Identity();
    b.segment<3>(row + 3) = Rk * delta.deltas().velocity;
    const Eigen::Matrix3d position_by_gravity = -0.5 * dt * dt * Eigen::Matrix3d::Identity(), velocity_by_gravity = -dt * Eigen::Matrix3d::Identity();
    if (gravity_direction) {
      A.block<3, 2>(row, g) = position_by_gravity * tangent;
      A.block<3, 2>(row + 3, g) = velocity_by_gravity * tangent;
      b.segment<3>(row) -= position_by_gravity * gravity_fixed;
      b.segment<3>(row + 3) -= velocity_by_gravity * gravity_fixed;
    } else {
      A.block<3, 3>(row, g) = position_by_gravity;
      A.block<3, 3>(row + 3, g) = velocity_by_gravity;
    }
  }
  const Eigen::VectorXd x = A.colPivHouseholderQr().solve(b);
  LinearSolution solution;
  for (int k = 0; k < n; ++k) solution.velocities.push_back(x.segment<3>(3 * k));
  solution.gravity = gravity_direction ? Eigen::Vector3d(gravity_fixed + tangent * x.segment<2>(g)) : Eigen::Vector3d(x.segment<3>(g));
  solution.scale = x(s);
  return solution;
}

}  // namespace

Result<VisualInertialAlignment> align_visual_inertial(const std::vector<AlignmentFrame>& frames, const std::vector<estimate::ImuSample>& imu,
                                                      const SE3& T_imu_camera, const VisualInertialAlignmentConfig& config) {
  const int n = static_cast<int>(frames.size());
  if (n < std::max(config.min_frames, 3)) return Error(fmt::format("{} frames; the alignment needs {}", n, std::max(config.min_frames, 3)));
  std::map<uint64_t, Track> tracks;
  for (int k = 0; k < n; ++k) {
    if (k > 0 && frames[static_cast<std::size_t>(k)].time <= frames[static_cast<std::size_t>(k - 1)].time) return Error("frames are not in time order");
    for (const FeatureObservation& observation : frames[static_cast<std::size_t>(k)].observations) {
      if (observation.camera == 0 && observation.normalized.allFinite()) tracks[observation.feature_id][k] = observation.normalized;
    }
  }
  Structure structure;
  HANZO_ASSIGN_OR_RETURN(structure, with_context(structure_from_motion(frames, tracks, config), "structure from motion"));

  std::vector<SO3> R_c0_imu;
  std::vector<Eigen::Vector3d> p_c0_camera;
  for (const std::optional<SE3>& T_camera_c0 : structure.T_camera_c0) {
    const SE3 T_c0_camera = T_camera_c0->inverse();
    R_c0_imu.push_back(T_c0_camera.rotation() * T_imu_camera.rotation().inverse());
    p_c0_camera.push_back(T_c0_camera.translation());
  }
  graph::ImuPreintegrationConfig preintegration_config;
  preintegration_config.process_noise_accel = config.process_noise_accel;
  preintegration_config.process_noise_gyro = config.process_noise_gyro;
  preintegration_config.sample_interval = config.sample_interval;
  const auto preintegrate_all = [&](const Eigen::Vector3d& gyro_bias) -> Result<std::vector<graph::ImuPreintegration>> {
    std::vector<graph::ImuPreintegration> deltas;
    for (int k = 0; k + 1 < n; ++k) {
      Result<graph::ImuPreintegration> delta =
          preintegrate(imu, frames[static_cast<std::size_t>(k)].time, frames[static_cast<std::size_t>(k + 1)].time, preintegration_config, gyro_bias);
      if (!delta) return delta.error();
      deltas.push_back(std::move(delta).value());
    }
    return deltas;
  };
  // Step 2: the gyro bias (two Gauss-Newton steps, re-preintegrating after each).
  VisualInertialAlignment alignment;
  std::vector<graph::ImuPreintegration> deltas;
  for (int iteration = 0; iteration < 2; ++iteration) {
    HANZO_ASSIGN_OR_RETURN(deltas, with_context(preintegrate_all(alignment.gyro_bias), "IMU"));
    Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
    Eigen::Vector3d gradient = Eigen::Vector3d::Zero();
    for (int k = 0; k + 1 < n; ++k) {
      const graph::ImuPreintegration& delta = deltas[static_cast<std::size_t>(k)];
      const SO3 visual = R_c0_imu[static_cast<std::size_t>(k)].inverse() * R_c0_imu[static_cast<std::size_t>(k + 1)];
      const Eigen::Vector3d residual = (delta.deltas().rotation.inverse() * visual).log();
      const Eigen::Matrix3d& J = delta.rotation_by_gyro_bias();
      H += J.transpose() * J;
      gradient += J.transpose() * residual;
    }
    alignment.gyro_bias += H.ldlt().solve(gradient);
  }
  HANZO_ASSIGN_OR_RETURN(deltas, with_context(preintegrate_all(alignment.gyro_bias), "IMU"));

  // Steps 3 and 4.
  const Eigen::Vector3d t_imu_camera = T_imu_camera.translation();
  LinearSolution solution = solve_linear(deltas, R_c0_imu, p_c0_camera, t_imu_camera, std::nullopt, config.gravity_magnitude);
  alignment.gravity_error = std::abs(solution.gravity.norm() / config.gravity_magnitude - 1.0);
  if (!(solution.scale > 0.0)) return Error(fmt::format("the scale came out {:.3g}: the images and the IMU disagree", solution.scale));
  if (!(alignment.gravity_error <= config.max_gravity_error)) {
    return Error(fmt::format("gravity came out {:.2f} m/s^2 (expected {:.2f}): the images and the IMU disagree", solution.gravity.norm(),
                             config.gravity_magnitude));
  }
  for (int iteration = 0; iteration < 3; ++iteration) {
    solution = solve_linear(deltas, R_c0_imu, p_c0_camera, t_imu_camera, solution.gravity, config.gravity_magnitude);
  }
  if (!(solution.scale > 0.0) || !solution.gravity.allFinite()) return Error("the refined solution has no positive scale");
  // World: gravity along -z, yaw that of c0.
  const Eigen::Quaterniond R_world_c0 = Eigen::Quaterniond::FromTwoVectors(solution.gravity.normalized(), -Eigen::Vector3d::UnitZ());
  const SO3 world_from_c0 = SO3(R_world_c0.normalized());
  alignment.R_world_imu = world_from_c0 * R_c0_imu.back();
  alignment.velocity_world = world_from_c0 * solution.velocities.back();
  alignment.scale = solution.scale;
  alignment.frames = n;
  alignment.points = static_cast<int>(structure.points.size());
  if (!alignment.velocity_world.allFinite() || !alignment.gyro_bias.allFinite()) return Error("the solution is not finite");
  return alignment;
}

}  // namespace hanzo::fusion::vision
