#pragma once
// Geodesy: WGS84 geodetic coordinates <-> ECEF <-> a local East-North-Up (ENU) frame around a
// datum, the world frame of hanzo-fusion when GNSS is used (spec, Coordinate Conventions).
// Implemented with GeographicLib's exact WGS84 ellipsoid conversions.

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion {

/// A WGS84 position. Latitude in [-90, 90] degrees, longitude in [-180, 180] degrees,
/// altitude in meters above the WGS84 ellipsoid (not above mean sea level).
struct GeodeticPoint {
  double latitude_deg = 0.0;
  double longitude_deg = 0.0;
  double altitude_m = 0.0;
};

/// Rejects non-finite values, latitude outside +-90 and longitude outside +-180; the error
/// names the field and value. Altitudes outside [-12 km, 1000 km] are rejected as impossible
/// for a receiver near the Earth.
Status validate(const GeodeticPoint& point);

/// ECEF (Earth-centred, Earth-fixed) coordinates in meters of a geodetic point.
Eigen::Vector3d geodetic_to_ecef(const GeodeticPoint& point);
GeodeticPoint ecef_to_geodetic(const Eigen::Vector3d& ecef);

/// A local tangent-plane frame: x east, y north, z up, origin at the datum.
class EnuFrame {
 public:
  /// Fails when the datum is not a valid geodetic point.
  static Result<EnuFrame> create(const GeodeticPoint& datum);

  const GeodeticPoint& datum() const { return datum_; }
  /// Rotation taking ENU coordinates into ECEF axes.
  const Eigen::Matrix3d& rotation_ecef_enu() const { return rotation_ecef_enu_; }

  Eigen::Vector3d to_enu(const GeodeticPoint& point) const;
  GeodeticPoint to_geodetic(const Eigen::Vector3d& enu) const;
  Eigen::Vector3d ecef_to_enu(const Eigen::Vector3d& ecef) const;
  Eigen::Vector3d enu_to_ecef(const Eigen::Vector3d& enu) const;

 private:
  EnuFrame() = default;
  GeodeticPoint datum_;
  Eigen::Vector3d origin_ecef_ = Eigen::Vector3d::Zero();
  Eigen::Matrix3d rotation_ecef_enu_ = Eigen::Matrix3d::Identity();
};

}  // namespace hanzo::fusion
