#pragma once
// Chunk compression for MCAP: zstd (single frame) and lz4 (LZ4 frame format), as the MCAP
// specification names them.

#include <cstdint>
#include <string>
#include <string_view>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/mcap.hpp"

namespace hanzo::fusion::io::mcap {

Result<std::string> compress(Compression compression, int level, std::string_view input);
/// `compression` as stored in the chunk ("", "lz4", "zstd"); the output must be exactly
/// `uncompressed_size` bytes.
/// The most a chunk may declare uncompressed (1 GiB): a file's header is checked against it (and,
/// for zstd, against the frame's own size) before anything is allocated.
inline constexpr uint64_t kMaxChunkBytes = 1ull << 30;

Result<std::string> decompress(std::string_view compression, std::string_view input, uint64_t uncompressed_size);

}  // namespace hanzo::fusion::io::mcap
