#include "argument_hint.hpp"

#include <algorithm>
#include <charconv>

#include <fmt/format.h>

namespace hanzo::fusion::app {
namespace {

bool is_number(const std::string& word) {
  double value = 0.0;
  const auto [end, error] = std::from_chars(word.data(), word.data() + word.size(), value);
  return error == std::errc() && end == word.data() + word.size();
}

// The option `name` ("--config", "-o") of `command` or of a parent it falls through to.
const CLI::Option* find_option(const CLI::App* command, const std::string& name) {
  for (; command != nullptr; command = command->get_parent()) {
    if (const CLI::Option* option = command->get_option_no_throw(name)) return option;
  }
  return nullptr;
}

// Every spelling of every option of `command` and its parents ("--calibration", "--calib", "-c").
std::vector<std::string> option_spellings(const CLI::App* command) {
  std::vector<std::string> spellings;
  for (; command != nullptr; command = command->get_parent()) {
    for (const CLI::Option* option : command->get_options()) {
      for (const std::string& name : option->get_lnames()) spellings.push_back("--" + name);
      for (const std::string& name : option->get_snames()) spellings.push_back("-" + name);
    }
  }
  return spellings;
}

std::string full_name(const CLI::App* command) {
  std::string name;
  for (; command != nullptr && command->get_parent() != nullptr; command = command->get_parent()) {
    name = command->get_name() + (name.empty() ? "" : " " + name);
  }
  return name.empty() ? "hanzo-fusion" : name;
}

// " did you mean 'X'?" for the closest candidate within a third of the word's length (at least
// two edits), "" when none is that close.
std::string closest(const std::string& word, const std::vector<std::string>& candidates) {
  const std::string* best = nullptr;
  std::size_t best_distance = std::max<std::size_t>(2, word.size() / 3) + 1;
  for (const std::string& candidate : candidates) {
    const std::size_t distance = edit_distance(word, candidate);
    if (distance < best_distance) {
      best_distance = distance;
      best = &candidate;
    }
  }
  return best != nullptr ? fmt::format("; did you mean '{}'?", *best) : "";
}

}  // namespace

std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> previous(b.size() + 1), current(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) previous[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    current[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      current[j] = std::min({previous[j] + 1, current[j - 1] + 1, previous[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
    }
    std::swap(previous, current);
  }
  return previous[b.size()];
}

std::optional<std::string> unknown_argument_hint(const CLI::App& app, const std::vector<std::string>& arguments) {
  const CLI::App* command = &app;
  for (std::size_t i = 0; i < arguments.size(); ++i) {
    const std::string& word = arguments[i];
    if (word == "--") break;  // positional arguments follow
    if (word.size() > 1 && word[0] == '-' && !is_number(word)) {
      const std::string name = word.substr(0, word.find('='));
      const CLI::Option* option = find_option(command, name);
      if (option == nullptr) {
        return fmt::format("unknown option '{}' for '{}'{}", name, full_name(command), closest(name, option_spellings(command)));
      }
      // Its values, unless given as --name=value: the words that follow, up to the count it takes.
      if (name.size() == word.size()) {
        const int values = option->get_items_expected_max();
        for (int taken = 0; taken < values && i + 1 < arguments.size(); ++taken) {
          const std::string& next = arguments[i + 1];
          if (next.size() > 1 && next[0] == '-' && !is_number(next)) break;
          ++i;
        }
      }
      continue;
    }
    const std::vector<const CLI::App*> subcommands = command->get_subcommands([](const CLI::App*) { return true; });
    const auto named = std::find_if(subcommands.begin(), subcommands.end(), [&](const CLI::App* sub) { return sub->check_name(word); });
    if (named != subcommands.end()) {
      command = *named;
      continue;
    }
    if (!subcommands.empty() && command->get_require_subcommand_min() > 0) {
      std::vector<std::string> names;
      for (const CLI::App* sub : subcommands) names.push_back(sub->get_name());
      return fmt::format("unknown command '{}' for '{}'{}", word, full_name(command), closest(word, names));
    }
  }
  return std::nullopt;
}

}  // namespace hanzo::fusion::app
