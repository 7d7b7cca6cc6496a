#pragma once
// Lossless conversion of FusionMap and MapUpdate between the C++ structs and the wire.
// from_proto() first runs validate() of msgs/map_validation.hpp (unknown format_version,
// inconsistent layers, ... are rejected with the field named), then converts.

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/v1/maps.pb.h"

namespace hanzo::fusion::msgs {

v1::FusionMap to_proto(const FusionMap& map);
v1::MapUpdate to_proto(const MapUpdate& update);
Result<FusionMap> from_proto(const v1::FusionMap& map);
Result<MapUpdate> from_proto(const v1::MapUpdate& update);

}  // namespace hanzo::fusion::msgs
