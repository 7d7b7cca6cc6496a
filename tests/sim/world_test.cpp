// The simulated world: ray casts against analytic distances for every primitive, the BVH
// against a brute-force cast, moving boxes, and the procedural textures.

#include <array>
#include <cmath>
#include <random>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "hanzo/fusion/sim/world.hpp"

namespace hanzo::fusion::sim {
namespace {

const Timestamp kStart = Timestamp::from_nanoseconds(1'700'000'000'000'000'000);

WorldDescription empty_world() {
  WorldDescription description;
  description.has_ground = false;
  return description;
}

TEST(World, GroundPlaneDistanceAndSurfaceCoordinates) {
  WorldDescription description;
  description.ground_height = -1.0;
  const World world(description);
  const Eigen::Vector3d direction = Eigen::Vector3d(1.0, 0.0, -1.0).normalized();
  const auto hit = world.cast({2.0, 3.0, 1.0}, direction, 100.0, kStart);
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->distance, 2.0 * std::sqrt(2.0), 1e-12);
  EXPECT_EQ(hit->object_id, -1);
  EXPECT_NEAR(hit->surface_uv.x(), 4.0, 1e-12);
  EXPECT_NEAR(hit->surface_uv.y(), 3.0, 1e-12);
  EXPECT_FALSE(world.cast({0.0, 0.0, 1.0}, Eigen::Vector3d::UnitZ(), 100.0, kStart));  // looking up: sky
  EXPECT_FALSE(world.cast({0.0, 0.0, 1.0}, direction, 2.0, kStart));                   // beyond max distance
}

TEST(World, RotatedBoxFacesAndNormals) {
  WorldDescription description = empty_world();
  Box box;
  box.center = {10.0, 0.0, 1.0};
  box.half_size = {1.0, 2.0, 1.0};
  box.yaw = M_PI / 4.0;
  description.boxes.push_back(box);
  const World world(description);
  // Along the x axis the ray meets the rotated box's -x face or -y face at a 45 degree angle:
  // its corner (-1, -2) in box coordinates sits at (10 + (-1 + 2)/sqrt2, (-1 - 2)/sqrt2).
  const auto hit = world.cast({0.0, 0.0, 1.0}, Eigen::Vector3d::UnitX(), 100.0, kStart);
  ASSERT_TRUE(hit);
  // The -x face is the line through the box centre offset by -1 along the box x axis
  // (cos45, sin45): points p with (p - c) . (cos45, sin45) = -1 -> x = 10 - sqrt2 at y = 0.
  EXPECT_NEAR(hit->distance, 10.0 - std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(hit->normal.x(), -std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(hit->normal.y(), -std::sqrt(0.5), 1e-12);
  EXPECT_EQ(hit->object_id, 0);
  // From above: the top face at z = 2, surface coordinates measured from the lower corner.
  const auto top = world.cast({10.0, 0.0, 5.0}, -Eigen::Vector3d::UnitZ(), 100.0, kStart);
  ASSERT_TRUE(top);
  EXPECT_NEAR(top->distance, 3.0, 1e-12);
  EXPECT_NEAR(top->surface_uv.x(), 1.0, 1e-12);
  EXPECT_NEAR(top->surface_uv.y(), 2.0, 1e-12);
  // A ray starting inside the box does not see it.
  EXPECT_FALSE(world.cast({10.0, 0.0, 1.0}, Eigen::Vector3d::UnitX(), 100.0, kStart));
}

TEST(World, CylinderSideAndTop) {
  WorldDescription description = empty_world();
  Cylinder pole;
  pole.base_center = {5.0, 0.0, 0.0};
  pole.radius = 0.5;
  pole.height = 3.0;
  description.cylinders.push_back(pole);
  const World world(description);
  const auto side = world.cast({0.0, 0.0, 1.0}, Eigen::Vector3d::UnitX(), 100.0, kStart);
  ASSERT_TRUE(side);
  EXPECT_NEAR(side->distance, 4.5, 1e-12);
  EXPECT_NEAR(side->normal.x(), -1.0, 1e-12);
  EXPECT_NEAR(side->surface_uv.y(), 1.0, 1e-12);
  EXPECT_FALSE(world.cast({0.0, 0.0, 3.5}, Eigen::Vector3d::UnitX(), 100.0, kStart));  // above it
  const auto top = world.cast({5.2, 0.0, 10.0}, -Eigen::Vector3d::UnitZ(), 100.0, kStart);
  ASSERT_TRUE(top);
  EXPECT_NEAR(top->distance, 7.0, 1e-12);
  EXPECT_NEAR(top->normal.z(), 1.0, 1e-12);
  // Tangent ray at an offset: hits at x = 5 - sqrt(0.25 - 0.16).
  const auto offset = world.cast({0.0, 0.4, 1.0}, Eigen::Vector3d::UnitX(), 100.0, kStart);
  ASSERT_TRUE(offset);
  EXPECT_NEAR(offset->distance, 5.0 - std::sqrt(0.09), 1e-12);
}

// `count` random rotated boxes and thin cylinders within +-extent metres of the origin (drawn in
// this order from `random`), over the default ground.
WorldDescription random_objects(std::mt19937_64& random, int count, double extent, double radius_scale) {
  std::uniform_real_distribution<double> uniform(-extent, extent), size(0.2, 3.0), angle(-M_PI, M_PI);
  WorldDescription description;
  for (int i = 0; i < count; ++i) {
    Box box;
    box.center = {uniform(random), uniform(random), size(random)};
    box.half_size = {size(random), size(random), size(random)};
    box.yaw = angle(random);
    description.boxes.push_back(box);
    Cylinder cylinder;
    cylinder.base_center = {uniform(random), uniform(random), 0.0};
    cylinder.radius = radius_scale * size(random);
    cylinder.height = 2.0 * size(random);
    description.cylinders.push_back(cylinder);
  }
  return description;
}

TEST(World, BoundingVolumeHierarchyMatchesBruteForce) {
  std::mt19937_64 random(7);
  std::uniform_real_distribution<double> uniform(-50.0, 50.0);
  const WorldDescription description = random_objects(random, 300, 50.0, 0.1);
  const World world(description);
  std::vector<World> singles;
  for (const Box& box : description.boxes) {
    WorldDescription one = empty_world();
    one.boxes.push_back(box);
    singles.emplace_back(one);
  }
  for (const Cylinder& cylinder : description.cylinders) {
    WorldDescription one = empty_world();
    one.cylinders.push_back(cylinder);
    singles.emplace_back(one);
  }
  WorldDescription ground_only;
  singles.emplace_back(ground_only);
  int hits = 0;
  for (int ray = 0; ray < 2000; ++ray) {
    const Eigen::Vector3d origin(uniform(random), uniform(random), 1.0 + 0.02 * uniform(random));
    const Eigen::Vector3d direction = Eigen::Vector3d(uniform(random), uniform(random), 0.2 * uniform(random)).normalized();
    double nearest = 80.0;
    for (const World& single : singles) {
      if (const auto hit = single.cast(origin, direction, nearest, kStart)) nearest = hit->distance;
    }
    const auto hit = world.cast(origin, direction, 80.0, kStart);
    if (nearest < 80.0) {
      ASSERT_TRUE(hit) << ray;
      EXPECT_NEAR(hit->distance, nearest, 1e-9) << ray;
      ++hits;
    } else {
      EXPECT_FALSE(hit) << ray;
    }
  }
  EXPECT_GT(hits, 1000);
}

// Rays cast through a RayGroup (a camera tile's pyramid) hit exactly what plain casts hit:
// static boxes and cylinders, moving boxes and the ground, from origins among the objects.
TEST(World, RayGroupCastsEqualPlainCasts) {
  std::mt19937_64 random(11);
  std::uniform_real_distribution<double> uniform(-40.0, 40.0), angle(-M_PI, M_PI), unit(-1.0, 1.0);
  WorldDescription description = random_objects(random, 200, 40.0, 0.2);
  for (int i = 0; i < 20; ++i) {
    MovingBox person;
    person.box.half_size = {0.3, 0.3, 0.9};
    person.path = {{uniform(random), uniform(random)}, {uniform(random), uniform(random)}};
    person.start_time = kStart;
    description.moving_boxes.push_back(person);
  }
  const World world(description);
  const WorldSnapshot snapshot = world.at(kStart + Duration::from_seconds(3.0));
  RayGroup group;
  int hits = 0, compared = 0;
  for (int cone = 0; cone < 300; ++cone) {
    // A random camera pose and a random tile: directions with x / z, y / z in a small box.
    const Eigen::Vector3d origin(uniform(random), uniform(random), 0.5 + 0.05 * (uniform(random) + 40.0));
    const Eigen::Matrix3d rotation = (Eigen::AngleAxisd(angle(random), Eigen::Vector3d::UnitZ()) *
                                      Eigen::AngleAxisd(0.5 * angle(random), Eigen::Vector3d::UnitX()))
                                         .toRotationMatrix();
    const double x_min = unit(random), y_min = unit(random), width = 0.05, height = 0.08;
    const std::array<Eigen::Vector3d, 5> inward = {rotation * Eigen::Vector3d(-1.0, 0.0, x_min + width), rotation * Eigen::Vector3d(1.0, 0.0, -x_min),
                                                   rotation * Eigen::Vector3d(0.0, -1.0, y_min + height), rotation * Eigen::Vector3d(0.0, 1.0, -y_min),
                                                   rotation * Eigen::Vector3d::UnitZ()};
    snapshot.group(origin, inward, 60.0, &group);
    EXPECT_LT(group.size(), description.boxes.size() + description.cylinders.size());  // culled
    int hint = -1;
    for (int ray = 0; ray < 30; ++ray) {
      const double fx = x_min + width * (ray % 6) / 5.0, fy = y_min + height * (ray / 6) / 4.0;  // corners included
      const Eigen::Vector3d direction = rotation * Eigen::Vector3d(fx, fy, 1.0).normalized();
      const auto plain = snapshot.cast(origin, direction, 60.0);
      const auto grouped = snapshot.cast(group, direction, &hint);
      ASSERT_EQ(plain.has_value(), grouped.has_value()) << cone << " " << ray;
      ++compared;
      if (!plain) continue;
      ++hits;
      EXPECT_EQ(plain->object_id, grouped->object_id) << cone << " " << ray;
      EXPECT_EQ(plain->distance, grouped->distance);
      EXPECT_EQ(plain->normal, grouped->normal);
      EXPECT_EQ(plain->surface_uv, grouped->surface_uv);
      EXPECT_EQ(plain->object_velocity, grouped->object_velocity);
    }
  }
  EXPECT_GT(hits, compared / 4);
}

TEST(World, MovingBoxWalksItsPathBackAndForth) {
  WorldDescription description = empty_world();
  MovingBox person;
  person.box.half_size = {0.25, 0.25, 0.9};
  person.path = {{0.0, 5.0}, {10.0, 5.0}};
  person.speed = 2.0;
  person.start_time = kStart + Duration::from_seconds(1.0);
  description.moving_boxes.push_back(person);
  const World world(description);
  // Before it starts, it stands at path[0]; after 3 s of walking it is at x = 6; after 7 s it
  // has turned back at x = 10 and is at x = 6 again, walking -x.
  EXPECT_NEAR(person.center_at(kStart, 0.0).x(), 0.0, 1e-12);
  EXPECT_NEAR(person.center_at(kStart + Duration::from_seconds(4.0), 0.0).x(), 6.0, 1e-9);
  EXPECT_NEAR(person.center_at(kStart + Duration::from_seconds(8.0), 0.0).x(), 6.0, 1e-9);
  EXPECT_NEAR(person.velocity_at(kStart + Duration::from_seconds(8.0)).x(), -2.0, 1e-12);
  EXPECT_NEAR(person.center_at(kStart, 0.0).z(), 0.9, 1e-12);
  const auto hit = world.cast({6.0, 0.0, 1.0}, Eigen::Vector3d::UnitY(), 100.0, kStart + Duration::from_seconds(4.0));
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->distance, 4.75, 1e-9);
  EXPECT_NEAR(hit->object_velocity.x(), 2.0, 1e-12);
  EXPECT_FALSE(world.cast({6.0, 0.0, 1.0}, Eigen::Vector3d::UnitY(), 100.0, kStart));
}

TEST(Texture, CheckerCornersAndDeterministicPatterns) {
  Texture checker;
  checker.type = TextureType::kChecker;
  checker.scale = 0.25;
  EXPECT_EQ(checker.color(0.1, 0.1), checker.color_a);
  EXPECT_EQ(checker.color(0.3, 0.1), checker.color_b);
  EXPECT_EQ(checker.color(-0.1, 0.1), checker.color_b);
  EXPECT_EQ(checker.color(0.3, 0.3), checker.color_a);
  for (TextureType type : {TextureType::kNoise, TextureType::kPoster}) {
    Texture texture;
    texture.type = type;
    texture.seed = 9;
    float minimum = 1.0F, maximum = 0.0F;
    TextureSampleCache cache;
    for (int i = 0; i < 400; ++i) {
      const double u = 0.037 * i, v = 0.011 * i;
      const Eigen::Vector3f color = texture.color(u, v);
      EXPECT_EQ(color, texture.color(u, v));
      EXPECT_EQ(color, texture.color(u, v, &cache));  // the cache changes the speed only
      EXPECT_TRUE((color.array() >= 0.0F).all() && (color.array() <= 1.0F).all());
      minimum = std::min(minimum, luminance(color));
      maximum = std::max(maximum, luminance(color));
    }
    EXPECT_GT(maximum - minimum, 0.2F) << to_string(type);  // real contrast, not flat
  }
  EXPECT_EQ(texture_type_from_string("poster"), TextureType::kPoster);
  EXPECT_FALSE(texture_type_from_string("marble"));
}

}  // namespace
}  // namespace hanzo::fusion::sim
