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

// floor() of a texture coordinate as an integer: exact for |value| < 2^62, and inlined, where
// std::floor is a library call on baseline x86-64 (a third of a camera frame's time).
int64_t floor_to_integer(double value) {
  const auto truncated = static_cast<int64_t>(value);
  return truncated - static_cast<int64_t>(value < static_cast<double>(truncated));
}

// Value noise: random values on the integer lattice, blended with a smoothstep. cell (optional)
// keeps the corners of the last cell this octave sampled.
float value_noise(double u, double v, uint32_t seed, TextureSampleCache::Cell* cell) {
  const int64_t x = floor_to_integer(u), y = floor_to_integer(v);
  TextureSampleCache::Cell computed;
  if (cell == nullptr || !cell->valid || cell->x != x || cell->y != y || cell->seed != seed) {
    computed = {true, x, y, seed, {unit_hash(x, y, seed), unit_hash(x + 1, y, seed), unit_hash(x, y + 1, seed), unit_hash(x + 1, y + 1, seed)}};
    if (cell != nullptr) *cell = computed;
  }
  const std::array<float, 4>& corners = cell != nullptr ? cell->corners : computed.corners;
  const auto su = static_cast<float>(u - static_cast<double>(x)), sv = static_cast<float>(v - static_cast<double>(y));
  const float wu = su * su * (3.0F - 2.0F * su), wv = sv * sv * (3.0F - 2.0F * sv);
  const float bottom = corners[0] + wu * (corners[1] - corners[0]);
  const float top = corners[2] + wu * (corners[3] - corners[2]);
  return bottom + wv * (top - bottom);
}

}  // namespace

std::string_view to_string(TextureType type) { return enum_name(kTextureNames, type); }
std::optional<TextureType> texture_type_from_string(std::string_view name) { return enum_from_name(kTextureNames, name); }

Eigen::Vector3f Texture::color(double u, double v, TextureSampleCache* cache) const {
  const double x = u / scale, y = v / scale;
  switch (type) {
    case TextureType::kUniform: return color_a;
    case TextureType::kChecker: {
      const auto parity = (floor_to_integer(x) + floor_to_integer(y)) & 1;
      return parity == 0 ? color_a : color_b;
    }
    case TextureType::kNoise: {
      auto octave = [cache](int index) { return cache != nullptr ? &cache->octaves_[index] : nullptr; };
      const float n = 0.5714F * value_noise(x, y, seed, octave(0)) + 0.2857F * value_noise(2.0 * x, 2.0 * y, seed + 1, octave(1)) +
                      0.1429F * value_noise(4.0 * x, 4.0 * y, seed + 2, octave(2));
      return color_a + n * (color_b - color_a);
    }
    case TextureType::kPoster: {
      const int64_t cx = floor_to_integer(x), cy = floor_to_integer(y);
      const double lx = x - static_cast<double>(cx), ly = y - static_cast<double>(cy);
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
