#pragma once
// Lookup between enum values and the names files and messages use for them, from one table
// per enum: constexpr std::array<std::pair<Enum, std::string_view>, N>.

#include <array>
#include <optional>
#include <string_view>
#include <utility>

namespace hanzo::fusion {

template <typename Enum, size_t N>
using EnumNames = std::array<std::pair<Enum, std::string_view>, N>;

/// The name of value, or "invalid" for a value outside the table.
template <typename Enum, size_t N>
constexpr std::string_view enum_name(const EnumNames<Enum, N>& table, Enum value) {
  for (const auto& [entry, name] : table) {
    if (entry == value) return name;
  }
  return "invalid";
}

/// The value named name, or nullopt.
template <typename Enum, size_t N>
constexpr std::optional<Enum> enum_from_name(const EnumNames<Enum, N>& table, std::string_view name) {
  for (const auto& [entry, entry_name] : table) {
    if (entry_name == name) return entry;
  }
  return std::nullopt;
}

}  // namespace hanzo::fusion
