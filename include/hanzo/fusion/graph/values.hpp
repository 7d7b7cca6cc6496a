#pragma once
// Values: the current estimate of every variable of a factor graph, by key.

#include <map>
#include <variant>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se2.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/graph/keys.hpp"

namespace hanzo::fusion::graph {

/// IMU biases (B(i) keys), IMU axes: accelerometer m/s^2, gyroscope rad/s. Euclidean; tangent
/// order (accelerometer, gyroscope), as GTSAM's imuBias::ConstantBias.
struct ImuBias {
  Eigen::Vector3d accelerometer = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyroscope = Eigen::Vector3d::Zero();

  Eigen::Matrix<double, 6, 1> vector() const {
    Eigen::Matrix<double, 6, 1> stacked;
    stacked << accelerometer, gyroscope;
    return stacked;
  }
  static ImuBias from_vector(const Eigen::Matrix<double, 6, 1>& stacked) { return {stacked.head<3>(), stacked.tail<3>()}; }
};

/// Poses (SE2, SE3), points and velocities (Vector3, Euclidean), IMU biases.
using Value = std::variant<SE2, SE3, Eigen::Vector3d, ImuBias>;

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
