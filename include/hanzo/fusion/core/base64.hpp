#pragma once
// Base64 (RFC 4648 section 4: '+', '/', '=' padding), for binary data inside JSON (images sent
// to POST /v1/calibrate).

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion {

/// Padded base64 of `bytes`, no line breaks.
std::string base64_encode(std::span<const uint8_t> bytes);

/// The bytes of padded base64 text. Line breaks and spaces are skipped (MIME-wrapped input).
/// Fails, naming the offset, on a character outside the alphabet, padding anywhere but at the
/// end, or a length (without the skipped characters) that is not a multiple of 4.
Result<std::vector<uint8_t>> base64_decode(std::string_view text);

}  // namespace hanzo::fusion
