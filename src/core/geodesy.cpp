#include "hanzo/fusion/core/geodesy.hpp"

#include <cmath>
#include <numbers>

#include <GeographicLib/Geocentric.hpp>
#include <fmt/format.h>

namespace hanzo::fusion {
namespace {

const GeographicLib::Geocentric& wgs84() { return GeographicLib::Geocentric::WGS84(); }

Status field_error(const char* field, double value, const char* expected) {
  return Error{fmt::format("GeodeticPoint.{}: {} is {}", field, value, expected), field};
}

}  // namespace

Status validate(const GeodeticPoint& point) {
  if (!std::isfinite(point.latitude_deg)) return field_error("latitude_deg", point.latitude_deg, "not finite");
  if (!std::isfinite(point.longitude_deg)) return field_error("longitude_deg", point.longitude_deg, "not finite");
  if (!std::isfinite(point.altitude_m)) return field_error("altitude_m", point.altitude_m, "not finite");
  if (std::abs(point.latitude_deg) > 90.0) return field_error("latitude_deg", point.latitude_deg, "outside [-90, 90] degrees");
  if (std::abs(point.longitude_deg) > 180.0) return field_error("longitude_deg", point.longitude_deg, "outside [-180, 180] degrees");
  if (point.altitude_m < -12'000.0 || point.altitude_m > 1'000'000.0) {
    return field_error("altitude_m", point.altitude_m, "outside [-12000, 1000000] m above the ellipsoid");
  }
  return ok_status();
}

Eigen::Vector3d geodetic_to_ecef(const GeodeticPoint& point) {
  Eigen::Vector3d ecef;
  wgs84().Forward(point.latitude_deg, point.longitude_deg, point.altitude_m, ecef.x(), ecef.y(), ecef.z());
  return ecef;
}

GeodeticPoint ecef_to_geodetic(const Eigen::Vector3d& ecef) {
  GeodeticPoint point;
  wgs84().Reverse(ecef.x(), ecef.y(), ecef.z(), point.latitude_deg, point.longitude_deg, point.altitude_m);
  return point;
}

Result<EnuFrame> EnuFrame::create(const GeodeticPoint& datum) {
  if (Status status = validate(datum); !status) return status.error();
  EnuFrame frame;
  frame.datum_ = datum;
  frame.origin_ecef_ = geodetic_to_ecef(datum);
  const double lat = datum.latitude_deg * std::numbers::pi / 180.0;
  const double lon = datum.longitude_deg * std::numbers::pi / 180.0;
  const double slat = std::sin(lat), clat = std::cos(lat), slon = std::sin(lon), clon = std::cos(lon);
  // Columns: the east, north and up unit vectors expressed in ECEF.
  frame.rotation_ecef_enu_ << -slon, -slat * clon, clat * clon,
                               clon, -slat * slon, clat * slon,
                               0.0, clat, slat;
  return frame;
}

Eigen::Vector3d EnuFrame::ecef_to_enu(const Eigen::Vector3d& ecef) const {
  return rotation_ecef_enu_.transpose() * (ecef - origin_ecef_);
}

Eigen::Vector3d EnuFrame::enu_to_ecef(const Eigen::Vector3d& enu) const {
  return origin_ecef_ + rotation_ecef_enu_ * enu;
}

Eigen::Vector3d EnuFrame::to_enu(const GeodeticPoint& point) const { return ecef_to_enu(geodetic_to_ecef(point)); }

GeodeticPoint EnuFrame::to_geodetic(const Eigen::Vector3d& enu) const { return ecef_to_geodetic(enu_to_ecef(enu)); }

}  // namespace hanzo::fusion
