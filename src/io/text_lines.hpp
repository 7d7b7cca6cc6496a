#pragma once
// Helpers for the line-oriented text formats the importers and trajectory readers parse.

#include <charconv>
#include <cmath>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace hanzo::fusion::io {

/// Splits a line at spaces, tabs and commas; drops empty fields and a trailing '\r'.
inline std::vector<std::string> split_fields(std::string_view line) {
  std::vector<std::string> fields;
  std::size_t begin = 0;
  while (begin < line.size()) {
    const std::size_t end = line.find_first_of(" \t,\r", begin);
    const std::size_t stop = end == std::string_view::npos ? line.size() : end;
    if (stop > begin) fields.emplace_back(line.substr(begin, stop - begin));
    begin = stop + 1;
  }
  return fields;
}

/// The whole field as a double (std::from_chars: exact, locale independent), or nullopt.
inline std::optional<double> parse_double(std::string_view text) {
  double value = 0.0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return value;
}

}  // namespace hanzo::fusion::io
