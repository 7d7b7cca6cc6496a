#include "hanzo/fusion/core/base64.hpp"

#include <array>

#include <fmt/format.h>

namespace hanzo::fusion {
namespace {

constexpr std::string_view kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

// 0-63 for alphabet characters, -1 otherwise.
constexpr std::array<int8_t, 256> decoding_table() {
  std::array<int8_t, 256> table{};
  table.fill(-1);
  for (std::size_t i = 0; i < kAlphabet.size(); ++i) table[static_cast<uint8_t>(kAlphabet[i])] = static_cast<int8_t>(i);
  return table;
}

}  // namespace

std::string base64_encode(std::span<const uint8_t> bytes) {
  std::string text;
  text.reserve((bytes.size() + 2) / 3 * 4);
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    const std::size_t left = bytes.size() - i;
    const uint32_t group = (uint32_t{bytes[i]} << 16) | (left > 1 ? uint32_t{bytes[i + 1]} << 8 : 0U) | (left > 2 ? uint32_t{bytes[i + 2]} : 0U);
    text += kAlphabet[(group >> 18) & 63U];
    text += kAlphabet[(group >> 12) & 63U];
    text += left > 1 ? kAlphabet[(group >> 6) & 63U] : '=';
    text += left > 2 ? kAlphabet[group & 63U] : '=';
  }
  return text;
}

Result<std::vector<uint8_t>> base64_decode(std::string_view text) {
  static constexpr std::array<int8_t, 256> kTable = decoding_table();
  std::vector<uint8_t> bytes;
  bytes.reserve(text.size() / 4 * 3);
  uint32_t group = 0;
  int count = 0;    // characters of the current group of four
  int padding = 0;  // '=' seen
  for (std::size_t offset = 0; offset < text.size(); ++offset) {
    const char c = text[offset];
    if (c == '\n' || c == '\r' || c == ' ' || c == '\t') continue;
    if (c == '=') {
      if (count < 2) return Error(fmt::format("base64: '=' at offset {} cannot pad a group of {} characters", offset, count));
      ++padding;
    } else {
      const int8_t value = kTable[static_cast<uint8_t>(c)];
      if (value < 0) return Error(fmt::format("base64: character {} at offset {} is not base64", static_cast<int>(static_cast<uint8_t>(c)), offset));
      if (padding > 0) return Error(fmt::format("base64: data after the '=' padding at offset {}", offset));
      group |= static_cast<uint32_t>(value) << (18 - 6 * count);
    }
    if (++count == 4) {
      bytes.push_back(static_cast<uint8_t>(group >> 16));
      if (padding < 2) bytes.push_back(static_cast<uint8_t>(group >> 8));
      if (padding < 1) bytes.push_back(static_cast<uint8_t>(group));
      group = 0;
      count = 0;
      if (padding > 0) padding = -1;  // the text must end here
    } else if (padding < 0) {
      return Error(fmt::format("base64: data after the '=' padding at offset {}", offset));
    }
  }
  if (count != 0) return Error(fmt::format("base64: {} characters left over (the length must be a multiple of 4)", count));
  return bytes;
}

}  // namespace hanzo::fusion
