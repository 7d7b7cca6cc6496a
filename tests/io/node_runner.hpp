#pragma once
// Runs a node script of tests/conformance (independent implementations: Foxglove's MCAP and
// ROS bag libraries) and parses the one JSON object it prints.

#include <array>
#include <cstdio>
#include <string>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace hanzo::fusion::test {

inline nlohmann::json run_node(const std::string& script, const std::string& arguments) {
  const std::string command = fmt::format("{} tests/conformance/{} {} 2>&1", HANZO_NODE_EXECUTABLE, script, arguments);
  FILE* pipe = ::popen(command.c_str(), "r");
  std::string out;
  std::array<char, 65536> buffer{};
  for (std::size_t n; pipe && (n = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0;) out.append(buffer.data(), n);
  const int status = pipe ? ::pclose(pipe) : -1;
  if (status != 0) {
    ADD_FAILURE() << command << " failed (" << status << "); is tests/conformance/node_modules installed "
                  << "(scripts/install-deps.sh)?\n" << out;
    return {};
  }
  return nlohmann::json::parse(out);
}

}  // namespace hanzo::fusion::test
