#pragma once
// How every subcommand reports: with --json exactly one JSON object on stdout, otherwise
// human-readable text; failures also print one line "hanzo-fusion: <reason>" on stderr and
// exit non-zero.

#include <string>

#include <nlohmann/json.hpp>

namespace hanzo::fusion::app {

struct Output {
  bool json = false;
};

/// Prints the result of a successful command (text or JSON) and returns exit code 0.
int report_success(const Output& output, const nlohmann::json& result, const std::string& text);
/// Prints the failure (JSON object with "ok": false and "error" on stdout when --json) plus
/// the one-line reason on stderr, and returns exit code 1.
int report_failure(const Output& output, nlohmann::json result, const std::string& reason);

}  // namespace hanzo::fusion::app
