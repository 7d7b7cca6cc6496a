#pragma once
// Procedural surface textures of the simulated world. A texture is a function of a surface's
// 2D coordinates (u, v) in metres (see World: ground = world x, y; box faces = the face's two
// in-plane axes; cylinders = arc length, height), so patterns keep their physical size on any
// surface. Colours are linear RGB in [0, 1].
//
//   uniform  color_a everywhere
//   checker  squares of side `scale` alternating color_a / color_b, a corner at (0, 0): exact
//            corners for sub-pixel tests
//   noise    smooth value noise (3 octaves, feature size `scale`) blending color_a..color_b:
//            texture everywhere for direct visual odometry
//   poster   tiles of side `scale`, each a random colour with a random inner rectangle: many
//            strong corners, as posters and shelf labels give a feature tracker
//
// Deterministic: the same (type, colours, scale, seed) gives the same pattern everywhere.

#include <array>
#include <cstdint>
#include <optional>
#include <string_view>

#include <Eigen/Core>

namespace hanzo::fusion::sim {

enum class TextureType { kUniform, kChecker, kNoise, kPoster };
std::string_view to_string(TextureType type);  // "uniform", "checker", "noise", "poster"
std::optional<TextureType> texture_type_from_string(std::string_view name);

/// The lattice corners of the noise cells sampled last (one per octave), so that neighbouring
/// samples (the pixels along an image row) skip recomputing them. Optional: colours are the
/// same with or without one. One per thread.
class TextureSampleCache {
 public:
  struct Cell {  // one octave's last lattice cell
    bool valid = false;
    int64_t x = 0, y = 0;
    uint32_t seed = 0;
    std::array<float, 4> corners{};  // values at (x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1)
  };

 private:
  friend struct Texture;
  std::array<Cell, 3> octaves_;
};

struct Texture {
  TextureType type = TextureType::kUniform;
  Eigen::Vector3f color_a{0.6F, 0.6F, 0.6F};
  Eigen::Vector3f color_b{0.15F, 0.15F, 0.15F};
  double scale = 0.5;  ///< metres: checker square, noise feature, poster tile; > 0
  uint32_t seed = 0;   ///< pattern of noise and poster textures

  Eigen::Vector3f color(double u, double v, TextureSampleCache* cache = nullptr) const;
};

/// Rec. 709 luminance of a linear RGB colour.
inline float luminance(const Eigen::Vector3f& rgb) { return 0.2126F * rgb.x() + 0.7152F * rgb.y() + 0.0722F * rgb.z(); }

}  // namespace hanzo::fusion::sim
