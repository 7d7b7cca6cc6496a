// Free-space evidence (maps/scan_visibility.hpp) and the point map's removal of moving objects
// (maps/point_map.hpp) on ray-cast scans of a floor, a wall and a car-sized box.

#include <cmath>
#include <numbers>
#include <optional>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/maps/point_map.hpp"
#include "hanzo/fusion/maps/scan_visibility.hpp"

namespace hanzo::fusion::maps {
namespace {

using ::testing::HasSubstr;

struct Box {
  Eigen::Vector3d low, high;
};

// A level spinning LiDAR at `origin` (world): 64 beams from -25 to +15 degrees, a column every
// 0.35 degrees, hitting the floor z = 0, a wall x = 30 and optionally a box. Returns in the
// sensor frame (axes as the world's).
std::vector<Eigen::Vector3f> cast_scan(const Eigen::Vector3d& origin, std::optional<Box> box) {
  std::vector<Eigen::Vector3f> returns;
  constexpr double kDegree = std::numbers::pi / 180.0;
  for (int beam = 0; beam < 64; ++beam) {
    const double elevation = (-25.0 + 40.0 * beam / 63.0) * kDegree;
    for (int column = 0; column < 1028; ++column) {
      const double azimuth = (-180.0 + 0.35 * column) * kDegree;
      const Eigen::Vector3d direction(std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
      double nearest = 100.0;
      if (direction.z() < 0.0) nearest = std::min(nearest, -origin.z() / direction.z());
      if (direction.x() > 0.0) nearest = std::min(nearest, (30.0 - origin.x()) / direction.x());
      if (box) {  // slab test
        double enter = 0.0, leave = 1e9;
        for (int axis = 0; axis < 3; ++axis) {
          const double inverse = 1.0 / direction(axis);
          double a = (box->low(axis) - origin(axis)) * inverse, b = (box->high(axis) - origin(axis)) * inverse;
          if (a > b) std::swap(a, b);
          enter = std::max(enter, a);
          leave = std::min(leave, b);
        }
        if (enter <= leave && enter > 0.0) nearest = std::min(nearest, enter);
      }
      if (nearest < 100.0) returns.push_back((nearest * direction).cast<float>());
    }
  }
  return returns;
}

TEST(ScanVisibility, SeenSeenThroughOccludedOrUnknown) {
  const VisibilityConfig config;
  ASSERT_TRUE(config.validate());
  const Eigen::Vector3d origin(0.0, 0.0, 1.8);
  const RangeImage image(config, cast_scan(origin, std::nullopt));
  const auto classify = [&](double x, double y, double z) { return image.classify((Eigen::Vector3d(x, y, z) - origin).cast<float>()); };
  EXPECT_EQ(classify(30.0, 2.0, 3.0), Visibility::kSeen);          // on the wall
  EXPECT_EQ(classify(35.0, 2.0, 3.0), Visibility::kOccluded);      // behind it
  EXPECT_EQ(classify(12.0, 1.0, 1.0), Visibility::kSeenThrough);   // floating in the empty street
  EXPECT_EQ(classify(12.0, 1.0, 8.0), Visibility::kUnknown);       // above the highest beam
  EXPECT_EQ(classify(-20.0, 1.0, 1.0), Visibility::kSeenThrough);  // behind the sensor: every azimuth
  EXPECT_EQ(classify(0.5, 0.0, 1.8), Visibility::kUnknown);        // nearer than min_range
  EXPECT_EQ(classify(-90.0, 0.0, 1.0), Visibility::kUnknown);      // past max_range
  // Floor points, also lifted by a pose error, at grazing angles: never seen through.
  for (const double x : {-40.0, -20.0, 5.0, 10.0, 20.0, 28.0}) {
    for (const double lift : {0.0, 0.05, 0.08}) EXPECT_NE(classify(x, 0.3, lift), Visibility::kSeenThrough) << x << " m, lifted " << lift;
  }
}

TEST(ScanVisibility, ConfigErrorsNameTheField) {
  VisibilityConfig config;
  config.bracket_deg = 0.1;
  EXPECT_THAT(config.validate().error().message, HasSubstr("bracket_deg"));
  config = {};
  config.max_range = 0.5;
  EXPECT_THAT(config.validate().error().message, HasSubstr("max_range"));
  PointMapConfig map_config;
  map_config.moving_points.min_seen_through = 0;
  EXPECT_THAT(map_config.validate().error().message, HasSubstr("min_seen_through"));
}

// A car parked in the first keyframe drives off: the later keyframes see the wall and the floor
// through its place. Its points leave the merged map; the floor and wall stay.
TEST(ScanVisibility, APointMapLeavesOutTheCarThatDroveOff) {
  const Box car{{10.0, -1.0, 0.0}, {14.5, 1.0, 1.5}};
  // Above the floor where the car stood (its lowest surface_margin is never seen through).
  const auto in_car = [&](const Eigen::Vector3f& point, float above) {
    return point.x() > 9.9F && point.x() < 14.6F && std::abs(point.y()) < 1.1F && point.z() > above && point.z() < 1.6F;
  };
  const auto map_of = [&](bool remove_moving_points, std::size_t* removed) {
    PointMapConfig config;
    config.moving_points.enabled = remove_moving_points;
    PointMap map = PointMap::create(config).value();
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector3d origin(-8.0 + 1.0 * k, 0.5, 1.8);
      cloud::PointCloud scan;
      scan.positions = cast_scan(origin, k == 0 ? std::optional<Box>(car) : std::nullopt);
      EXPECT_TRUE(map.add_keyframe(static_cast<uint64_t>(k), SE3(SO3::identity(), origin), scan));
    }
    *removed = map.moving_points_removed();
    return map.cloud();
  };
  std::size_t removed_kept = 0, removed = 0;
  const cloud::PointCloud kept = map_of(false, &removed_kept);
  const cloud::PointCloud cleaned = map_of(true, &removed);
  const auto count_car = [&](const cloud::PointCloud& cloud, float above) {
    return std::count_if(cloud.positions.begin(), cloud.positions.end(), [&](const Eigen::Vector3f& point) { return in_car(point, above); });
  };
  EXPECT_GT(count_car(kept, 0.25F), 100);
  EXPECT_EQ(count_car(cleaned, 0.25F), 0);
  EXPECT_EQ(removed_kept, 0u);
  EXPECT_GT(removed, 100u);
  // Everything but the car stays.
  EXPECT_EQ(cleaned.size() - static_cast<std::size_t>(count_car(cleaned, 0.05F)), kept.size() - static_cast<std::size_t>(count_car(kept, 0.05F)));
}

}  // namespace
}  // namespace hanzo::fusion::maps
