#pragma once
// The FusionMap file (".fmap"): the canonical, binary map container of the spec. Its content
// is one hanzo.fusion.v1.FusionMap protobuf message, cut into chunks that are compressed and
// checksummed one by one, so that large layers stream: a reader can decode the metadata from
// the first chunk alone, and a writer never needs more than one chunk of compressed output in
// flight.
//
// Layout (integers little-endian):
//
//   magic        8 bytes  "HZFMAP\r\n"  (catches text-mode transfers, like PNG's signature)
//   format       u32      FusionMap format_version (kFusionMapFormatVersion)
//   reserved     u32      0
//   chunk*       u8 kind = 1, u8 compression (0 none, 1 zstd), u16 reserved 0,
//                u32 crc32 of the stored bytes, u64 uncompressed size, u64 stored size,
//                stored bytes
//   end          u8 kind = 2, u8 0, u16 0, u32 chunk count, u64 total uncompressed bytes
//
// Each chunk's uncompressed bytes are a serialized FusionMap holding a piece of the map: the
// first the metadata (ids, versions, frame, datum, sensor configuration, provenance), the
// others consecutive slices of one layer's arrays (points, occupancy cells, TSDF blocks, mesh
// vertices or triangles) with that layer's scalars. Protobuf's merge rule (repeated fields
// append, sub-messages merge) makes the concatenation of the chunks exactly the whole map.
//
// Readers reject, naming what is wrong: a missing magic, a format_version this build does not
// know (the spec: "readers MUST reject maps with an unrecognized version"), a checksum
// mismatch, a chunk larger than kMaxChunkBytes, a truncated file (no end record, or counts
// that disagree), trailing bytes, and any map that fails msgs::validate().

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

/// Largest uncompressed chunk a reader accepts (a writer's chunks are far smaller).
inline constexpr uint64_t kMaxChunkBytes = uint64_t{256} << 20;

struct FusionMapFileConfig {
  /// Target uncompressed bytes per layer chunk.
  std::size_t chunk_bytes = std::size_t{4} << 20;
  /// zstd level (1 fast .. 19 small); 0 stores chunks uncompressed.
  int compression_level = 3;
};

/// The file's bytes for `map` (which must pass msgs::validate; the error names the field).
Result<std::string> serialize_fusion_map(const msgs::FusionMap& map, const FusionMapFileConfig& config = {});
/// Decodes a whole file. `source_name` prefixes errors.
Result<msgs::FusionMap> parse_fusion_map(std::string_view bytes, const std::string& source_name = "FusionMap");
/// The metadata of a file (its first chunk: no layers), without decoding the layers.
Result<msgs::FusionMap> parse_fusion_map_metadata(std::string_view bytes, const std::string& source_name = "FusionMap");

/// How many leading bytes of a file parse_fusion_map_metadata needs (header and first chunk),
/// read from its first 40 bytes (fewer: an error). At most kMaxChunkBytes + 40.
Result<uint64_t> fusion_map_metadata_bytes(std::string_view first_bytes);
/// Writes atomically (temporary file, fsync, rename): readers see the old file or the new one.
Status write_fusion_map(const std::string& path, const msgs::FusionMap& map, const FusionMapFileConfig& config = {});
Result<msgs::FusionMap> read_fusion_map(const std::string& path);
/// Reads only the header and the first chunk.
Result<msgs::FusionMap> read_fusion_map_metadata(const std::string& path);

}  // namespace hanzo::fusion::maps
