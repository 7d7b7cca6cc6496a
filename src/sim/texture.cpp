#include "hanzo/fusion/sim/texture.hpp"

#include <array>
#include <cmath>

#include "hanzo/fusion/core/enum_names.hpp"

namespace hanzo::fusion::sim {
namespace {

constexpr EnumNames<TextureType, 4> kTextureNames{{
    {TextureType::kUniform, "uniform"}, {TextureType::kChecker, "checker"},
    {TextureType::kNoise, "noise"},     {TextureType::kPoster, "poster"}}};

// A well-mixed 32-bit hash of a lattice cell and a seed (murmur3's finalizer).
uint32_t hash_cell(int64_t x, int64_t y, uint32_t seed) {
  uint32_t h = seed * 0x9E3779B9U ^ static_cast<uint32_t>(x) * 0x85EBCA6BU ^ static_cast<uint32_t>(y) * 0xC2B2AE35U;
  h ^= h >> 16;
  h *= 0x85EBCA6BU;
  h ^= h >> 13;
  h *= 0xC2B2AE35U;
  h ^= h >> 16;
  return h;
}

float unit_hash(int64_t x, int64_t y, uint32_t seed) { return static_cast<float>(hash_cell(x, y, seed) >> 8) * (1.0F / 16777216.0F); }

// Value noise: random values on the integer lattice, blended with a smoothstep.
float value_noise(double u, double v, uint32_t seed) {
  const double fu = std::floor(u), fv = std::floor(v);
  const auto x = static_cast<int64_t>(fu), y = static_cast<int64_t>(fv);
  const auto su = static_cast<float>(u - fu), sv = static_cast<float>(v - fv);
  const float wu = su * su * (3.0F - 2.0F * su), wv = sv * sv * (3.0F - 2.0F * sv);
  const float corner_00 = unit_hash(x, y, seed), corner_10 = unit_hash(x + 1, y, seed);
  const float corner_01 = unit_hash(x, y + 1, seed), corner_11 = unit_hash(x + 1, y + 1, seed);
  const float bottom = corner_00 + wu * (corner_10 - corner_00);
  const float top = corner_01 + wu * (corner_11 - corner_01);
  return bottom + wv * (top - bottom);
}

}  // namespace

std::string_view to_string(TextureType type) { return enum_name(kTextureNames, type); }
std::optional<TextureType> texture_type_from_string(std::string_view name) { return enum_from_name(kTextureNames, name); }

Eigen::Vector3f Texture::color(double u, double v) const {
  const double x = u / scale, y = v / scale;
  switch (type) {
    case TextureType::kUniform: return color_a;
    case TextureType::kChecker: {
      const auto parity = (static_cast<int64_t>(std::floor(x)) + static_cast<int64_t>(std::floor(y))) & 1;
      return parity == 0 ? color_a : color_b;
    }
    case TextureType::kNoise: {
      const float n = 0.5714F * value_noise(x, y, seed) + 0.2857F * value_noise(2.0 * x, 2.0 * y, seed + 1) +
                      0.1429F * value_noise(4.0 * x, 4.0 * y, seed + 2);
      return color_a + n * (color_b - color_a);
    }
    case TextureType::kPoster: {
      const double fx = std::floor(x), fy = std::floor(y);
      const auto cx = static_cast<int64_t>(fx), cy = static_cast<int64_t>(fy);
      const double lx = x - fx, ly = y - fy;
      // The inner rectangle spans [0.15, 0.35 + 0.5 r] of the tile in each direction.
      const double inner_x = 0.35 + 0.5 * unit_hash(cx, cy, seed + 7), inner_y = 0.35 + 0.5 * unit_hash(cx, cy, seed + 11);
      const bool inside = lx > 0.15 && lx < inner_x && ly > 0.15 && ly < inner_y;
      const uint32_t h = hash_cell(cx, cy, seed + (inside ? 3U : 5U));
      const Eigen::Vector3f random_color(static_cast<float>(h & 0xFFU) / 255.0F, static_cast<float>((h >> 8) & 0xFFU) / 255.0F,
                                         static_cast<float>((h >> 16) & 0xFFU) / 255.0F);
      const float t = static_cast<float>((h >> 24) & 0xFFU) / 255.0F;
      return inside ? random_color : color_a + t * (color_b - color_a);
    }
  }
  return color_a;
}

}  // namespace hanzo::fusion::sim
