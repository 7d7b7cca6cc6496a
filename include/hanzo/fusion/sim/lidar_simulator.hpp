#pragma once
// LidarSimulator: spinning LiDAR sweeps by ray casting the World along a SplineTrajectory.
//
// A sweep is one revolution of `columns` firings spread evenly over 1 / rate_hz seconds; all
// rings of a column fire at the column's time (as an Ouster does; a Velodyne's sequential
// lasers are microseconds apart). The sensor moves during the sweep: every column is cast from
// the pose T_world_body(t) * T_body_lidar at its own time, and its points are expressed in the
// sensor frame of that instant, so sweeps carry the motion distortion a real sensor has and
// `point_timestamps` (non-decreasing, from the sweep start) tell a deskewer where each point
// belongs. The message timestamp is the sweep start. The sweep starts behind the sensor
// (azimuth pi) and turns clockwise seen from above, like a Velodyne. Points are ordered by
// column, then ring; `ring_ids` index `LidarPattern::elevations`.
//
// Per return: range = true range + N(0, range_noise^2); intensity = reflectivity
// * (0.5 + 0.5 * luminance of the texture) * |cos incidence| in [0, 1]. Rays that hit nothing
// within max_range, or closer than min_range, give no point.
//
// Weather episodes (rain, fog) inside [start, end]: each return is dropped with
// dropout_probability, returns beyond visibility_range are lost, and with phantom_probability
// a ray instead returns from a drop in the air at a uniform range in [min_range,
// phantom_max_range] with low intensity.

#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"
#include "hanzo/fusion/sim/world.hpp"

namespace hanzo::fusion::sim {

enum class LidarModel { kVelodyneVlp16, kVelodyneHdl64, kOusterOs1_64, kPlanarLaser };
/// "velodyne_vlp16", "velodyne_hdl64", "ouster_os1_64", "planar_laser" (the fusion
/// configuration's lidar types; planar_laser: config::kPlanarLaserType).
std::string_view to_string(LidarModel model);
std::optional<LidarModel> lidar_model_from_string(std::string_view name);

/// The beam layout of a spinning LiDAR.
struct LidarPattern {
  std::vector<double> elevations;  ///< radians, one per ring
  int columns = 1800;              ///< firings per revolution
  double min_range = 0.5;          ///< metres
  double max_range = 100.0;        ///< metres
  /// Horizontal field of view centred on the sensor's x axis (radians, (0, 2 pi]): a LiDAR
  /// mounted where the vehicle blocks part of its turn, or a forward-looking one. Columns
  /// outside give no returns (their time in the sweep stays).
  double horizontal_fov = 2.0 * 3.14159265358979323846;

  /// VLP-16: 16 rings -15..+15 deg every 2 deg, 1800 columns (0.2 deg at 10 Hz), 0.5-100 m.
  /// HDL-64E: 64 rings -24.33..+2 deg (lower block 1/2 deg apart, upper block 1/3 deg), 2083 columns, 0.9-120 m.
  /// Rings are numbered from the lowest beam up in every preset.
  /// OS1-64: 64 rings -22.5..+22.5 deg evenly, 1024 columns, 0.3-120 m.
  /// Planar laser (a 2D scanner such as a SICK or Hokuyo, all round): one ring at 0 deg,
  /// 1440 columns (0.25 deg), 0.1-30 m.
  static LidarPattern preset(LidarModel model);
};

struct LidarWeatherEpisode {
  Timestamp start;
  Timestamp end;
  double dropout_probability = 0.1;   ///< per return
  double phantom_probability = 0.02;  ///< per ray
  double phantom_max_range = 3.0;     ///< metres
  double visibility_range = 40.0;     ///< metres: returns beyond are lost
};

struct LidarSimulatorConfig {
  LidarPattern pattern = LidarPattern::preset(LidarModel::kVelodyneVlp16);
  double rate_hz = 10.0;      ///< revolutions per second, > 0
  double range_noise = 0.02;  ///< metres, standard deviation
  SE3 T_body_lidar;
  std::string frame_id = "lidar";
  std::vector<LidarWeatherEpisode> weather;
  int num_threads = 1;  ///< ray-casting threads (TBB); 0: all cores. The sweep is the same for any count.
  uint64_t seed = 2;
};

class LidarSimulator {
 public:
  /// world and trajectory must outlive the simulator.
  LidarSimulator(LidarSimulatorConfig config, const World& world, const SplineTrajectory& trajectory);

  /// The sweep starting at sweep_start. Call in increasing time order (noise is drawn in
  /// sequence). A sweep that sees nothing has no points (msgs::validate rejects it; the
  /// scenario runner leaves it out).
  msgs::PointCloudMessage measure(Timestamp sweep_start);
  /// The ground truth of the last sweep's points, one per point in their order: the object each
  /// hit (RayHit::object_id: World::object_class and World::is_moving tell its class and whether
  /// it moves; kPhantomReturn for a weather phantom).
  const std::vector<int>& last_object_ids() const { return last_object_ids_; }

  const LidarSimulatorConfig& config() const { return config_; }

 private:
  const LidarWeatherEpisode* weather_at(Timestamp time) const;

  LidarSimulatorConfig config_;
  const World& world_;
  const SplineTrajectory& trajectory_;
  std::vector<Eigen::Vector3d> ring_directions_;  // unit, sensor frame, at azimuth 0
  std::mt19937_64 random_;
  std::vector<int> last_object_ids_;
};

}  // namespace hanzo::fusion::sim
