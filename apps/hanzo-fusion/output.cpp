#include "output.hpp"

#include <iostream>

namespace hanzo::fusion::app {

int report_success(const Output& output, const nlohmann::json& result, const std::string& text) {
  if (output.json) {
    std::cout << result.dump(2) << '\n';
  } else {
    std::cout << text;
  }
  return 0;
}

int report_failure(const Output& output, nlohmann::json result, const std::string& reason) {
  if (output.json) {
    result["ok"] = false;
    result["error"] = reason;
    std::cout << result.dump(2) << '\n';
  }
  std::cerr << "hanzo-fusion: " << reason << '\n';
  return 1;
}

}  // namespace hanzo::fusion::app
