#include "http_compression.hpp"

#include <algorithm>
#include <cctype>
#include <cstdlib>

#include <brotli/encode.h>
#include <fmt/format.h>
#include <zlib.h>

namespace hanzo::fusion::service::detail {
namespace {

constexpr int kBrotliQuality = 1;  // 0..11; 11 is brotli's (and httplib's) default; bench_service PageCompression
constexpr int kGzipLevel = 1;      // 1..9

std::string trimmed_lower(std::string_view text) {
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.front()))) text.remove_prefix(1);
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.remove_suffix(1);
  std::string lower(text);
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return lower;
}

Result<std::string> gzip(std::string_view body) {
  z_stream stream{};
  // windowBits 15 + 16: a gzip header and trailer instead of zlib's.
  if (deflateInit2(&stream, kGzipLevel, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) return Error("gzip: cannot start the compressor");
  std::string out(deflateBound(&stream, static_cast<uLong>(body.size())), '\0');
  stream.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(body.data()));
  stream.avail_in = static_cast<uInt>(body.size());
  stream.next_out = reinterpret_cast<Bytef*>(out.data());
  stream.avail_out = static_cast<uInt>(out.size());
  const int status = deflate(&stream, Z_FINISH);
  out.resize(stream.total_out);
  deflateEnd(&stream);
  if (status != Z_STREAM_END) return Error(fmt::format("gzip: compression failed ({})", status));
  return out;
}

Result<std::string> brotli(std::string_view body) {
  std::size_t size = BrotliEncoderMaxCompressedSize(body.size());
  if (size == 0) return Error("brotli: the body is too large");
  std::string out(size, '\0');
  if (BrotliEncoderCompress(kBrotliQuality, BROTLI_DEFAULT_WINDOW, BROTLI_MODE_TEXT, body.size(), reinterpret_cast<const uint8_t*>(body.data()),
                            &size, reinterpret_cast<uint8_t*>(out.data())) != BROTLI_TRUE) {
    return Error("brotli: compression failed");
  }
  out.resize(size);
  return out;
}

}  // namespace

ContentEncoding negotiate_encoding(std::string_view accept_encoding) {
  bool brotli_accepted = false, gzip_accepted = false;
  while (!accept_encoding.empty()) {
    const std::size_t comma = accept_encoding.find(',');
    const std::string_view item = accept_encoding.substr(0, comma);
    accept_encoding = comma == std::string_view::npos ? std::string_view() : accept_encoding.substr(comma + 1);
    const std::size_t semicolon = item.find(';');
    const std::string token = trimmed_lower(item.substr(0, semicolon));
    double quality = 1.0;
    if (semicolon != std::string_view::npos) {
      const std::string parameter = trimmed_lower(item.substr(semicolon + 1));
      if (parameter.rfind("q=", 0) == 0) quality = std::strtod(parameter.c_str() + 2, nullptr);
    }
    if (quality <= 0.0) continue;
    if (token == "br" || token == "*") brotli_accepted = true;
    if (token == "gzip" || token == "x-gzip") gzip_accepted = true;
  }
  if (brotli_accepted) return ContentEncoding::kBrotli;
  if (gzip_accepted) return ContentEncoding::kGzip;
  return ContentEncoding::kIdentity;
}

std::string_view to_string(ContentEncoding encoding) {
  switch (encoding) {
    case ContentEncoding::kBrotli: return "br";
    case ContentEncoding::kGzip: return "gzip";
    case ContentEncoding::kIdentity: break;
  }
  return "identity";
}

Result<std::string> compress(std::string_view body, ContentEncoding encoding) {
  switch (encoding) {
    case ContentEncoding::kBrotli: return brotli(body);
    case ContentEncoding::kGzip: return gzip(body);
    case ContentEncoding::kIdentity: break;
  }
  return std::string(body);
}

}  // namespace hanzo::fusion::service::detail
