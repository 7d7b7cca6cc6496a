#include "hanzo/fusion/maps/scan_visibility.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

namespace hanzo::fusion::maps {
namespace {

constexpr double kRadiansPerDegree = std::numbers::pi / 180.0;
// Rise over run below which two returns lie on a floor (about 27 degrees).
constexpr double kMaxFloorSlope = 0.5;

double elevation_of(const Eigen::Vector3f& point, double range) { return std::asin(std::clamp(point.z() / range, -1.0, 1.0)); }

}  // namespace

Status VisibilityConfig::validate() const {
  for (const auto& [value, name] : {std::pair{azimuth_resolution_deg, "azimuth_resolution_deg"}, std::pair{elevation_resolution_deg, "elevation_resolution_deg"}}) {
    if (!(value > 0.0 && value <= 10.0)) return Error{fmt::format("visibility.{}: must lie in (0, 10] degrees, got {}", name, value), name};
  }
  if (!(bracket_deg >= elevation_resolution_deg && bracket_deg <= 30.0)) {
    return Error{fmt::format("visibility.bracket_deg: must lie in [elevation_resolution_deg, 30] degrees, got {}", bracket_deg), "bracket_deg"};
  }
  if (!(std::isfinite(min_range) && min_range >= 0.0)) return Error{fmt::format("visibility.min_range: must be >= 0 m, got {}", min_range), "min_range"};
  if (!(std::isfinite(max_range) && max_range > min_range)) {
    return Error{fmt::format("visibility.max_range: must be a number of metres above min_range, got {}", max_range), "max_range"};
  }
  if (!(std::isfinite(margin) && margin > 0.0)) return Error{fmt::format("visibility.margin: must be > 0 m, got {}", margin), "margin"};
  if (!(std::isfinite(surface_margin) && surface_margin > 0.0)) {
    return Error{fmt::format("visibility.surface_margin: must be > 0 m, got {}", surface_margin), "surface_margin"};
  }
  for (const auto& [value, name] : {std::pair{margin_per_metre, "margin_per_metre"}, std::pair{surface_margin_per_metre, "surface_margin_per_metre"}}) {
    if (!(std::isfinite(value) && value >= 0.0 && value < 1.0)) return Error{fmt::format("visibility.{}: must lie in [0, 1), got {}", name, value), name};
  }
  return ok_status();
}

RangeImage::RangeImage(const VisibilityConfig& config, std::span<const Eigen::Vector3f> returns_in_sensor_frame, const Eigen::Vector3d& up_in_sensor_frame)
    : config_(config), up_(up_in_sensor_frame.normalized()) {
  azimuth_bins_per_radian_ = 1.0 / (config.azimuth_resolution_deg * kRadiansPerDegree);
  elevation_bins_per_radian_ = 1.0 / (config.elevation_resolution_deg * kRadiansPerDegree);
  columns_ = static_cast<int>(std::ceil(2.0 * std::numbers::pi * azimuth_bins_per_radian_));
  bracket_rows_ = static_cast<int>(std::ceil(config.bracket_deg / config.elevation_resolution_deg));
  double lowest = std::numbers::pi, highest = -std::numbers::pi;
  for (const Eigen::Vector3f& point : returns_in_sensor_frame) {
    const double range = point.cast<double>().norm();
    if (!(range >= config.min_range) || !std::isfinite(range)) continue;
    const double elevation = elevation_of(point, range);
    lowest = std::min(lowest, elevation);
    highest = std::max(highest, elevation);
  }
  if (lowest > highest) return;  // no return: every point kUnknown
  lowest_elevation_ = lowest;
  rows_ = static_cast<int>(std::floor((highest - lowest) * elevation_bins_per_radian_)) + 1;
  pixels_.assign(static_cast<std::size_t>(columns_) * static_cast<std::size_t>(rows_), Pixel{});
  for (const Eigen::Vector3f& point : returns_in_sensor_frame) {
    const double range = point.cast<double>().norm();
    if (!(range >= config.min_range) || !std::isfinite(range)) continue;
    const int column = std::clamp(static_cast<int>((std::atan2(point.y(), point.x()) + std::numbers::pi) * azimuth_bins_per_radian_), 0, columns_ - 1);
    const double elevation = elevation_of(point, range);
    const int row = std::clamp(static_cast<int>((elevation - lowest_elevation_) * elevation_bins_per_radian_), 0, rows_ - 1);
    Pixel& pixel = pixels_[static_cast<std::size_t>(column) * static_cast<std::size_t>(rows_) + static_cast<std::size_t>(row)];
    if (pixel.range == 0.0F || range < pixel.range) pixel = {point, static_cast<float>(range), static_cast<float>(elevation)};
  }
}

Visibility RangeImage::classify(const Eigen::Vector3f& point_in_sensor_frame) const {
  const double squared = point_in_sensor_frame.cast<double>().squaredNorm();
  if (rows_ == 0 || !(squared <= config_.max_range * config_.max_range) || squared < config_.min_range * config_.min_range) return Visibility::kUnknown;
  const double range = std::sqrt(squared);
  const double elevation = elevation_of(point_in_sensor_frame, range);
  const int row = static_cast<int>(std::floor((elevation - lowest_elevation_) * elevation_bins_per_radian_));
  if (row < -bracket_rows_ || row >= rows_ + bracket_rows_) return Visibility::kUnknown;
  const int column = static_cast<int>((std::atan2(point_in_sensor_frame.y(), point_in_sensor_frame.x()) + std::numbers::pi) * azimuth_bins_per_radian_);
  const double margin = config_.margin + config_.margin_per_metre * range;
  bool occluded = false;
  // The returns below and above the point nearest its elevation (below: with its column and row).
  struct Nearest {
    const Pixel* pixel = nullptr;
    int row = 0;
  };
  Nearest below, above;
  // Scans rows [from, to) by step for the first return; true when it sees the point.
  const auto look = [&](const Pixel* pixels, int from, int to, int step, Nearest& nearest) {
    for (int r = from; r != to; r += step) {
      if (r < 0 || r >= rows_ || pixels[r].range == 0.0F) continue;
      const Pixel& pixel = pixels[r];
      if (std::abs(pixel.range - range) <= margin) return true;
      occluded = occluded || pixel.range < range - margin;
      if (nearest.pixel == nullptr || std::abs(pixel.elevation - elevation) < std::abs(nearest.pixel->elevation - elevation)) nearest = {&pixel, r};
      return false;
    }
    return false;
  };
  for (int offset = -1; offset <= 1; ++offset) {
    const int wrapped = ((column + offset) % columns_ + columns_) % columns_;
    const Pixel* pixels = pixels_.data() + static_cast<std::size_t>(wrapped) * static_cast<std::size_t>(rows_);
    Nearest level;  // a return of the point's own row may lie a little above or below it
    if (look(pixels, row, row + 1, 1, level)) return Visibility::kSeen;
    if (look(pixels, row - 1, row - bracket_rows_ - 1, -1, below)) return Visibility::kSeen;
    if (look(pixels, row + 1, row + bracket_rows_ + 1, 1, above)) return Visibility::kSeen;
  }
  if (occluded) return Visibility::kOccluded;
  if (below.pixel == nullptr || above.pixel == nullptr) return Visibility::kUnknown;
  // Every ray passed the point by more than the margin. Its place was empty only if the surface
  // the rays met lies farther than s from it (header: horizontal surface behind, other surface).
  const double surface_margin = config_.surface_margin + config_.surface_margin_per_metre * range;
  const Eigen::Vector3d point = point_in_sensor_frame.cast<double>();
  const Eigen::Vector3d low = below.pixel->point.cast<double>();
  // The next return below `below` (another beam: at least one row lower), in the point's
  // three columns, down to twice the bracket.
  const Pixel* lower = nullptr;
  for (int offset = -1; offset <= 1; ++offset) {
    const int wrapped = ((column + offset) % columns_ + columns_) % columns_;
    const Pixel* pixels = pixels_.data() + static_cast<std::size_t>(wrapped) * static_cast<std::size_t>(rows_);
    for (int r = std::min(below.row - 1, rows_ - 1); r >= std::max(0, below.row - 2 * bracket_rows_); --r) {
      if (pixels[r].range == 0.0F) continue;
      if (lower == nullptr || pixels[r].elevation > lower->elevation) lower = &pixels[r];
      break;
    }
  }
  if (lower != nullptr) {
    const Eigen::Vector3d step = low - lower->point.cast<double>();
    const double rise = step.dot(up_);
    if (std::abs(rise) < kMaxFloorSlope * (step - rise * up_).norm()) return point.dot(up_) - low.dot(up_) > surface_margin ? Visibility::kSeenThrough : Visibility::kUnknown;
  }
  const auto in_plane = [](double r, double e) { return Eigen::Vector2d(r * std::cos(e), r * std::sin(e)); };
  const Eigen::Vector2d point_in_plane = in_plane(range, elevation);
  const Eigen::Vector2d low_in_plane = in_plane(below.pixel->range, below.pixel->elevation);
  const Eigen::Vector2d along = in_plane(above.pixel->range, above.pixel->elevation) - low_in_plane;
  const Eigen::Vector2d offset = point_in_plane - low_in_plane;
  const double length = along.norm();
  const double distance = length > 1e-6 ? std::abs(along.x() * offset.y() - along.y() * offset.x()) / length : offset.norm();
  return distance > surface_margin ? Visibility::kSeenThrough : Visibility::kUnknown;
}

}  // namespace hanzo::fusion::maps
