#include "hanzo/fusion/core/files.hpp"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

namespace hanzo::fusion {

Result<std::string> read_file(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) return Error(fmt::format("{}: cannot open file ({})", path, std::strerror(errno)));
  std::ostringstream text;
  text << file.rdbuf();
  if (file.bad()) return Error(fmt::format("{}: read error ({})", path, std::strerror(errno)));
  return text.str();
}

}  // namespace hanzo::fusion
