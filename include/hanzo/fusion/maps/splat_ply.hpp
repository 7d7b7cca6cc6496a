#pragma once
// A FusionMap's Gaussian splats as the PLY that 3D Gaussian splatting viewers read (the reference
// implementation's layout): binary little-endian, one vertex per Gaussian with float properties
//   x y z nx ny nz f_dc_0 f_dc_1 f_dc_2 f_rest_0 .. f_rest_{3 (K-1) - 1} opacity
//   scale_0 scale_1 scale_2 rot_0 rot_1 rot_2 rot_3
// where K = (degree + 1)^2, f_rest is channel-major (all of red's higher coefficients, then
// green's, then blue's), opacity is the logit, scale the log of the standard deviations and rot
// the quaternion (w, x, y, z); the normals are zero.
//
// decode_splat_ply() takes that layout back (any property order, the degree from the f_rest
// count); it refuses another format, a missing property, a truncated body and non-finite values,
// each error starting with `source`.

#include <string>
#include <string_view>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

/// Fails, naming the array, when the layer's sizes disagree with its count and degree or a value is not finite.
Status validate_splats(const msgs::GaussianSplatLayer& layer);
/// The layer as PLY bytes (the provenance is not part of the format). The layer must validate.
std::string encode_splat_ply(const msgs::GaussianSplatLayer& layer);
Result<msgs::GaussianSplatLayer> decode_splat_ply(std::string_view bytes, const std::string& source);

}  // namespace hanzo::fusion::maps
