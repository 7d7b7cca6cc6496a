#pragma once
// One layer through the FusionMap checks of msgs/map_validation.hpp (which work on whole maps):
// what a layer handed to a grid, a volume or an export must pass.

#include <type_traits>

#include "hanzo/fusion/msgs/map_convert.hpp"
#include "hanzo/fusion/msgs/map_validation.hpp"

namespace hanzo::fusion::maps {

template <typename Layer>
Status validate_layer(const Layer& layer) {
  msgs::FusionMap wrapper;
  wrapper.map_id = "layer";
  if constexpr (std::is_same_v<Layer, msgs::OccupancyGridLayer>) {
    wrapper.occupancy = layer;
    wrapper.occupancy->classes.clear();  // indices into the whole map's label table, not checked here
  } else {
    static_assert(std::is_same_v<Layer, msgs::TsdfLayer>);
    wrapper.tsdf = layer;
  }
  return msgs::validate(msgs::to_proto(wrapper));
}

}  // namespace hanzo::fusion::maps
