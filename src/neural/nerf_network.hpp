#pragma once
// NerfField's parameters and networks (private to the neural module).

#include <span>
#include <vector>

#include "hanzo/fusion/neural/mlp.hpp"
#include "hanzo/fusion/neural/nerf_field.hpp"

namespace hanzo::fusion::neural {

inline constexpr int kDensityOutputs = 16;     // log density + 15 features, all fed to the colour network
inline constexpr int kDirectionFeatures = 16;  // spherical harmonics up to degree 3

struct NerfField::Network {
  NerfFieldConfig config;
  HashGrid encoding;
  Mlp density_network;  // encoding -> width -> 16
  Mlp colour_network;   // 16 + 16 -> width -> width -> 3
  OccupancyGrid occupancy;
  std::vector<float> table, density_weights, colour_weights;

  explicit Network(const NerfFieldConfig& field_config);

  /// The parameter groups: the encoding's table, the density network's, the colour network's.
  std::vector<std::span<float>> parameters();
  std::vector<std::span<const float>> parameters() const;

  /// What forward() keeps for backward() (reused between calls).
  struct Cache {
    std::vector<float> encoded, density_hidden, density_output, colour_input, colour_hidden, colour;
  };
  Cache training_cache;  ///< the trainer's, kept between steps

  /// Density (per unit-cube length) and colour (RGB 0..1) at unit-cube `positions` seen along
  /// unit `directions` (3 floats a sample each).
  void forward(const float* positions, const float* directions, std::size_t count, float* density, float* colour, Cache* cache = nullptr) const;
  /// Gradients of every parameter group (sized like parameters(), accumulated) from dL/ddensity
  /// and dL/dcolour, with forward()'s cache of the same samples.
  void backward(const float* positions, std::size_t count, Cache& cache, const float* density_gradient, const float* colour_gradient,
                std::vector<std::vector<float>>& gradients) const;
  /// Density only (the first network).
  void density(const float* positions, std::size_t count, float* density) const;
};

}  // namespace hanzo::fusion::neural
