#pragma once
// A procedural city for the urban scenarios: a grid of blocks separated by streets, each
// block filled with buildings of random height and facade, lamp poles and trees along the
// kerbs, and cars parked at the roadside. Deterministic from the seed.
//
// Street centrelines run along x = origin.x + i * pitch (i = 0..blocks_x) and
// y = origin.y + j * pitch (j = 0..blocks_y), pitch = block_size + street_width; block (i, j)
// fills the square between centrelines i, i+1 and j, j+1 minus half a street on each side.
// So a vehicle driving between street intersections, e.g. waypoints (origin + (i, j) * pitch),
// stays on the road.

#include <cstdint>

#include <Eigen/Core>

#include "hanzo/fusion/sim/world.hpp"

namespace hanzo::fusion::sim {

struct CityConfig {
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();  ///< world x, y of the first street crossing
  int blocks_x = 3;
  int blocks_y = 2;
  double block_size = 60.0;                           ///< metres
  double street_width = 16.0;                         ///< metres, kerb to kerb
  Eigen::Vector2d building_height{8.0, 30.0};         ///< metres, min and max
  double pole_spacing = 25.0;                         ///< metres along each kerb; 0: no poles
  double parked_car_probability = 0.3;                ///< per parking spot (every 8 m)
  uint32_t seed = 11;
};

/// Appends the city's buildings, poles, trees and parked cars to world.
void add_city(const CityConfig& config, WorldDescription* world);

}  // namespace hanzo::fusion::sim
