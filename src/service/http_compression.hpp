#pragma once
// Compression of REST responses at fast levels. cpp-httplib (Debian's build) compresses every
// text or JSON body itself when the client accepts br or gzip, with brotli's slowest level
// (quality 11): a 4.8 MB trajectory page took 9.9 s, far more than sending it plain. The REST
// server compresses large bodies here instead, at the fastest levels (brotli quality 1: 170 MB/s
// for a 3.4x smaller page, about as fast as the bytes it saves go over a 1 Gbit/s link, a gain on
// anything slower; gzip level 1 for clients without br) and hands them to httplib as a sized
// content provider, which httplib sends as it is. Internal to the service module.

#include <string>
#include <string_view>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::service::detail {

enum class ContentEncoding { kIdentity, kGzip, kBrotli };

/// The encoding for a request's Accept-Encoding value: br when accepted (q > 0), else gzip, else
/// identity. Tokens are case-insensitive; "*" accepts br.
ContentEncoding negotiate_encoding(std::string_view accept_encoding);

/// "br", "gzip" or "identity".
std::string_view to_string(ContentEncoding encoding);

/// `body` compressed (kIdentity returns it unchanged). Fails only when the compressor does.
Result<std::string> compress(std::string_view body, ContentEncoding encoding);

}  // namespace hanzo::fusion::service::detail
