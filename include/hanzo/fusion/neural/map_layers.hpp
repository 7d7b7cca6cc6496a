#pragma once
// The neural layers of a FusionMap (msgs/map_messages.hpp): Gaussian splats (GaussianCloud's
// arrays, exactly) and a neural radiance field (its model file's bytes, exactly), each with how
// it was trained (NeuralProvenance).

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/neural/gaussian_cloud.hpp"
#include "hanzo/fusion/neural/nerf_field.hpp"

namespace hanzo::fusion::neural {

msgs::GaussianSplatLayer to_splat_layer(const GaussianCloud& cloud, msgs::NeuralProvenance provenance);
/// Fails, naming the array, when the sizes disagree with the count and degree or a value is not finite.
Result<GaussianCloud> from_splat_layer(const msgs::GaussianSplatLayer& layer);

msgs::NeuralFieldLayer to_neural_field_layer(const NerfField& field, msgs::NeuralProvenance provenance);
/// Fails for an encoding other than "hznerf1" or a model that does not parse (parse_nerf).
Result<NerfField> from_neural_field_layer(const msgs::NeuralFieldLayer& layer);

}  // namespace hanzo::fusion::neural
