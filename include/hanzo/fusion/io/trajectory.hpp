#pragma once
// Trajectories (timestamped poses T_world_body) and the three text formats robotics users
// exchange them in:
//
//  - TUM:   one pose a line, "timestamp tx ty tz qx qy qz qw" (seconds, metres, Hamilton
//           quaternion x y z w); '#' comment lines; space or comma separated.
//  - KITTI: one pose a line, the 12 numbers of the row-major 3x4 matrix [R | t]; no times
//           (frame i gets the i-th line of an optional times file, e.g. KITTI's times.txt,
//           or i seconds when there is none).
//  - EuRoC: the ASL ground-truth CSV "#timestamp [ns], p_RS_R_x [m], p_RS_R_y [m],
//           p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], ..." (nanoseconds,
//           quaternion w x y z; any further columns — velocity, biases — are ignored).
//
// Readers reject malformed lines, non-finite numbers, zero quaternions and timestamps that go
// back in time, naming file and line. A pose that repeats the previous timestamp (motion-capture
// files have them: TUM fr2/desk line 10863) is dropped with a logged warning and counted; the
// first pose of the time is kept, which is the one evo's association would match. Rotation matrices and quaternions are kept as written
// (the matrix form is stored, so evaluation reproduces tools that work on raw matrices).

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se2.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"

namespace hanzo::fusion::io {

/// A pose as read from a file: a 4x4 homogeneous matrix [R t; 0 1] mapping body coordinates
/// into the trajectory's world frame. R is what the file gave (quaternions are converted
/// with Eigen's toRotationMatrix() after normalization; KITTI matrices are taken verbatim).
using PoseMatrix = Eigen::Matrix4d;

/// A planar pose (rotation about z, z = 0) as a pose matrix, and a pose matrix's planar part
/// (x, y and the yaw of R) as an SE2.
PoseMatrix pose_matrix(const SE2& pose);
SE2 planar_pose(const PoseMatrix& pose);

struct Trajectory {
  std::vector<Timestamp> timestamps;  ///< same length as poses, strictly increasing
  std::vector<PoseMatrix> poses;      ///< T_world_body
  /// Poses the reader dropped because they repeated the previous timestamp.
  std::size_t dropped_duplicate_timestamps = 0;

  std::size_t size() const { return poses.size(); }
  bool empty() const { return poses.empty(); }
  Eigen::Vector3d position(std::size_t i) const { return poses[i].block<3, 1>(0, 3); }
  /// The pose as an SE3 (rotation projected onto SO3).
  SE3 pose_se3(std::size_t i) const { return SE3::from_matrix(poses[i]); }
  /// Sum of the distances between consecutive positions (m).
  double path_length() const;
  /// Keeps the poses at `indices` (in that order; repeats allowed).
  Trajectory subset(const std::vector<std::size_t>& indices) const;
  /// Applies T_new_world on the left of every pose (and scales positions by `scale` first,
  /// for Sim(3): p' = s R p + t, R' = R_align R).
  void transform(const PoseMatrix& T_new_world, double scale = 1.0);
};

enum class TrajectoryFormat { kTum, kKitti, kEuroc };

/// "tum", "kitti", "euroc".
Result<TrajectoryFormat> trajectory_format_from_name(const std::string& name);
const char* trajectory_format_name(TrajectoryFormat format);

/// Reads a trajectory. `kitti_times_path` (KITTI only) is a file with one time in seconds a
/// line and as many lines as poses.
Result<Trajectory> read_trajectory(const std::string& path, TrajectoryFormat format,
                                   const std::optional<std::string>& kitti_times_path = std::nullopt);
/// Parses a trajectory from text (`source_name` is used in error messages).
Result<Trajectory> parse_trajectory(const std::string& text, TrajectoryFormat format,
                                    const std::string& source_name,
                                    const std::vector<Timestamp>* kitti_times = nullptr);
/// Writes atomically. Numbers are written in shortest round-trip form, so reading the file
/// back gives the same doubles (TUM/EuRoC quaternions are computed from the matrix).
Status write_trajectory(const std::string& path, const Trajectory& trajectory, TrajectoryFormat format);
std::string format_trajectory(const Trajectory& trajectory, TrajectoryFormat format);

/// Parses a decimal number of seconds ("1311868164.363181", "1.037359e-01") into a
/// Timestamp, exactly for plain decimals (no rounding through double) up to 9 fractional digits.
Result<Timestamp> parse_seconds(const std::string& text);
/// Seconds with 9 fractional digits, trailing zeros removed ("1311868164.363181").
std::string format_seconds(Timestamp timestamp);

}  // namespace hanzo::fusion::io
