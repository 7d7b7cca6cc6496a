#include "hanzo/fusion/neural/map_layers.hpp"

#include <fmt/format.h>

#include "hanzo/fusion/maps/splat_ply.hpp"

namespace hanzo::fusion::neural {

msgs::GaussianSplatLayer to_splat_layer(const GaussianCloud& cloud, msgs::NeuralProvenance provenance) {
  msgs::GaussianSplatLayer layer;
  layer.sh_degree = static_cast<uint32_t>(cloud.sh_degree);
  layer.positions = cloud.position;
  layer.log_scales = cloud.log_scale;
  layer.rotations = cloud.rotation;
  layer.opacity_logits = cloud.opacity_logit;
  layer.sh = cloud.sh;
  layer.provenance = std::move(provenance);
  return layer;
}

Result<GaussianCloud> from_splat_layer(const msgs::GaussianSplatLayer& layer) {
  HANZO_RETURN_IF_ERROR(maps::validate_splats(layer));
  GaussianCloud cloud;
  cloud.sh_degree = static_cast<int>(layer.sh_degree);
  cloud.position = layer.positions;
  cloud.log_scale = layer.log_scales;
  cloud.rotation = layer.rotations;
  cloud.opacity_logit = layer.opacity_logits;
  cloud.sh = layer.sh;
  return cloud;
}

msgs::NeuralFieldLayer to_neural_field_layer(const NerfField& field, msgs::NeuralProvenance provenance) {
  msgs::NeuralFieldLayer layer;
  layer.encoding = "hznerf1";
  layer.model = serialize_nerf(field);
  layer.provenance = std::move(provenance);
  return layer;
}

Result<NerfField> from_neural_field_layer(const msgs::NeuralFieldLayer& layer) {
  if (layer.encoding != "hznerf1") return Error(fmt::format("neural_field: encoding \"{}\" (this build reads \"hznerf1\")", layer.encoding));
  return parse_nerf(layer.model, "neural_field");
}

}  // namespace hanzo::fusion::neural
