#include "mcap_compression.hpp"

#include <lz4frame.h>
#include <zstd.h>

#include <fmt/format.h>

namespace hanzo::fusion::io::mcap {

const char* compression_name(Compression compression) {
  switch (compression) {
    case Compression::kNone: return "";
    case Compression::kLz4: return "lz4";
    case Compression::kZstd: return "zstd";
  }
  return "?";
}

Result<Compression> compression_from_name(std::string_view name) {
  if (name.empty() || name == "none") return Compression::kNone;
  if (name == "lz4") return Compression::kLz4;
  if (name == "zstd") return Compression::kZstd;
  return Error(fmt::format("unknown compression '{}' (expected none, lz4 or zstd)", name));
}

Result<std::string> compress(Compression compression, int level, std::string_view input) {
  std::string output;
  if (compression == Compression::kNone) return std::string(input);
  if (compression == Compression::kZstd) {
    output.resize(ZSTD_compressBound(input.size()));
    const std::size_t n = ZSTD_compress(output.data(), output.size(), input.data(), input.size(), level);
    if (ZSTD_isError(n)) return Error(fmt::format("zstd compression failed: {}", ZSTD_getErrorName(n)));
    output.resize(n);
    return output;
  }
  LZ4F_preferences_t preferences = LZ4F_INIT_PREFERENCES;
  preferences.compressionLevel = level;
  preferences.frameInfo.contentSize = input.size();
  output.resize(LZ4F_compressFrameBound(input.size(), &preferences));
  const std::size_t n = LZ4F_compressFrame(output.data(), output.size(), input.data(), input.size(), &preferences);
  if (LZ4F_isError(n)) return Error(fmt::format("lz4 compression failed: {}", LZ4F_getErrorName(n)));
  output.resize(n);
  return output;
}

Result<std::string> decompress(std::string_view compression, std::string_view input, uint64_t uncompressed_size) {
  if (compression.empty()) {
    if (input.size() != uncompressed_size) {
      return Error(fmt::format("uncompressed chunk holds {} bytes, its header says {}", input.size(), uncompressed_size));
    }
    return std::string(input);
  }
  // The declared size comes from the file: check it before allocating it.
  if (uncompressed_size > kMaxChunkBytes) {
    return Error(fmt::format("chunk declares {} bytes uncompressed, more than the {} a chunk may hold", uncompressed_size, kMaxChunkBytes));
  }
  if (compression == "zstd") {
    const unsigned long long frame_size = ZSTD_getFrameContentSize(input.data(), input.size());
    if (frame_size == ZSTD_CONTENTSIZE_ERROR) return Error("zstd decompression failed: not a zstd frame");
    if (frame_size != ZSTD_CONTENTSIZE_UNKNOWN && frame_size != uncompressed_size) {
      return Error(fmt::format("zstd chunk holds {} bytes, its header says {}", frame_size, uncompressed_size));
    }
  } else if (compression == "lz4" && uncompressed_size > input.size() * 256 + (1u << 16)) {  // LZ4's ratio is at most ~255
    return Error(fmt::format("lz4 chunk of {} bytes cannot hold the {} its header says", input.size(), uncompressed_size));
  }
  std::string output;
  output.resize(uncompressed_size);
  if (compression == "zstd") {
    const std::size_t n = ZSTD_decompress(output.data(), output.size(), input.data(), input.size());
    if (ZSTD_isError(n)) return Error(fmt::format("zstd decompression failed: {}", ZSTD_getErrorName(n)));
    if (n != uncompressed_size) {
      return Error(fmt::format("zstd chunk decompressed to {} bytes, its header says {}", n, uncompressed_size));
    }
    return output;
  }
  if (compression == "lz4") {
    LZ4F_dctx* context = nullptr;
    if (LZ4F_isError(LZ4F_createDecompressionContext(&context, LZ4F_VERSION))) return Error("lz4: cannot create a context");
    std::size_t written = 0;
    std::size_t consumed = 0;
    std::size_t status = 1;
    while (status != 0 && consumed < input.size()) {
      std::size_t out_size = output.size() - written;
      std::size_t in_size = input.size() - consumed;
      status = LZ4F_decompress(context, output.data() + written, &out_size, input.data() + consumed, &in_size, nullptr);
      if (LZ4F_isError(status)) {
        LZ4F_freeDecompressionContext(context);
        return Error(fmt::format("lz4 decompression failed: {}", LZ4F_getErrorName(status)));
      }
      written += out_size;
      consumed += in_size;
      if (out_size == 0 && in_size == 0) break;  // no progress: output full or input exhausted
    }
    LZ4F_freeDecompressionContext(context);
    if (status != 0 || written != uncompressed_size) {
      return Error(fmt::format("lz4 chunk decompressed to {} bytes (frame {}), its header says {}", written,
                               status == 0 ? "complete" : "incomplete", uncompressed_size));
    }
    return output;
  }
  return Error(fmt::format("unsupported chunk compression '{}'", compression));
}

}  // namespace hanzo::fusion::io::mcap
