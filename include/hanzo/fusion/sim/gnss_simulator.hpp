#pragma once
// GnssSimulator: GNSS fixes of an antenna on the body, in WGS84 through the scenario's datum
// (the world ENU origin).
//
// Each fix = true antenna position (T_world_body(t) * T_body_gnss origin) + error, where the
// error per axis is a first-order Gauss-Markov process with the fix type's standard deviation
// (horizontal for east/north, vertical for up) and correlation_time (0: white noise, each fix
// independent). The reported position_covariance is the diagonal of those variances, so a
// filter's chi-square gate sees honest fixes; multipath jumps are NOT in the covariance (that
// is what makes them outliers).
//
// Default standard deviations (horizontal / vertical, metres): RTK_FIXED 0.02 / 0.04,
// RTK_FLOAT 0.3 / 0.6, FIX_3D 1.5 / 3.0, FIX_2D 5 / 10.
//
// Episodes in [start, end]:
//   outage   (tunnel, indoor) the receiver reports NO_FIX, 0 satellites, hdop 99, no
//            covariance, and the last fixed position (so consumers must read fix_type).
//   degraded (urban canyon) the fix type becomes `fix_type`, noise is multiplied by
//            noise_scale, fewer satellites; multipath jumps arrive at multipath_rate_hz
//            (Poisson), each an offset of multipath_magnitude metres in a random horizontal
//            direction lasting multipath_duration seconds.
//
// Sky blockage (sky_blockage, with a World): `constellation` satellites at fixed directions
// above the elevation mask (spread evenly in azimuth, elevations drawn from the seed; they
// move too slowly to matter over minutes). At each fix the antenna casts a ray to each; the
// World's buildings block them. With v of N visible: v < 4 gives NO_FIX (as an outage);
// v < N/2 degrades the fix as an episode would: FIX_3D (RTK lost), noise * sqrt(N / v),
// multipath jumps at 0.3 Hz * blocked fraction; satellites_used = v. Scripted episodes take
// precedence.

#include <cstdint>
#include <optional>
#include <random>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/geodesy.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"
#include "hanzo/fusion/sim/world.hpp"

namespace hanzo::fusion::sim {

/// Horizontal and vertical standard deviations (metres) of a fix type's default noise; zero
/// for NO_FIX.
Eigen::Vector2d default_gnss_noise(msgs::GnssFixType fix_type);

enum class GnssEpisodeType { kOutage, kDegraded };
std::string_view to_string(GnssEpisodeType type);  // "outage", "degraded"
std::optional<GnssEpisodeType> gnss_episode_type_from_string(std::string_view name);

struct GnssEpisode {
  GnssEpisodeType type = GnssEpisodeType::kOutage;
  Timestamp start;
  Timestamp end;
  msgs::GnssFixType fix_type = msgs::GnssFixType::kFix3d;  ///< degraded only
  double noise_scale = 3.0;                                ///< degraded only, >= 1
  double multipath_rate_hz = 0.1;                          ///< degraded only, jumps per second
  double multipath_magnitude = 10.0;                       ///< metres
  double multipath_duration = 3.0;                         ///< seconds
  uint32_t satellites = 6;                                 ///< degraded only
};

struct GnssSimulatorConfig {
  double rate_hz = 10.0;
  GeodeticPoint datum;  ///< WGS84 position of the world ENU origin
  SE3 T_body_gnss;      ///< the antenna's lever arm is its translation
  msgs::GnssFixType fix_type = msgs::GnssFixType::kFix3d;  ///< nominal fix
  /// Horizontal / vertical standard deviations in metres; absent: default_gnss_noise(fix_type).
  std::optional<Eigen::Vector2d> noise;
  double correlation_time = 0.0;  ///< seconds, >= 0 (0: white)
  uint32_t satellites = 14;
  std::vector<GnssEpisode> episodes;
  bool sky_blockage = false;      ///< needs a World at create()
  int constellation = 12;         ///< satellites above the mask, >= 4
  double elevation_mask = 0.1745; ///< radians (10 deg)
  uint64_t seed = 3;
};

class GnssSimulator {
 public:
  /// Fails when the datum is not a valid WGS84 point, or sky_blockage is set without a world
  /// (which must then outlive the simulator).
  static Result<GnssSimulator> create(GnssSimulatorConfig config, const SplineTrajectory& trajectory,
                                      const World* world = nullptr);

  /// The fix at `time`; call in increasing time order.
  msgs::GnssMessage measure(Timestamp time);
  /// The true antenna position in world ENU at `time`.
  Eigen::Vector3d true_antenna_position(Timestamp time) const;
  /// Satellites the antenna sees at `time` (the whole constellation without sky blockage).
  int visible_satellites(Timestamp time) const;
  const EnuFrame& enu_frame() const { return enu_; }

 private:
  GnssSimulator(GnssSimulatorConfig config, const SplineTrajectory& trajectory, const World* world, EnuFrame enu);
  /// The scripted episode at `time`, else the one sky blockage implies (kept in sky_episode_).
  const GnssEpisode* episode_at(Timestamp time);

  GnssSimulatorConfig config_;
  const SplineTrajectory* trajectory_;
  const World* world_;
  std::vector<Eigen::Vector3d> satellites_;  // unit directions, world ENU
  GnssEpisode sky_episode_;
  EnuFrame enu_;
  std::mt19937_64 random_;
  Eigen::Vector3d error_ = Eigen::Vector3d::Zero();  // standardized Gauss-Markov state (unit variance)
  std::optional<Timestamp> previous_time_;
  Eigen::Vector3d multipath_offset_ = Eigen::Vector3d::Zero();
  Timestamp multipath_until_;
  std::optional<msgs::GnssMessage> last_fix_;
};

}  // namespace hanzo::fusion::sim
