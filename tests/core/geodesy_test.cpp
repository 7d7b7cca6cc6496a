#include "hanzo/fusion/core/geodesy.hpp"

#include <cmath>

#include <gtest/gtest.h>

namespace hanzo::fusion {
namespace {

// Datum: Zurich main station, for no other reason than being a real place.
const GeodeticPoint kDatum{47.378177, 8.540192, 408.0};

TEST(Geodesy, DatumIsTheOrigin) {
  const EnuFrame frame = EnuFrame::create(kDatum).value();
  EXPECT_LT(frame.to_enu(kDatum).norm(), 1e-6);
  const GeodeticPoint back = frame.to_geodetic(Eigen::Vector3d::Zero());
  EXPECT_NEAR(back.latitude_deg, kDatum.latitude_deg, 1e-11);
  EXPECT_NEAR(back.longitude_deg, kDatum.longitude_deg, 1e-11);
  EXPECT_NEAR(back.altitude_m, kDatum.altitude_m, 1e-6);
}

TEST(Geodesy, PointOneKilometreNorthOfTheDatum) {
  // 1000 m north along the meridian: dlat = 1000 / (M + h) with M the meridional radius of
  // curvature of WGS84, taken at the middle of the arc (M changes ~10 m over 1 km here).
  const double a = 6378137.0;
  const double f = 1.0 / 298.257223563;
  const double e2 = f * (2.0 - f);
  const auto meridional_radius = [&](double lat_deg) {
    const double s = std::sin(lat_deg * M_PI / 180.0);
    const double w = 1.0 - e2 * s * s;
    return a * (1.0 - e2) / (w * std::sqrt(w)) + kDatum.altitude_m;
  };
  double dlat_deg = 1000.0 / meridional_radius(kDatum.latitude_deg) * 180.0 / M_PI;
  dlat_deg = 1000.0 / meridional_radius(kDatum.latitude_deg + 0.5 * dlat_deg) * 180.0 / M_PI;
  const double radius = meridional_radius(kDatum.latitude_deg + 0.5 * dlat_deg);

  const EnuFrame frame = EnuFrame::create(kDatum).value();
  const Eigen::Vector3d enu = frame.to_enu({kDatum.latitude_deg + dlat_deg, kDatum.longitude_deg, kDatum.altitude_m});
  EXPECT_NEAR(enu.x(), 0.0, 1e-3);
  EXPECT_NEAR(enu.y(), 1000.0, 1e-3);  // R sin(d / R) = 1000 - 4 um
  // The ellipsoid curves away below the tangent plane by d^2 / (2 R) ~ 7.9 cm.
  EXPECT_NEAR(enu.z(), -1000.0 * 1000.0 / (2.0 * radius), 1e-3);
}

TEST(Geodesy, AltitudeChangeIsStraightUp) {
  const EnuFrame frame = EnuFrame::create(kDatum).value();
  const Eigen::Vector3d enu = frame.to_enu({kDatum.latitude_deg, kDatum.longitude_deg, kDatum.altitude_m + 123.456});
  EXPECT_NEAR(enu.x(), 0.0, 1e-3);
  EXPECT_NEAR(enu.y(), 0.0, 1e-3);
  EXPECT_NEAR(enu.z(), 123.456, 1e-3);
}

TEST(Geodesy, EquatorPrimeMeridianEcefIsTheSemiMajorAxis) {
  const Eigen::Vector3d ecef = geodetic_to_ecef({0.0, 0.0, 0.0});
  EXPECT_NEAR(ecef.x(), 6378137.0, 1e-3);
  EXPECT_NEAR(ecef.y(), 0.0, 1e-3);
  EXPECT_NEAR(ecef.z(), 0.0, 1e-3);
  const GeodeticPoint pole = ecef_to_geodetic({0.0, 0.0, 6356752.314245});
  EXPECT_NEAR(pole.latitude_deg, 90.0, 1e-9);
  EXPECT_NEAR(pole.altitude_m, 0.0, 1e-3);
}

TEST(Geodesy, EnuToWgs84ToEnuRoundTrip) {
  const EnuFrame frame = EnuFrame::create(kDatum).value();
  for (const Eigen::Vector3d& enu : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1000, 0, 0), Eigen::Vector3d(-2500.5, 7300.25, 12.0),
                                     Eigen::Vector3d(50'000, -80'000, -300), Eigen::Vector3d(0.001, 0.002, 0.003)}) {
    const Eigen::Vector3d back = frame.to_enu(frame.to_geodetic(enu));
    EXPECT_LT((back - enu).norm(), 1e-3) << enu.transpose();
  }
}

TEST(Geodesy, RejectsImpossibleCoordinates) {
  EXPECT_FALSE(EnuFrame::create({91.0, 0.0, 0.0}).ok());
  EXPECT_FALSE(EnuFrame::create({0.0, 181.0, 0.0}).ok());
  EXPECT_FALSE(EnuFrame::create({NAN, 0.0, 0.0}).ok());
  const Status status = validate(GeodeticPoint{-90.5, 10.0, 0.0});
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().field, "latitude_deg");
  EXPECT_NE(status.error().message.find("-90.5"), std::string::npos);
  EXPECT_TRUE(validate(GeodeticPoint{-90.0, 180.0, -100.0}).ok());
}

}  // namespace
}  // namespace hanzo::fusion
