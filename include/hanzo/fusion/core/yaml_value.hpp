#pragma once
// YamlValue: typed, error-reporting access to a YAML document, shared by every loader of a
// configuration or calibration file. Each value remembers the file, its key path and its line,
// so every error reads like
//     calibration.yaml:7: lidar_to_body.rotation: expected 4 numbers (w, x, y, z), got 3
// Non-finite numbers (.nan, .inf) are always rejected.

#include <cstdint>
#include <initializer_list>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <yaml-cpp/node/node.h>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion {

class YamlValue {
 public:
  /// Parses a file; a syntax error names the file, line and column.
  static Result<YamlValue> load_file(const std::string& path);
  /// Parses text; source_name stands in for the file name in errors.
  static Result<YamlValue> load_string(const std::string& text, const std::string& source_name);

  /// False when the key this value was looked up by is absent (or explicitly null).
  bool present() const;
  bool is_map() const;
  /// The value under key (absent when missing; an absent value's children are absent too).
  YamlValue operator[](std::string_view key) const;
  /// The entries of a map in file order (empty when not a map).
  std::vector<std::pair<std::string, YamlValue>> entries() const;
  /// The items of a sequence, their paths "key[0]", "key[1]", ... (empty when not a sequence).
  std::vector<YamlValue> elements() const;
  bool is_sequence() const;

  /// Key path, e.g. "lidar_to_body.rotation" ("" for the root).
  const std::string& path() const { return path_; }
  /// The same value, but its children's paths start afresh below it: for a file whose single
  /// top-level key (`calibration:`) is its body, errors then read "lidar_to_body.rotation".
  YamlValue as_path_root() const;
  /// 1-based line of this value's key, or of its parent's key when absent.
  int line() const { return line_; }
  const std::string& source_name() const { return *source_; }

  /// "file:line: path: what".
  Error error(std::string_view what) const;

  Result<double> as_double() const;
  Result<int64_t> as_int64() const;
  Result<std::string> as_string() const;
  /// true/false (also yes/no, on/off as YAML 1.1 spells them).
  Result<bool> as_bool() const;
  /// A sequence of exactly count numbers; description names them in the error, e.g.
  /// "(w, x, y, z)" gives "expected 4 numbers (w, x, y, z), got 3".
  Result<std::vector<double>> as_doubles(size_t count, std::string_view description) const;
  /// A sequence of numbers of any length (an empty sequence is allowed).
  Result<std::vector<double>> as_doubles() const;

  /// Fails naming the first key of this map that is not in allowed (catches typos) and the keys
  /// that are. Also fails when this value is present but not a map.
  Status check_keys(std::initializer_list<std::string_view> allowed) const;
  /// Fails when this value is present but not a map.
  Status expect_map() const;

 private:
  YamlValue(YAML::Node node, std::shared_ptr<const std::string> source, std::string path, int line);
  std::string child_path(std::string_view key) const;
  YAML::Node node_;
  std::shared_ptr<const std::string> source_;
  std::string path_;
  bool is_path_root_ = false;
  int line_ = 1;
};

/// Shortest text that reads back as exactly the same double ("0.1", "458.654", "1e-06").
std::string format_double(double value);

}  // namespace hanzo::fusion

/// Helpers shared by the loaders and writers of configuration files.
namespace hanzo::fusion::yaml {

/// The value as a finite number >= 0, or fallback when absent.
Result<double> non_negative_or(const YamlValue& value, double fallback);
/// The value as a finite number > 0, or fallback when absent.
Result<double> positive_or(const YamlValue& value, double fallback);
/// A list of three finite numbers >= 0, or fallback when absent; description names the
/// components in errors ("(x, y, z)").
Result<Eigen::Vector3d> vector3_or(const YamlValue& value, const Eigen::Vector3d& fallback, std::string_view description);

/// "[0.1, 0.1, 0.1]" with shortest round-trip numbers.
std::string flow_sequence(const Eigen::VectorXd& values);
/// A string as a YAML scalar: plain when that reads back as the same string, quoted otherwise.
std::string scalar(const std::string& text);
/// Writes text to path through a temporary file in the same folder renamed into place, so a
/// crash never leaves a half-written file. The error names the path and the system's reason.
Status write_file_atomically(const std::string& path, const std::string& text);

}  // namespace hanzo::fusion::yaml
