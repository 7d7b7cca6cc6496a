#pragma once
// Values: the current estimate of every variable of a factor graph, by key.

#include <map>
#include <variant>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se2.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/graph/keys.hpp"

namespace hanzo::fusion::graph {

using Value = std::variant<SE2, SE3, Eigen::Vector3d>;

class Values {
 public:
  /// Adds or replaces.
  void insert(Key key, const Value& value) { values_[key] = value; }
  bool exists(Key key) const { return values_.count(key) != 0; }
  size_t size() const { return values_.size(); }
  const std::map<Key, Value>& all() const { return values_; }

  /// The value as T; fails naming the key when it is missing or of another type.
  template <typename T>
  Result<T> at(Key key) const {
    const auto found = values_.find(key);
    std::string message = "value of key ";
    message += key_to_string(key);
    if (found == values_.end()) return Error(message + ": missing");
    if (const T* value = std::get_if<T>(&found->second)) return *value;
    return Error(message + ": another type");
  }

 private:
  std::map<Key, Value> values_;
};

}  // namespace hanzo::fusion::graph
