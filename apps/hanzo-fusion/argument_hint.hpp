#pragma once
// What to tell a user whose command line did not parse: the first option or subcommand that
// no command knows, with the closest valid spelling ("unknown option '--calibraton' for 'run';
// did you mean '--calibration'?"). CLI11 reports the first rule broken instead ("--log is
// required" while the misspelt flag was meant to be something else).

#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

namespace hanzo::fusion::app {

/// Walks `arguments` (argv without the program name) down the subcommands of `app`; returns
/// the hint for the first option that neither the subcommand reached nor a parent has, or for
/// a word where a subcommand is required that names none. nullopt when every option and
/// subcommand is known (the parse error is about something else).
std::optional<std::string> unknown_argument_hint(const CLI::App& app, const std::vector<std::string>& arguments);

/// The number of single-character insertions, deletions and substitutions between a and b.
std::size_t edit_distance(const std::string& a, const std::string& b);

}  // namespace hanzo::fusion::app
