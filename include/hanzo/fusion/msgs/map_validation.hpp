#pragma once
// Checks for FusionMap and MapUpdate as they arrive on the wire or from a file, before any
// reader interprets them. The C++ map types themselves belong to the maps module; these checks
// are what every reader shares.
//
// Rejected, naming the field: a format_version other than kFusionMapFormatVersion (the spec:
// readers MUST reject maps with an unrecognized version rather than misinterpret them); an
// empty map_id; an invalid datum; non-finite coordinates or values; per-element arrays
// (uncertainties, labels, intensities) that are neither empty nor one per element; occupancy
// probabilities outside [0, 1] or a cell count other than size_x * size_y * size_z;
// non-positive resolutions or voxel sizes; TSDF blocks whose arrays are not block_size^3;
// negative TSDF weights; triangle index lists that are not triples or point past the vertices;
// unknown semantic labels.

#include <cstdint>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/v1/maps.pb.h"

namespace hanzo::fusion::msgs {

/// The FusionMap format_version this build reads and writes.
inline constexpr uint32_t kFusionMapFormatVersion = 1;

Status validate(const v1::FusionMap& map);
Status validate(const v1::MapUpdate& update);

}  // namespace hanzo::fusion::msgs
