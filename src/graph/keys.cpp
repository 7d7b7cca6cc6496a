#include "hanzo/fusion/graph/keys.hpp"

#include <cctype>

#include <fmt/format.h>

namespace hanzo::fusion::graph {

std::string key_to_string(Key key) {
  const char character = symbol_character(key);
  if (std::isprint(static_cast<unsigned char>(character)) && character != ' ') return fmt::format("{}{}", character, symbol_index(key));
  return fmt::format("{}", key);
}

}  // namespace hanzo::fusion::graph
