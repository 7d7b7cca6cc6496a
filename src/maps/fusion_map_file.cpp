#include "hanzo/fusion/maps/fusion_map_file.hpp"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <vector>

#include <fmt/format.h>
#include <zlib.h>
#include <zstd.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/core/yaml_value.hpp"
#include "hanzo/fusion/msgs/map_convert.hpp"
#include "hanzo/fusion/msgs/map_validation.hpp"

namespace hanzo::fusion::maps {
namespace {

constexpr std::string_view kMagic{"HZFMAP\r\n", 8};
constexpr std::size_t kFileHeaderBytes = 16;
constexpr std::size_t kChunkHeaderBytes = 24;
constexpr std::size_t kEndRecordBytes = 16;
constexpr uint8_t kChunkRecord = 1;
constexpr uint8_t kEndRecord = 2;
constexpr uint8_t kUncompressed = 0;
constexpr uint8_t kZstd = 1;

template <typename T>
void put(std::string& out, T value) {
  char bytes[sizeof(T)];
  for (std::size_t i = 0; i < sizeof(T); ++i) bytes[i] = static_cast<char>((static_cast<uint64_t>(value) >> (8 * i)) & 0xff);
  out.append(bytes, sizeof(T));
}

template <typename T>
T get(std::string_view bytes, std::size_t offset) {
  uint64_t value = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) value |= static_cast<uint64_t>(static_cast<uint8_t>(bytes[offset + i])) << (8 * i);
  return static_cast<T>(value);
}

uint32_t crc32_of(std::string_view bytes) {
  return static_cast<uint32_t>(::crc32(0L, reinterpret_cast<const Bytef*>(bytes.data()), static_cast<uInt>(bytes.size())));
}

// ---- cutting the map into chunks ------------------------------------------------------------

/// Calls `emit(begin, end)` for consecutive slices of [0, count) of about `per_chunk` elements;
/// once with an empty slice when count is 0 (so that an empty layer still appears).
void for_each_slice(int count, std::size_t per_chunk, const std::function<void(int, int)>& emit) {
  const int step = static_cast<int>(std::max<std::size_t>(1, std::min<std::size_t>(per_chunk, 1u << 30)));
  if (count == 0) emit(0, 0);
  for (int begin = 0; begin < count; begin += step) emit(begin, std::min(count, begin + step));
}

template <typename Repeated>
void copy_slice(const Repeated& from, int begin, int end, Repeated* to) {
  if (from.empty()) return;
  for (int i = begin; i < end; ++i) *to->Add() = from.Get(i);
}

/// The map as a list of FusionMap pieces whose merge is the whole map.
std::vector<v1::FusionMap> cut_into_pieces(const v1::FusionMap& map, std::size_t chunk_bytes) {
  std::vector<v1::FusionMap> pieces;
  v1::FusionMap metadata = map;
  metadata.clear_points();
  metadata.clear_occupancy();
  metadata.clear_tsdf();
  metadata.clear_mesh();
  metadata.clear_visual_landmarks();
  metadata.clear_gaussian_splats();
  metadata.clear_neural_field();
  metadata.clear_lidar_keyframes();
  pieces.push_back(std::move(metadata));

  if (map.has_points()) {
    const v1::PointLayer& layer = map.points();
    for_each_slice(layer.points_size(), chunk_bytes / 28, [&](int begin, int end) {
      v1::PointLayer* piece = pieces.emplace_back().mutable_points();
      piece->set_voxel_size(layer.voxel_size());
      copy_slice(layer.points(), begin, end, piece->mutable_points());
      copy_slice(layer.position_std(), begin, end, piece->mutable_position_std());
      copy_slice(layer.labels(), begin, end, piece->mutable_labels());
      copy_slice(layer.intensities(), begin, end, piece->mutable_intensities());
      copy_slice(layer.classes(), begin, end, piece->mutable_classes());
      copy_slice(layer.class_probability(), begin, end, piece->mutable_class_probability());
    });
  }
  if (map.has_occupancy()) {
    const v1::OccupancyGridLayer& layer = map.occupancy();
    for_each_slice(layer.occupancy_size(), chunk_bytes / 5, [&](int begin, int end) {
      v1::OccupancyGridLayer* piece = pieces.emplace_back().mutable_occupancy();
      if (begin == 0) {
        *piece = layer;
        piece->clear_occupancy();
        piece->clear_labels();
        piece->clear_classes();
      }
      copy_slice(layer.occupancy(), begin, end, piece->mutable_occupancy());
      copy_slice(layer.labels(), begin, end, piece->mutable_labels());
      copy_slice(layer.classes(), begin, end, piece->mutable_classes());
    });
  }
  if (map.has_tsdf()) {
    const v1::TsdfLayer& layer = map.tsdf();
    const std::size_t block_bytes = std::max<std::size_t>(1, std::size_t{layer.block_size()} * layer.block_size() * layer.block_size() * 8 + 16);
    for_each_slice(layer.blocks_size(), chunk_bytes / block_bytes, [&](int begin, int end) {
      v1::TsdfLayer* piece = pieces.emplace_back().mutable_tsdf();
      piece->set_voxel_size(layer.voxel_size());
      piece->set_truncation_distance(layer.truncation_distance());
      piece->set_block_size(layer.block_size());
      copy_slice(layer.blocks(), begin, end, piece->mutable_blocks());
    });
  }
  if (map.has_mesh()) {
    const v1::MeshLayer& layer = map.mesh();
    // Vertices first, then triangles: indices refer to the whole vertex list, which the merge
    // rebuilds in order.
    for_each_slice(layer.vertices_size(), chunk_bytes / 20, [&](int begin, int end) {
      v1::MeshLayer* piece = pieces.emplace_back().mutable_mesh();
      copy_slice(layer.vertices(), begin, end, piece->mutable_vertices());
      copy_slice(layer.vertex_labels(), begin, end, piece->mutable_vertex_labels());
    });
    if (layer.triangle_indices_size() > 0) {
      for_each_slice(layer.triangle_indices_size(), (chunk_bytes / 15) * 3, [&](int begin, int end) {
        copy_slice(layer.triangle_indices(), begin, end, pieces.emplace_back().mutable_mesh()->mutable_triangle_indices());
      });
    }
  }
  if (map.has_visual_landmarks()) {
    // Landmarks first, then keyframes (their indices refer to the whole landmark list, which
    // the merge rebuilds in order).
    const v1::VisualLandmarkLayer& layer = map.visual_landmarks();
    v1::VisualLandmarkLayer* head = pieces.emplace_back().mutable_visual_landmarks();
    head->set_camera(layer.camera());
    head->set_descriptor_type(layer.descriptor_type());
    head->set_float_descriptor_size(layer.float_descriptor_size());
    head->set_scale_free(layer.scale_free());
    *head->mutable_sources() = layer.sources();
    const auto floats = static_cast<int>(layer.float_descriptor_size());
    for_each_slice(layer.positions_size(), chunk_bytes / (60 + 4 * static_cast<std::size_t>(floats)), [&](int begin, int end) {
      v1::VisualLandmarkLayer* piece = pieces.emplace_back().mutable_visual_landmarks();
      copy_slice(layer.positions(), begin, end, piece->mutable_positions());
      if (layer.descriptors_size() > 0) copy_slice(layer.descriptors(), 4 * begin, 4 * end, piece->mutable_descriptors());
      copy_slice(layer.float_descriptors(), floats * begin, floats * end, piece->mutable_float_descriptors());
      copy_slice(layer.position_std(), begin, end, piece->mutable_position_std());
      copy_slice(layer.observations(), begin, end, piece->mutable_observations());
    });
    for_each_slice(layer.keyframes_size(), std::max<std::size_t>(1, chunk_bytes / 4096), [&](int begin, int end) {
      copy_slice(layer.keyframes(), begin, end, pieces.emplace_back().mutable_visual_landmarks()->mutable_keyframes());
    });
  }
  if (map.has_gaussian_splats()) {
    const v1::GaussianSplatLayer& layer = map.gaussian_splats();
    v1::GaussianSplatLayer* head = pieces.emplace_back().mutable_gaussian_splats();
    head->set_sh_degree(layer.sh_degree());
    *head->mutable_provenance() = layer.provenance();
    const int sh = layer.opacity_logits_size() > 0 ? layer.sh_size() / layer.opacity_logits_size() : 0;
    for_each_slice(layer.opacity_logits_size(), chunk_bytes / (4 * (11 + static_cast<std::size_t>(sh))), [&](int begin, int end) {
      v1::GaussianSplatLayer* piece = pieces.emplace_back().mutable_gaussian_splats();
      copy_slice(layer.positions(), 3 * begin, 3 * end, piece->mutable_positions());
      copy_slice(layer.log_scales(), 3 * begin, 3 * end, piece->mutable_log_scales());
      copy_slice(layer.rotations(), 4 * begin, 4 * end, piece->mutable_rotations());
      copy_slice(layer.opacity_logits(), begin, end, piece->mutable_opacity_logits());
      copy_slice(layer.sh(), sh * begin, sh * end, piece->mutable_sh());
    });
  }
  if (map.has_neural_field()) {
    // The model's bytes in parts of chunk_bytes (their concatenation is the model).
    const v1::NeuralFieldLayer& layer = map.neural_field();
    v1::NeuralFieldLayer* head = pieces.emplace_back().mutable_neural_field();
    head->set_encoding(layer.encoding());
    *head->mutable_provenance() = layer.provenance();
    const std::size_t part_bytes = std::max<std::size_t>(1, chunk_bytes);
    for (const std::string& part : layer.model_parts()) {
      for (std::size_t begin = 0; begin < part.size(); begin += part_bytes) {
        pieces.emplace_back().mutable_neural_field()->add_model_parts(part.substr(begin, part_bytes));
      }
    }
  }
  if (map.has_lidar_keyframes()) {
    // The sources, then whole keyframes (a keyframe's points stay in one chunk).
    const v1::LidarKeyframeLayer& layer = map.lidar_keyframes();
    *pieces.emplace_back().mutable_lidar_keyframes()->mutable_sources() = layer.sources();
    std::size_t bytes = 0;
    v1::LidarKeyframeLayer* piece = nullptr;
    for (const v1::LidarKeyframe& keyframe : layer.keyframes()) {
      const std::size_t keyframe_bytes = 64 + 15 * static_cast<std::size_t>(keyframe.points_size());
      if (piece == nullptr || bytes + keyframe_bytes > chunk_bytes) {
        piece = pieces.emplace_back().mutable_lidar_keyframes();
        bytes = 0;
      }
      *piece->add_keyframes() = keyframe;
      bytes += keyframe_bytes;
    }
  }
  return pieces;
}

Status append_chunk(std::string& out, const std::string& payload, int compression_level) {
  std::string stored;
  uint8_t compression = kUncompressed;
  if (compression_level > 0 && !payload.empty()) {
    stored.resize(ZSTD_compressBound(payload.size()));
    const std::size_t size = ZSTD_compress(stored.data(), stored.size(), payload.data(), payload.size(), compression_level);
    if (ZSTD_isError(size)) return Error{fmt::format("FusionMap: zstd compression failed ({})", ZSTD_getErrorName(size))};
    stored.resize(size);
    compression = kZstd;
  } else {
    stored = payload;
  }
  put<uint8_t>(out, kChunkRecord);
  put<uint8_t>(out, compression);
  put<uint16_t>(out, 0);
  put<uint32_t>(out, crc32_of(stored));
  put<uint64_t>(out, payload.size());
  put<uint64_t>(out, stored.size());
  out += stored;
  return ok_status();
}

// ---- reading ------------------------------------------------------------------------------

struct ChunkReader {
  std::string_view bytes;
  const std::string& source;
  std::size_t offset = kFileHeaderBytes;
  uint32_t chunks = 0;
  uint64_t uncompressed_total = 0;

  Error error(const std::string& what) const { return Error{fmt::format("{}: {}", source, what)}; }

  Status check_header() const {
    if (bytes.size() < kFileHeaderBytes || bytes.substr(0, kMagic.size()) != kMagic) {
      return error("not a FusionMap file (missing the \"HZFMAP\" signature)");
    }
    const uint32_t version = get<uint32_t>(bytes, 8);
    if (version != msgs::kFusionMapFormatVersion) {
      return Error{fmt::format("{}: unsupported FusionMap format_version {} (this build reads version {})", source, version,
                               msgs::kFusionMapFormatVersion),
                   "format_version"};
    }
    return ok_status();
  }

  /// The next chunk's uncompressed bytes, or an empty optional at the end record.
  Result<std::optional<std::string>> next() {
    if (offset + 8 > bytes.size()) return error("truncated file (no end record)");
    const uint8_t kind = get<uint8_t>(bytes, offset);
    if (kind == kEndRecord) {
      if (offset + kEndRecordBytes > bytes.size()) return error("truncated end record");
      const uint32_t count = get<uint32_t>(bytes, offset + 4);
      const uint64_t total = get<uint64_t>(bytes, offset + 8);
      if (count != chunks || total != uncompressed_total) {
        return error(fmt::format("end record announces {} chunks / {} bytes, the file holds {} / {}", count, total, chunks,
                                 uncompressed_total));
      }
      if (offset + kEndRecordBytes != bytes.size()) {
        return error(fmt::format("{} unexpected bytes after the end record", bytes.size() - offset - kEndRecordBytes));
      }
      return std::optional<std::string>{};
    }
    if (kind != kChunkRecord) return error(fmt::format("unknown record kind {} at byte {}", kind, offset));
    if (offset + kChunkHeaderBytes > bytes.size()) return error("truncated chunk header");
    const uint8_t compression = get<uint8_t>(bytes, offset + 1);
    const uint32_t crc = get<uint32_t>(bytes, offset + 4);
    const uint64_t size = get<uint64_t>(bytes, offset + 8);
    const uint64_t stored_size = get<uint64_t>(bytes, offset + 16);
    const std::size_t data_offset = offset + kChunkHeaderBytes;
    if (size > kMaxChunkBytes) return error(fmt::format("chunk {} announces {} bytes (limit {})", chunks, size, kMaxChunkBytes));
    if (stored_size > bytes.size() - data_offset) return error(fmt::format("truncated chunk {}", chunks));
    const std::string_view stored = bytes.substr(data_offset, stored_size);
    if (crc32_of(stored) != crc) return error(fmt::format("chunk {} is corrupted (checksum mismatch)", chunks));
    std::string payload;
    if (compression == kUncompressed) {
      if (stored_size != size) return error(fmt::format("chunk {}: stored size differs from its size", chunks));
      payload.assign(stored);
    } else if (compression == kZstd) {
      payload.resize(size);
      const std::size_t produced = ZSTD_decompress(payload.data(), payload.size(), stored.data(), stored.size());
      if (ZSTD_isError(produced) || produced != size) {
        return error(fmt::format("chunk {} does not decompress to its announced {} bytes", chunks, size));
      }
    } else {
      return error(fmt::format("chunk {}: unknown compression {}", chunks, compression));
    }
    offset = data_offset + stored_size;
    ++chunks;
    uncompressed_total += size;
    return std::optional<std::string>{std::move(payload)};
  }
};

Result<msgs::FusionMap> decode(std::string_view bytes, const std::string& source_name, bool metadata_only) {
  ChunkReader reader{bytes, source_name};
  HANZO_RETURN_IF_ERROR(reader.check_header());
  v1::FusionMap map;
  while (true) {
    std::optional<std::string> payload;
    HANZO_ASSIGN_OR_RETURN(payload, reader.next());
    if (!payload) break;
    if (!map.MergeFromString(*payload)) {
      return reader.error(fmt::format("chunk {} is not a FusionMap protobuf message", reader.chunks - 1));
    }
    if (metadata_only) break;
  }
  if (reader.chunks == 0) return reader.error("no chunks");
  if (map.format_version() != msgs::kFusionMapFormatVersion) {
    return Error{fmt::format("{}: unsupported FusionMap format_version {} in the map (this build reads version {})",
                             source_name, map.format_version(), msgs::kFusionMapFormatVersion),
                 "format_version"};
  }
  return with_context(msgs::from_proto(map), source_name);
}

}  // namespace

Result<std::string> serialize_fusion_map(const msgs::FusionMap& map, const FusionMapFileConfig& config) {
  const v1::FusionMap proto = msgs::to_proto(map);
  HANZO_RETURN_IF_ERROR(msgs::validate(proto));
  std::string out;
  out.append(kMagic);
  put<uint32_t>(out, msgs::kFusionMapFormatVersion);
  put<uint32_t>(out, 0);
  uint32_t chunks = 0;
  uint64_t total = 0;
  for (const v1::FusionMap& piece : cut_into_pieces(proto, std::max<std::size_t>(config.chunk_bytes, 64))) {
    const std::string payload = piece.SerializeAsString();
    HANZO_RETURN_IF_ERROR(append_chunk(out, payload, config.compression_level));
    ++chunks;
    total += payload.size();
  }
  put<uint8_t>(out, kEndRecord);
  put<uint8_t>(out, 0);
  put<uint16_t>(out, 0);
  put<uint32_t>(out, chunks);
  put<uint64_t>(out, total);
  return out;
}

Result<msgs::FusionMap> parse_fusion_map(std::string_view bytes, const std::string& source_name) {
  return decode(bytes, source_name, false);
}

Result<msgs::FusionMap> parse_fusion_map_metadata(std::string_view bytes, const std::string& source_name) {
  return decode(bytes, source_name, true);
}

Result<uint64_t> fusion_map_metadata_bytes(std::string_view first_bytes) {
  if (first_bytes.size() < kFileHeaderBytes + kChunkHeaderBytes || first_bytes.substr(0, kMagic.size()) != kMagic) {
    return Error("not a FusionMap file, or shorter than its header");
  }
  return kFileHeaderBytes + kChunkHeaderBytes + std::min(get<uint64_t>(first_bytes, kFileHeaderBytes + 16), kMaxChunkBytes);
}

Status write_fusion_map(const std::string& path, const msgs::FusionMap& map, const FusionMapFileConfig& config) {
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, serialize_fusion_map(map, config));
  return yaml::write_file_atomically(path, bytes);
}

Result<msgs::FusionMap> read_fusion_map(const std::string& path) {
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, read_file(path));
  return parse_fusion_map(bytes, path);
}

Result<msgs::FusionMap> read_fusion_map_metadata(const std::string& path) {
  // The header and the first chunk are at the start: read only as much as they need.
  std::ifstream file(path, std::ios::binary);
  if (!file) return Error{fmt::format("{}: cannot open file ({})", path, std::strerror(errno))};
  std::string bytes(kFileHeaderBytes + kChunkHeaderBytes, '\0');
  file.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  bytes.resize(static_cast<std::size_t>(file.gcount()));
  if (bytes.size() == kFileHeaderBytes + kChunkHeaderBytes) {
    // Never more than the file holds, whatever the header announces.
    std::error_code size_error;
    const uint64_t file_size = std::filesystem::file_size(path, size_error);
    const uint64_t stored_size = std::min({get<uint64_t>(bytes, kFileHeaderBytes + 16), kMaxChunkBytes,
                                           size_error ? uint64_t{0} : file_size - std::min<uint64_t>(file_size, bytes.size())});
    const std::size_t header_size = bytes.size();
    bytes.resize(header_size + stored_size);
    file.read(bytes.data() + header_size, static_cast<std::streamsize>(stored_size));
    bytes.resize(header_size + static_cast<std::size_t>(file.gcount()));
  }
  return parse_fusion_map_metadata(bytes, path);
}

}  // namespace hanzo::fusion::maps
