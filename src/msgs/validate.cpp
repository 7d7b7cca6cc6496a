#include "hanzo/fusion/msgs/validate.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

#include "hanzo/fusion/core/finite.hpp"

namespace hanzo::fusion::msgs {
namespace {

// Builds errors of the form "<Message>.<field>: <what>".
class Checker {
 public:
  explicit Checker(std::string_view message_name) : message_name_(message_name) {}

  Status fail(std::string_view field, std::string_view what) const {
    return Error{fmt::format("{}.{}: {}", message_name_, field, what), std::string(field)};
  }

  Status timestamp(Timestamp time, std::string_view field) const {
    if (time.is_zero()) return fail(field, "zero timestamp (expected nanoseconds since the Unix epoch)");
    if (time.nanoseconds() < 0) return fail(field, fmt::format("negative timestamp {}", time.nanoseconds()));
    return ok_status();
  }

  Status finite(double value, std::string_view field) const {
    if (!std::isfinite(value)) return fail(field, fmt::format("non-finite value {}", value));
    return ok_status();
  }

  template <typename Derived>
  Status finite_vector(const Eigen::MatrixBase<Derived>& vector, std::string_view field) const {
    constexpr std::array<std::string_view, 3> kAxes{"x", "y", "z"};
    for (Eigen::Index i = 0; i < vector.size(); ++i) {
      if (std::isfinite(static_cast<double>(vector[i]))) continue;  // names are formatted only for the error
      const std::string component = vector.size() == 3 ? fmt::format("{}.{}", field, kAxes[i]) : fmt::format("{}[{}]", field, i);
      return finite(static_cast<double>(vector[i]), component);
    }
    return ok_status();
  }

  // Components named as in the protobuf Matrix3x3/Matrix6x6 (row-major data[k]).
  template <int N>
  Status covariance(const Eigen::Matrix<double, N, N>& matrix, std::string_view field) const {
    for (int row = 0; row < N; ++row) {
      for (int col = 0; col < N; ++col) {
        if (!std::isfinite(matrix(row, col))) return finite(matrix(row, col), fmt::format("{}.data[{}]", field, row * N + col));
      }
    }
    for (int i = 0; i < N; ++i) {
      if (matrix(i, i) < 0.0) {
        return fail(fmt::format("{}.data[{}]", field, i * N + i), fmt::format("negative variance {} on the diagonal", matrix(i, i)));
      }
    }
    for (int row = 0; row < N; ++row) {
      for (int col = row + 1; col < N; ++col) {
        const double a = matrix(row, col);
        const double b = matrix(col, row);
        if (std::abs(a - b) > 1e-9 * std::max({1.0, std::abs(a), std::abs(b)})) {
          return fail(fmt::format("{}.data[{}]", field, row * N + col),
                      fmt::format("covariance not symmetric: ({},{}) = {} but ({},{}) = {}", row, col, a, col, row, b));
        }
      }
    }
    return ok_status();
  }

  template <int N>
  Status optional_covariance(const std::optional<Eigen::Matrix<double, N, N>>& matrix, std::string_view field) const {
    return matrix ? covariance<N>(*matrix, field) : ok_status();
  }

  Status unit_quaternion(const Eigen::Quaterniond& q, std::string_view field) const {
    if (Status status = finite_vector(Eigen::Vector4d(q.w(), q.x(), q.y(), q.z()), field); !status) return status;
    const double norm = q.norm();
    if (std::abs(norm - 1.0) > kUnitQuaternionTolerance) {
      return fail(field, fmt::format("quaternion (w, x, y, z) = ({}, {}, {}, {}) has norm {} (expected 1)", q.w(), q.x(),
                                     q.y(), q.z(), norm));
    }
    return ok_status();
  }

  Status pose(const Pose& value, std::string_view field) const {
    if (Status status = finite_vector(value.position, fmt::format("{}.position", field)); !status) return status;
    return unit_quaternion(value.orientation, fmt::format("{}.orientation", field));
  }

  template <typename Vector>
  Status per_point(const Vector& values, size_t point_count, std::string_view field) const {
    if (!values.empty() && values.size() != point_count) {
      return fail(field, fmt::format("{} values for {} points (expected none or one per point)", values.size(), point_count));
    }
    return ok_status();
  }

 private:
  std::string_view message_name_;
};

}  // namespace

Status validate(const ImuMessage& message) {
  const Checker check("ImuMessage");
  HANZO_RETURN_IF_ERROR(check.timestamp(message.timestamp, "timestamp_ns"));
  HANZO_RETURN_IF_ERROR(check.finite_vector(message.linear_acceleration, "linear_acceleration"));
  HANZO_RETURN_IF_ERROR(check.finite_vector(message.angular_velocity, "angular_velocity"));
  HANZO_RETURN_IF_ERROR(check.optional_covariance(message.acceleration_covariance, "acceleration_covariance"));
  HANZO_RETURN_IF_ERROR(check.optional_covariance(message.gyroscope_covariance, "gyroscope_covariance"));
  if (message.orientation) HANZO_RETURN_IF_ERROR(check.unit_quaternion(*message.orientation, "orientation"));
  if (message.orientation_covariance && !message.orientation) {
    return check.fail("orientation_covariance", "given without an orientation");
  }
  HANZO_RETURN_IF_ERROR(check.optional_covariance(message.orientation_covariance, "orientation_covariance"));
  return ok_status();
}

Status validate(const PointCloudMessage& message) {
  const Checker check("PointCloudMessage");
  HANZO_RETURN_IF_ERROR(check.timestamp(message.timestamp, "timestamp_ns"));
  const size_t count = message.points.size();
  if (count == 0) return check.fail("points", "empty (a point cloud needs at least one point)");
  // Per-point checks format a field name only for the point that fails (a cloud has 10^5 points).
  if (!all_finite(message.points.front().data(), 3 * count)) {
    for (size_t i = 0; i < count; ++i) {
      if (!message.points[i].allFinite()) return check.finite_vector(message.points[i], fmt::format("points[{}]", i));
    }
  }
  HANZO_RETURN_IF_ERROR(check.per_point(message.intensities, count, "intensities"));
  HANZO_RETURN_IF_ERROR(check.per_point(message.ring_ids, count, "ring_ids"));
  HANZO_RETURN_IF_ERROR(check.per_point(message.point_timestamps, count, "point_timestamps"));
  const bool intensities_valid = all_within(message.intensities.data(), message.intensities.size(), 0.0F, 1.0F);
  for (size_t i = 0; !intensities_valid && i < message.intensities.size(); ++i) {
    const float intensity = message.intensities[i];
    if (!(intensity >= 0.0F && intensity <= 1.0F)) {
      return check.fail(fmt::format("intensities[{}]", i), fmt::format("{} outside [0, 1]", intensity));
    }
  }
  for (size_t i = 0; i < message.point_timestamps.size(); ++i) {
    const Timestamp time = message.point_timestamps[i];
    if (time.is_zero() || time.nanoseconds() < 0) return check.timestamp(time, fmt::format("point_timestamps[{}]", i));
  }
  return ok_status();
}

Status validate(const CameraIntrinsics& intrinsics, std::string_view field_prefix) {
  const Checker check("CameraIntrinsics");
  const auto field = [&](std::string_view name) { return fmt::format("{}.{}", field_prefix, name); };
  for (const auto& [name, value] : {std::pair<std::string_view, double>{"fx", intrinsics.fx}, {"fy", intrinsics.fy},
                                    {"cx", intrinsics.cx}, {"cy", intrinsics.cy}}) {
    HANZO_RETURN_IF_ERROR(check.finite(value, field(name)));
  }
  if (intrinsics.fx <= 0.0) return check.fail(field("fx"), fmt::format("focal length {} must be positive", intrinsics.fx));
  if (intrinsics.fy <= 0.0) return check.fail(field("fy"), fmt::format("focal length {} must be positive", intrinsics.fy));
  if (intrinsics.width > 0 && (intrinsics.cx < 0.0 || intrinsics.cx > intrinsics.width)) {
    return check.fail(field("cx"), fmt::format("principal point {} outside the image width {}", intrinsics.cx, intrinsics.width));
  }
  if (intrinsics.height > 0 && (intrinsics.cy < 0.0 || intrinsics.cy > intrinsics.height)) {
    return check.fail(field("cy"), fmt::format("principal point {} outside the image height {}", intrinsics.cy, intrinsics.height));
  }
  return ok_status();
}

Status validate(const DistortionModel& distortion, std::string_view field_prefix) {
  const Checker check("DistortionModel");
  const std::string field = fmt::format("{}.coefficients", field_prefix);
  const size_t count = distortion.coefficients.size();
  for (size_t i = 0; i < count; ++i) HANZO_RETURN_IF_ERROR(check.finite(distortion.coefficients[i], fmt::format("{}[{}]", field, i)));
  switch (distortion.type) {
    case DistortionType::kNone:
      if (count != 0) return check.fail(field, fmt::format("model none takes no coefficients, got {}", count));
      break;
    case DistortionType::kRadtan:
      if (count != 4 && count != 5) {
        return check.fail(field, fmt::format("model radtan takes 4 or 5 coefficients (k1, k2, p1, p2[, k3]), got {}", count));
      }
      break;
    case DistortionType::kEquidistant:
      if (count != 4) return check.fail(field, fmt::format("model equidistant takes 4 coefficients (k1, k2, k3, k4), got {}", count));
      break;
  }
  return ok_status();
}

Status validate(const ImageMessage& message) {
  const Checker check("ImageMessage");
  HANZO_RETURN_IF_ERROR(check.timestamp(message.timestamp, "timestamp_ns"));
  if (message.width == 0) return check.fail("width", "zero");
  if (message.height == 0) return check.fail("height", "zero");
  const uint64_t expected = uint64_t{message.width} * message.height * bytes_per_pixel(message.encoding);
  if (message.data.size() != expected) {
    return check.fail("data", fmt::format("{} bytes, but {}x{} {} needs {}", message.data.size(), message.width,
                                          message.height, to_string(message.encoding), expected));
  }
  if (message.intrinsics) {
    HANZO_RETURN_IF_ERROR(validate(*message.intrinsics));
    if ((message.intrinsics->width != 0 && message.intrinsics->width != message.width) ||
        (message.intrinsics->height != 0 && message.intrinsics->height != message.height)) {
      return check.fail("intrinsics.width", fmt::format("intrinsics are for {}x{} but the image is {}x{}",
                                                         message.intrinsics->width, message.intrinsics->height,
                                                         message.width, message.height));
    }
  }
  if (message.distortion) HANZO_RETURN_IF_ERROR(validate(*message.distortion));
  return ok_status();
}

Status validate(const GnssMessage& message) {
  const Checker check("GnssMessage");
  HANZO_RETURN_IF_ERROR(check.timestamp(message.timestamp, "timestamp_ns"));
  HANZO_RETURN_IF_ERROR(check.finite(message.latitude, "latitude"));
  HANZO_RETURN_IF_ERROR(check.finite(message.longitude, "longitude"));
  HANZO_RETURN_IF_ERROR(check.finite(message.altitude, "altitude"));
  if (std::abs(message.latitude) > 90.0) return check.fail("latitude", fmt::format("{} outside [-90, 90] degrees", message.latitude));
  if (std::abs(message.longitude) > 180.0) {
    return check.fail("longitude", fmt::format("{} outside [-180, 180] degrees", message.longitude));
  }
  if (Status status = validate(message.geodetic()); !status) return check.fail("altitude", status.error().message);
  HANZO_RETURN_IF_ERROR(check.optional_covariance(message.position_covariance, "position_covariance"));
  if (!std::isfinite(message.hdop) || message.hdop < 0.0F) {
    return check.fail("hdop", fmt::format("{} (expected a finite value >= 0)", message.hdop));
  }
  return ok_status();
}

Status validate(const WheelOdometryMessage& message) {
  const Checker check("WheelOdometryMessage");
  HANZO_RETURN_IF_ERROR(check.timestamp(message.timestamp, "timestamp_ns"));
  HANZO_RETURN_IF_ERROR(check.finite(message.left_distance, "left_distance"));
  HANZO_RETURN_IF_ERROR(check.finite(message.right_distance, "right_distance"));
  HANZO_RETURN_IF_ERROR(check.finite(message.wheel_separation, "wheel_separation"));
  HANZO_RETURN_IF_ERROR(check.finite(message.wheel_radius, "wheel_radius"));
  if (message.wheel_separation <= 0.0) {
    return check.fail("wheel_separation", fmt::format("{} m (expected > 0)", message.wheel_separation));
  }
  if (message.wheel_radius < 0.0) return check.fail("wheel_radius", fmt::format("{} m (expected >= 0; 0 = unknown)", message.wheel_radius));
  return ok_status();
}

Status validate(const RadarMessage& message) {
  const Checker check("RadarMessage");
  HANZO_RETURN_IF_ERROR(check.timestamp(message.timestamp, "timestamp_ns"));
  for (size_t i = 0; i < message.targets.size(); ++i) {
    const RadarTarget& target = message.targets[i];
    const auto field = [&](std::string_view name) { return fmt::format("targets[{}].{}", i, name); };
    for (const auto& [name, value] : {std::pair<std::string_view, float>{"range", target.range}, {"azimuth", target.azimuth},
                                      {"elevation", target.elevation}, {"radial_velocity", target.radial_velocity},
                                      {"rcs", target.rcs}}) {
      if (!std::isfinite(value)) return check.finite(value, field(name));
    }
    if (target.range < 0.0F) return check.fail(field("range"), fmt::format("negative range {} m", target.range));
    if (std::abs(target.azimuth) > std::numbers::pi_v<float>) {
      return check.fail(field("azimuth"), fmt::format("{} rad outside [-pi, pi]", target.azimuth));
    }
    if (std::abs(target.elevation) > std::numbers::pi_v<float> / 2.0F) {
      return check.fail(field("elevation"), fmt::format("{} rad outside [-pi/2, pi/2]", target.elevation));
    }
  }
  return ok_status();
}

Status validate(const RangeMessage& message) {
  const Checker check("RangeMessage");
  HANZO_RETURN_IF_ERROR(check.timestamp(message.timestamp, "timestamp_ns"));
  for (const auto& [name, value] : {std::pair<std::string_view, float>{"field_of_view", message.field_of_view}, {"min_range", message.min_range},
                                    {"max_range", message.max_range}, {"variance", message.variance}}) {
    if (!std::isfinite(value)) return check.finite(value, name);
  }
  if (std::isnan(message.range)) return check.fail("range", "NaN (+inf: nothing within max_range, -inf: nearer than min_range)");
  if (message.radiation != RangeRadiation::kUltrasound && message.radiation != RangeRadiation::kInfrared) {
    return check.fail("radiation_type", fmt::format("{} (expected 0 ultrasound or 1 infrared)", static_cast<int>(message.radiation)));
  }
  if (!(message.field_of_view > 0.0F && message.field_of_view < std::numbers::pi_v<float>)) {
    return check.fail("field_of_view", fmt::format("{} rad outside (0, pi)", message.field_of_view));
  }
  if (message.min_range < 0.0F || message.max_range <= message.min_range) {
    return check.fail("max_range", fmt::format("[{}, {}] m is not a range (expected 0 <= min_range < max_range)", message.min_range, message.max_range));
  }
  if (std::isfinite(message.range) && (message.range < message.min_range || message.range > message.max_range)) {
    return check.fail("range", fmt::format("{} m outside [{}, {}] m (use +inf or -inf for no reading)", message.range, message.min_range, message.max_range));
  }
  if (message.variance < 0.0F) return check.fail("variance", fmt::format("negative variance {} m^2", message.variance));
  return ok_status();
}

Status validate(const DetectionsMessage& message) {
  const Checker check("DetectionsMessage");
  HANZO_RETURN_IF_ERROR(check.timestamp(message.timestamp, "timestamp_ns"));
  if (message.image_width == 0 || message.image_height == 0) {
    return check.fail("image_width", fmt::format("image size {} x {}: the detector's image size is required", message.image_width, message.image_height));
  }
  const float width = static_cast<float>(message.image_width), height = static_cast<float>(message.image_height);
  for (std::size_t i = 0; i < message.detections.size(); ++i) {
    const Detection2D& detection = message.detections[i];
    const auto field = [i](std::string_view name) { return fmt::format("detections[{}].{}", i, name); };
    if (detection.class_name.empty()) return check.fail(field("class_name"), "empty");
    if (!(detection.score >= 0.0F && detection.score <= 1.0F)) return check.fail(field("score"), fmt::format("{} outside [0, 1]", detection.score));
    for (const auto& [name, value] : {std::pair<std::string_view, float>{"x_min", detection.x_min}, {"y_min", detection.y_min},
                                      {"x_max", detection.x_max}, {"y_max", detection.y_max}}) {
      if (!std::isfinite(value)) return check.fail(field(name), "not finite");
    }
    if (detection.x_min > detection.x_max || detection.y_min > detection.y_max) {
      return check.fail(field("x_min"), fmt::format("box ({}, {}) - ({}, {}) has its corners swapped", detection.x_min, detection.y_min, detection.x_max, detection.y_max));
    }
    if (detection.x_min < -0.5F || detection.y_min < -0.5F || detection.x_max > width - 0.5F || detection.y_max > height - 0.5F) {
      return check.fail(field("x_max"), fmt::format("box ({}, {}) - ({}, {}) outside the {} x {} image", detection.x_min, detection.y_min, detection.x_max,
                                                    detection.y_max, message.image_width, message.image_height));
    }
    if (detection.mask.size() != static_cast<std::size_t>(detection.mask_width) * detection.mask_height) {
      return check.fail(field("mask"), fmt::format("{} bytes for a {} x {} mask", detection.mask.size(), detection.mask_width, detection.mask_height));
    }
  }
  if (message.segmentation.empty()) {
    if (!message.segmentation_classes.empty()) return check.fail("segmentation", "a label table without a segmentation image");
    return ok_status();
  }
  if (message.segmentation.size() != static_cast<std::size_t>(message.image_width) * message.image_height) {
    return check.fail("segmentation", fmt::format("{} class ids for a {} x {} image", message.segmentation.size(), message.image_width, message.image_height));
  }
  if (message.segmentation_classes.empty() || message.segmentation_classes.size() >= kUnlabelledPixel) {
    return check.fail("segmentation_classes", fmt::format("{} classes: a segmentation needs 1 to {} named classes", message.segmentation_classes.size(),
                                                          kUnlabelledPixel - 1));
  }
  for (std::size_t i = 0; i < message.segmentation_classes.size(); ++i) {
    if (message.segmentation_classes[i].empty()) return check.fail(fmt::format("segmentation_classes[{}]", i), "empty");
  }
  const auto unknown = std::find_if(message.segmentation.begin(), message.segmentation.end(), [&message](uint8_t id) {
    return id != kUnlabelledPixel && id >= message.segmentation_classes.size();
  });
  if (unknown != message.segmentation.end()) {
    const auto pixel = static_cast<std::size_t>(unknown - message.segmentation.begin());
    return check.fail("segmentation", fmt::format("pixel ({}, {}) has class id {}, the label table has {} classes", pixel % message.image_width,
                                                  pixel / message.image_width, *unknown, message.segmentation_classes.size()));
  }
  return ok_status();
}

Status validate(const PoseEstimate& message) {
  const Checker check("PoseEstimate");
  HANZO_RETURN_IF_ERROR(check.timestamp(message.timestamp, "timestamp_ns"));
  HANZO_RETURN_IF_ERROR(check.finite_vector(message.T_world_body.position, "position"));
  HANZO_RETURN_IF_ERROR(check.unit_quaternion(message.T_world_body.orientation, "orientation"));
  HANZO_RETURN_IF_ERROR(check.finite_vector(message.velocity, "velocity"));
  HANZO_RETURN_IF_ERROR(check.optional_covariance(message.pose_covariance, "pose_covariance"));
  return ok_status();
}

Status validate(const Keyframe& message) {
  const Checker check("Keyframe");
  HANZO_RETURN_IF_ERROR(check.timestamp(message.timestamp, "timestamp_ns"));
  HANZO_RETURN_IF_ERROR(check.pose(message.T_world_body, "pose"));
  HANZO_RETURN_IF_ERROR(check.finite_vector(message.velocity, "velocity"));
  HANZO_RETURN_IF_ERROR(check.optional_covariance(message.pose_covariance, "pose_covariance"));
  if (message.T_previous_current) HANZO_RETURN_IF_ERROR(check.pose(*message.T_previous_current, "relative_pose"));
  if (message.relative_covariance && !message.T_previous_current) {
    return check.fail("relative_covariance", "given without a relative_pose");
  }
  HANZO_RETURN_IF_ERROR(check.optional_covariance(message.relative_covariance, "relative_covariance"));
  return ok_status();
}

Status validate(const SensorMessage& message) {
  return std::visit([](const auto& m) { return validate(m); }, message);
}

}  // namespace hanzo::fusion::msgs
