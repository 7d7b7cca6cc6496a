#include "hanzo/fusion/sim/city_generator.hpp"

#include <random>

namespace hanzo::fusion::sim {
namespace {

constexpr double kSidewalk = 3.0;       // metres between kerb and facade
constexpr double kParkingSpot = 8.0;    // metres
constexpr double kCarLength = 4.5, kCarWidth = 1.8, kCarHeight = 1.5;

Material facade(std::mt19937& random) {
  std::uniform_real_distribution<float> tone(0.25F, 0.85F);
  Material material;
  material.texture.type = random() % 3 == 0 ? TextureType::kPoster : TextureType::kNoise;
  material.texture.color_a = Eigen::Vector3f(tone(random), tone(random), tone(random));
  material.texture.color_b = material.texture.color_a * 0.4F;
  material.texture.scale = material.texture.type == TextureType::kPoster ? 1.5 : 0.8;
  material.texture.seed = static_cast<uint32_t>(random());
  material.reflectivity = 0.4;
  material.radar_cross_section = 20.0;
  return material;
}

}  // namespace

void add_city(const CityConfig& config, WorldDescription* world) {
  std::mt19937 random(config.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double pitch = config.block_size + config.street_width;
  const double ground = world->ground_height;
  for (int i = 0; i < config.blocks_x; ++i) {
    for (int j = 0; j < config.blocks_y; ++j) {
      // The block between the kerbs, and the buildings set back by the sidewalk.
      const Eigen::Vector2d low = config.origin + Eigen::Vector2d(i, j) * pitch + Eigen::Vector2d::Constant(config.street_width / 2.0);
      const Eigen::Vector2d high = low + Eigen::Vector2d::Constant(config.block_size);
      const int columns = 2 + static_cast<int>(random() % 2), rows = 2 + static_cast<int>(random() % 2);
      const Eigen::Vector2d lot = (high - low - Eigen::Vector2d::Constant(2.0 * kSidewalk)).cwiseQuotient(Eigen::Vector2d(columns, rows));
      for (int c = 0; c < columns; ++c) {
        for (int r = 0; r < rows; ++r) {
          const double height = config.building_height.x() + unit(random) * (config.building_height.y() - config.building_height.x());
          const Eigen::Vector2d center = low + Eigen::Vector2d::Constant(kSidewalk) + lot.cwiseProduct(Eigen::Vector2d(c + 0.5, r + 0.5));
          Box building;
          building.center = {center.x(), center.y(), ground + height / 2.0};
          building.half_size = {lot.x() * (0.42 + 0.08 * unit(random)), lot.y() * (0.42 + 0.08 * unit(random)), height / 2.0};
          building.material = facade(random);
          building.class_name = "building";
          world->boxes.push_back(building);
        }
      }
      // Poles (lamps) and trees along the four kerbs, cars parked beside them.
      const Eigen::Vector2d corners[4] = {low, {high.x(), low.y()}, high, {low.x(), high.y()}};
      for (int side = 0; side < 4; ++side) {
        const Eigen::Vector2d from = corners[side], to = corners[(side + 1) % 4];
        const Eigen::Vector2d along = (to - from).normalized();
        const Eigen::Vector2d outward(along.y(), -along.x());  // corners run counter-clockwise
        const double length = (to - from).norm();
        for (double s = config.pole_spacing / 2.0; config.pole_spacing > 0.0 && s < length; s += config.pole_spacing) {
          const Eigen::Vector2d base = from + along * s - outward * 0.5;
          Cylinder pole;
          const bool tree = random() % 2 == 0;
          pole.base_center = {base.x(), base.y(), ground};
          pole.radius = tree ? 0.25 : 0.12;
          pole.height = tree ? 5.0 : 7.0;
          pole.material.texture.type = TextureType::kNoise;
          pole.material.texture.color_a = tree ? Eigen::Vector3f(0.35F, 0.25F, 0.15F) : Eigen::Vector3f(0.5F, 0.5F, 0.55F);
          pole.material.texture.color_b = pole.material.texture.color_a * 0.5F;
          pole.material.texture.scale = 0.2;
          pole.material.reflectivity = tree ? 0.3 : 0.7;
          pole.material.radar_cross_section = tree ? 5.0 : 10.0;
          pole.class_name = "pole";
          world->cylinders.push_back(pole);
        }
        for (double s = kParkingSpot; s + kParkingSpot < length; s += kParkingSpot) {
          if (unit(random) >= config.parked_car_probability) continue;
          const Eigen::Vector2d center = from + along * s + outward * (kCarWidth / 2.0 + 0.3);
          Box car;
          car.center = {center.x(), center.y(), ground + kCarHeight / 2.0};
          car.half_size = {kCarLength / 2.0, kCarWidth / 2.0, kCarHeight / 2.0};
          car.yaw = std::atan2(along.y(), along.x());
          car.material.texture.type = TextureType::kUniform;
          car.material.texture.color_a = Eigen::Vector3f(static_cast<float>(unit(random)), static_cast<float>(unit(random)),
                                                         static_cast<float>(unit(random)));
          car.material.reflectivity = 0.6;
          car.material.radar_cross_section = 15.0;
          car.class_name = "car";
          world->boxes.push_back(car);
        }
      }
    }
  }
}

}  // namespace hanzo::fusion::sim
