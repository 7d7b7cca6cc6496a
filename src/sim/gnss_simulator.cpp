#include "hanzo/fusion/sim/gnss_simulator.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

#include "hanzo/fusion/core/enum_names.hpp"

namespace hanzo::fusion::sim {
namespace {

constexpr EnumNames<GnssEpisodeType, 2> kEpisodeNames{{{GnssEpisodeType::kOutage, "outage"},
                                                       {GnssEpisodeType::kDegraded, "degraded"}}};
constexpr float kNominalHdop = 0.9F;
constexpr float kNoFixHdop = 99.0F;
constexpr double kSkyRayLength = 1000.0;  // metres: buildings farther away do not block

}  // namespace

std::string_view to_string(GnssEpisodeType type) { return enum_name(kEpisodeNames, type); }
std::optional<GnssEpisodeType> gnss_episode_type_from_string(std::string_view name) { return enum_from_name(kEpisodeNames, name); }

Eigen::Vector2d default_gnss_noise(msgs::GnssFixType fix_type) {
  switch (fix_type) {
    case msgs::GnssFixType::kRtkFixed: return {0.02, 0.04};
    case msgs::GnssFixType::kRtkFloat: return {0.3, 0.6};
    case msgs::GnssFixType::kFix3d: return {1.5, 3.0};
    case msgs::GnssFixType::kFix2d: return {5.0, 10.0};
    case msgs::GnssFixType::kNoFix: break;
  }
  return Eigen::Vector2d::Zero();
}

Result<GnssSimulator> GnssSimulator::create(GnssSimulatorConfig config, const SplineTrajectory& trajectory, const World* world) {
  Result<EnuFrame> enu = with_context(EnuFrame::create(config.datum), "gnss datum");
  if (!enu) return enu.error();
  if (config.sky_blockage && world == nullptr) return Error{"gnss sky_blockage: needs the world to cast satellite rays in", "sky_blockage"};
  if (config.sky_blockage && config.constellation < 4) {
    return Error{fmt::format("gnss constellation: expected at least 4 satellites, got {}", config.constellation), "constellation"};
  }
  return GnssSimulator(std::move(config), trajectory, world, *enu);
}

GnssSimulator::GnssSimulator(GnssSimulatorConfig config, const SplineTrajectory& trajectory, const World* world, EnuFrame enu)
    : config_(std::move(config)), trajectory_(&trajectory), world_(world), enu_(enu), random_(config_.seed) {
  if (!config_.sky_blockage) return;
  // Evenly spread azimuths, elevations between the mask and 85 deg (a separate stream, so the
  // noise draws do not depend on whether sky blockage is on).
  std::mt19937_64 sky_random(config_.seed ^ 0x5A7E111735ULL);
  std::uniform_real_distribution<double> elevation(config_.elevation_mask, 85.0 * std::numbers::pi / 180.0);
  for (int i = 0; i < config_.constellation; ++i) {
    const double azimuth = 2.0 * std::numbers::pi * (i + 0.5) / config_.constellation;
    const double e = elevation(sky_random);
    satellites_.emplace_back(std::cos(e) * std::sin(azimuth), std::cos(e) * std::cos(azimuth), std::sin(e));  // ENU, azimuth from north
  }
  sky_episode_.type = GnssEpisodeType::kDegraded;
  sky_episode_.fix_type = msgs::GnssFixType::kFix3d;
  sky_episode_.multipath_magnitude = 10.0;
  sky_episode_.multipath_duration = 2.0;
}

int GnssSimulator::visible_satellites(Timestamp time) const {
  if (!config_.sky_blockage) return config_.constellation;
  const WorldSnapshot snapshot = world_->at(time);
  const Eigen::Vector3d antenna = true_antenna_position(time);
  int visible = 0;
  for (const Eigen::Vector3d& direction : satellites_) visible += snapshot.cast(antenna, direction, kSkyRayLength) ? 0 : 1;
  return visible;
}

const GnssEpisode* GnssSimulator::episode_at(Timestamp time) {
  for (const GnssEpisode& episode : config_.episodes) {
    if (time >= episode.start && time <= episode.end) return &episode;
  }
  if (!config_.sky_blockage) return nullptr;
  const int visible = visible_satellites(time);
  const int total = config_.constellation;
  if (visible >= (total + 1) / 2) return nullptr;
  sky_episode_.type = visible < 4 ? GnssEpisodeType::kOutage : GnssEpisodeType::kDegraded;
  sky_episode_.noise_scale = std::sqrt(static_cast<double>(total) / std::max(visible, 1));
  sky_episode_.multipath_rate_hz = 0.3 * static_cast<double>(total - visible) / total;
  sky_episode_.satellites = static_cast<uint32_t>(visible);
  return &sky_episode_;
}

Eigen::Vector3d GnssSimulator::true_antenna_position(Timestamp time) const {
  return trajectory_->sample(time).T_world_body * config_.T_body_gnss.translation();
}

msgs::GnssMessage GnssSimulator::measure(Timestamp time) {
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  // The error process runs through outages too, so it stays stationary and reproducible.
  const double dt = previous_time_ ? (time - *previous_time_).seconds() : 0.0;
  const double a = previous_time_ && config_.correlation_time > 0.0 ? std::exp(-dt / config_.correlation_time) : 0.0;
  for (int axis = 0; axis < 3; ++axis) error_[axis] = a * error_[axis] + std::sqrt(1.0 - a * a) * normal(random_);
  previous_time_ = time;

  const GnssEpisode* episode = episode_at(time);
  if (episode != nullptr && episode->type == GnssEpisodeType::kOutage) {
    msgs::GnssMessage no_fix = last_fix_.value_or(msgs::GnssMessage{});
    if (!last_fix_) {
      const GeodeticPoint truth = enu_.to_geodetic(true_antenna_position(time));
      no_fix.latitude = truth.latitude_deg;
      no_fix.longitude = truth.longitude_deg;
      no_fix.altitude = truth.altitude_m;
    }
    no_fix.timestamp = time;
    no_fix.fix_type = msgs::GnssFixType::kNoFix;
    no_fix.position_covariance.reset();
    no_fix.satellites_used = 0;
    no_fix.hdop = kNoFixHdop;
    return no_fix;
  }

  const bool degraded = episode != nullptr;
  const msgs::GnssFixType fix_type = degraded ? episode->fix_type : config_.fix_type;
  const double scale = degraded ? episode->noise_scale : 1.0;
  const Eigen::Vector2d sigma = config_.noise.value_or(default_gnss_noise(fix_type)) * scale;
  const Eigen::Vector3d sigma_enu(sigma.x(), sigma.x(), sigma.y());

  if (degraded && time >= multipath_until_ && uniform(random_) < 1.0 - std::exp(-episode->multipath_rate_hz * dt)) {
    const double direction = 2.0 * std::numbers::pi * uniform(random_);
    multipath_offset_ = episode->multipath_magnitude * Eigen::Vector3d(std::cos(direction), std::sin(direction), 0.0);
    multipath_until_ = time + Duration::from_seconds(episode->multipath_duration);
  }
  const bool multipath = degraded && time < multipath_until_;

  const Eigen::Vector3d measured = true_antenna_position(time) + sigma_enu.cwiseProduct(error_) +
                                   (multipath ? multipath_offset_ : Eigen::Vector3d::Zero());
  const GeodeticPoint geodetic = enu_.to_geodetic(measured);
  msgs::GnssMessage fix;
  fix.timestamp = time;
  fix.latitude = geodetic.latitude_deg;
  fix.longitude = geodetic.longitude_deg;
  fix.altitude = geodetic.altitude_m;
  fix.fix_type = fix_type;
  fix.position_covariance = sigma_enu.cwiseProduct(sigma_enu).asDiagonal();
  fix.satellites_used = degraded ? episode->satellites : config_.satellites;
  fix.hdop = kNominalHdop * static_cast<float>(scale);
  last_fix_ = fix;
  return fix;
}

}  // namespace hanzo::fusion::sim
