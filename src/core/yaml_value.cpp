#include "hanzo/fusion/core/yaml_value.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

#include <fcntl.h>
#include <unistd.h>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "hanzo/fusion/core/files.hpp"

namespace hanzo::fusion {
namespace {

std::string describe(const YAML::Node& node) {
  switch (node.Type()) {
    case YAML::NodeType::Scalar: return fmt::format("'{}'", node.Scalar());
    case YAML::NodeType::Sequence: return fmt::format("a list of {}", node.size());
    case YAML::NodeType::Map: return "a map";
    default: return "nothing";
  }
}

bool parse_double(const std::string& text, double* value) {
  // yaml-cpp's own conversion accepts YAML 1.1/1.2 spellings (.nan, .inf, 1e3, 0x10 is not a
  // float) and refuses trailing garbage.
  return YAML::convert<double>::decode(YAML::Node(text), *value);
}

// The first key that appears twice in one map (yaml-cpp keeps both and its lookups return the
// first, so a second value would be silently ignored): "line L: duplicate key 'k' (first at line F)".
std::optional<std::string> duplicate_key(const YAML::Node& node) {
  if (node.IsMap()) {
    std::map<std::string, int> lines;
    for (const auto& entry : node) {
      if (entry.first.IsScalar()) {
        const int line = entry.first.Mark().line + 1;
        const auto [first, inserted] = lines.emplace(entry.first.Scalar(), line);
        if (!inserted) return fmt::format("{}: duplicate key '{}' (first at line {})", line, entry.first.Scalar(), first->second);
      }
      if (auto found = duplicate_key(entry.second)) return found;
    }
  } else if (node.IsSequence()) {
    for (const auto& item : node) {
      if (auto found = duplicate_key(item)) return found;
    }
  }
  return std::nullopt;
}

}  // namespace

YamlValue::YamlValue(YAML::Node node, std::shared_ptr<const std::string> source, std::string path, int line)
    : node_(std::move(node)), source_(std::move(source)), path_(std::move(path)), line_(line) {}

Result<YamlValue> YamlValue::load_string(const std::string& text, const std::string& source_name) {
  try {
    YAML::Node root = YAML::Load(text);
    if (auto duplicate = duplicate_key(root)) return Error{fmt::format("{}:{}", source_name, *duplicate)};
    return YamlValue(root, std::make_shared<const std::string>(source_name), "", std::max(1, root.Mark().line + 1));
  } catch (const YAML::Exception& e) {
    return Error{fmt::format("{}:{}:{}: YAML syntax error: {}", source_name, e.mark.line + 1, e.mark.column + 1, e.msg)};
  }
}

Result<YamlValue> YamlValue::load_file(const std::string& path) {
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_file(path));
  return load_string(text, path);
}

bool YamlValue::present() const { return node_.IsDefined() && !node_.IsNull(); }

bool YamlValue::is_map() const { return node_.IsMap(); }

std::string YamlValue::child_path(std::string_view key) const {
  return path_.empty() || is_path_root_ ? std::string(key) : fmt::format("{}.{}", path_, key);
}

YamlValue YamlValue::as_path_root() const {
  YamlValue root = *this;
  root.is_path_root_ = true;
  return root;
}

YamlValue YamlValue::operator[](std::string_view key) const {
  for (auto& [name, value] : entries()) {
    if (name == key) return value;
  }
  return YamlValue(YAML::Node(YAML::NodeType::Undefined), source_, child_path(key), line_);
}

// Each entry's line is the line of its key, so errors about a nested block point at its name.
std::vector<std::pair<std::string, YamlValue>> YamlValue::entries() const {
  std::vector<std::pair<std::string, YamlValue>> result;
  if (!node_.IsMap()) return result;
  for (const auto& entry : node_) {
    const std::string key = entry.first.Scalar();
    result.emplace_back(key, YamlValue(entry.second, source_, child_path(key), entry.first.Mark().line + 1));
  }
  return result;
}

std::vector<YamlValue> YamlValue::elements() const {
  std::vector<YamlValue> result;
  if (!node_.IsSequence()) return result;
  for (std::size_t i = 0; i < node_.size(); ++i) {
    const YAML::Node item = node_[i];
    result.push_back(YamlValue(item, source_, fmt::format("{}[{}]", path_, i), item.Mark().line >= 0 ? item.Mark().line + 1 : line_));
  }
  return result;
}

bool YamlValue::is_sequence() const { return node_.IsSequence(); }

Error YamlValue::error(std::string_view what) const {
  return Error{fmt::format("{}:{}: {}: {}", *source_, line_, path_.empty() ? "(document)" : path_, what), path_};
}

Result<double> YamlValue::as_double() const {
  if (!present()) return error("missing (expected a number)");
  double value = 0.0;
  if (!node_.IsScalar() || !parse_double(node_.Scalar(), &value)) return error(fmt::format("expected a number, got {}", describe(node_)));
  if (!std::isfinite(value)) return error(fmt::format("expected a finite number, got {}", describe(node_)));
  return value;
}

Result<int64_t> YamlValue::as_int64() const {
  if (!present()) return error("missing (expected an integer)");
  if (!node_.IsScalar()) return error(fmt::format("expected an integer, got {}", describe(node_)));
  const std::string& text = node_.Scalar();
  int64_t value = 0;
  const char* begin = text.data();
  if (!text.empty() && text[0] == '+') ++begin;
  const auto [end, code] = std::from_chars(begin, text.data() + text.size(), value);
  if (code == std::errc::result_out_of_range) return error(fmt::format("integer {} is out of the 64-bit range", describe(node_)));
  if (code != std::errc() || end != text.data() + text.size()) {
    return error(fmt::format("expected an integer, got {}", describe(node_)));
  }
  return value;
}

Result<bool> YamlValue::as_bool() const {
  if (!present()) return error("missing (expected true or false)");
  bool value = false;
  if (!node_.IsScalar() || !YAML::convert<bool>::decode(node_, value)) return error(fmt::format("expected true or false, got {}", describe(node_)));
  return value;
}

Result<std::string> YamlValue::as_string() const {
  if (!present()) return error("missing (expected a string)");
  if (!node_.IsScalar()) return error(fmt::format("expected a string, got {}", describe(node_)));
  return node_.Scalar();
}

Result<std::vector<double>> YamlValue::as_doubles() const {
  if (!present()) return error("missing (expected a list of numbers)");
  if (!node_.IsSequence()) return error(fmt::format("expected a list of numbers, got {}", describe(node_)));
  std::vector<double> values;
  values.reserve(node_.size());
  for (size_t i = 0; i < node_.size(); ++i) {
    double value = 0.0;
    const YAML::Node& item = node_[i];
    if (!item.IsScalar() || !parse_double(item.Scalar(), &value)) {
      return error(fmt::format("item {}: expected a number, got {}", i, describe(item)));
    }
    if (!std::isfinite(value)) return error(fmt::format("item {}: expected a finite number, got {}", i, describe(item)));
    values.push_back(value);
  }
  return values;
}

Result<std::vector<double>> YamlValue::as_doubles(size_t count, std::string_view description) const {
  const std::string expected = fmt::format("expected {} numbers{}{}", count, description.empty() ? "" : " ", description);
  if (!present()) return error(fmt::format("missing ({})", expected));
  if (!node_.IsSequence()) return error(fmt::format("{}, got {}", expected, describe(node_)));
  if (node_.size() != count) return error(fmt::format("{}, got {}", expected, node_.size()));
  return as_doubles();
}

Status YamlValue::expect_map() const {
  if (present() && !node_.IsMap()) return error(fmt::format("expected a map of keys, got {}", describe(node_)));
  return ok_status();
}

Status YamlValue::check_keys(std::initializer_list<std::string_view> allowed) const {
  if (Status status = expect_map(); !status) return status;
  for (const auto& [key, value] : entries()) {
    bool known = false;
    for (std::string_view name : allowed) known = known || name == key;
    if (!known) return value.error(fmt::format("unknown key (expected one of: {})", fmt::join(allowed, ", ")));
  }
  return ok_status();
}

std::string format_double(double value) {
  char buffer[64];
  const auto [end, code] = std::to_chars(buffer, buffer + sizeof(buffer), value);
  std::string text(buffer, code == std::errc() ? end : buffer);
  // Keep it visibly a float in YAML ("1" -> "1.0") so a reader never takes it for an integer.
  if (std::isfinite(value) && text.find_first_of(".eEn") == std::string::npos) text += ".0";
  return text;
}

}  // namespace hanzo::fusion

namespace hanzo::fusion::yaml {

Result<double> non_negative_or(const YamlValue& value, double fallback) {
  if (!value.present()) return fallback;
  Result<double> number = value.as_double();
  if (!number) return number;
  if (*number < 0.0) return value.error(fmt::format("expected a number >= 0, got {}", *number));
  return number;
}

Result<double> positive_or(const YamlValue& value, double fallback) {
  if (!value.present()) return fallback;
  Result<double> number = value.as_double();
  if (!number) return number;
  if (!(*number > 0.0)) return value.error(fmt::format("expected a positive number, got {}", *number));
  return number;
}

Result<Eigen::Vector3d> vector3_or(const YamlValue& value, const Eigen::Vector3d& fallback, std::string_view description) {
  if (!value.present()) return fallback;
  Result<std::vector<double>> numbers = value.as_doubles(3, description);
  if (!numbers) return numbers.error();
  for (double number : *numbers) {
    if (number < 0.0) return value.error(fmt::format("expected numbers >= 0, got {}", number));
  }
  return Eigen::Vector3d((*numbers)[0], (*numbers)[1], (*numbers)[2]);
}

std::string flow_sequence(const Eigen::VectorXd& values) {
  std::vector<std::string> items;
  for (Eigen::Index i = 0; i < values.size(); ++i) items.push_back(format_double(values[i]));
  return fmt::format("[{}]", fmt::join(items, ", "));
}

std::string scalar(const std::string& text) {
  YAML::Emitter emitter;
  emitter << text;
  return emitter.c_str();
}

Status write_file_atomically(const std::string& path, const std::string& text) {
  // Write and fsync a temporary file in the same folder, then rename it over the target:
  // readers see the old file or the new one, never a partial one, even after a power loss.
  const std::string temporary = path + ".tmp";
  HANZO_RETURN_IF_ERROR(write_file_durably(temporary, text));
  if (::rename(temporary.c_str(), path.c_str()) != 0) {
    const int rename_errno = errno;
    ::unlink(temporary.c_str());
    return Error{fmt::format("{}: cannot replace ({})", path, std::strerror(rename_errno))};
  }
  return ok_status();
}

}  // namespace hanzo::fusion::yaml
