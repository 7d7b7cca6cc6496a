#include "hanzo/fusion/msgs/convert.hpp"

#include <cmath>
#include <algorithm>
#include <limits>

#include <fmt/format.h>

#include "hanzo/fusion/msgs/validate.hpp"
#include "wire_helpers.hpp"

namespace hanzo::fusion::msgs {
namespace {

using wire::write;
using wire::write_time;

// ---- to_proto helpers -------------------------------------------------------------------

template <int N, typename ProtoMatrix>
void write(const Eigen::Matrix<double, N, N>& matrix, ProtoMatrix* out) {
  out->mutable_data()->Reserve(N * N);
  for (int row = 0; row < N; ++row) {
    for (int col = 0; col < N; ++col) out->add_data(matrix(row, col));
  }
}

// ---- from_proto helpers -----------------------------------------------------------------

class Reader {
 public:
  explicit Reader(std::string_view message_name) : message_name_(message_name) {}

  Error fail(std::string_view field, std::string_view what) const {
    return Error{fmt::format("{}.{}: {}", message_name_, field, what), std::string(field)};
  }

  Result<Timestamp> time(uint64_t nanoseconds, std::string_view field) const {
    return wire::read_time(nanoseconds, message_name_, field);
  }

  // A required vector submessage.
  template <typename Message>
  Result<Eigen::Vector3d> vector(bool present, const Message& value, std::string_view field) const {
    if (!present) return fail(field, "missing");
    return Eigen::Vector3d(value.x(), value.y(), value.z());
  }

  // Absent or empty -> nullopt; otherwise exactly N*N values.
  template <int N, typename ProtoMatrix>
  Result<std::optional<Eigen::Matrix<double, N, N>>> matrix(bool present, const ProtoMatrix& value,
                                                            std::string_view field) const {
    using Matrix = Eigen::Matrix<double, N, N>;
    if (!present || value.data_size() == 0) return std::optional<Matrix>();
    if (value.data_size() != N * N) {
      return fail(field, fmt::format("{} values (expected {} for a {}x{} row-major matrix, or none)", value.data_size(),
                                     N * N, N, N));
    }
    Matrix matrix;
    for (int row = 0; row < N; ++row) {
      for (int col = 0; col < N; ++col) matrix(row, col) = value.data(row * N + col);
    }
    return std::optional<Matrix>(matrix);
  }

  Result<Pose> pose(bool present, const v1::Pose& value, std::string_view field) const {
    if (!present) return fail(field, "missing");
    if (!value.has_position()) return fail(fmt::format("{}.position", field), "missing");
    if (!value.has_orientation()) return fail(fmt::format("{}.orientation", field), "missing");
    const v1::Quaternion& q = value.orientation();
    return Pose{{value.position().x(), value.position().y(), value.position().z()}, Eigen::Quaterniond(q.w(), q.x(), q.y(), q.z())};
  }

 private:
  std::string_view message_name_;
};

// Returns the message after validate(), or validate's error.
template <typename Message>
Result<Message> validated(Message message) {
  if (Status status = validate(message); !status) return status.error();
  return message;
}

}  // namespace

// ---- IMU --------------------------------------------------------------------------------

v1::ImuMessage to_proto(const ImuMessage& message) {
  v1::ImuMessage out;
  out.set_timestamp_ns(write_time(message.timestamp));
  out.set_frame_id(message.frame_id);
  write(message.linear_acceleration, out.mutable_linear_acceleration());
  write(message.angular_velocity, out.mutable_angular_velocity());
  if (message.acceleration_covariance) write(*message.acceleration_covariance, out.mutable_acceleration_covariance());
  if (message.gyroscope_covariance) write(*message.gyroscope_covariance, out.mutable_gyroscope_covariance());
  if (message.orientation) write(*message.orientation, out.mutable_orientation());
  if (message.orientation_covariance) write(*message.orientation_covariance, out.mutable_orientation_covariance());
  return out;
}

Result<ImuMessage> from_proto(const v1::ImuMessage& in) {
  const Reader read("ImuMessage");
  ImuMessage message;
  HANZO_ASSIGN_OR_RETURN(message.timestamp, read.time(in.timestamp_ns(), "timestamp_ns"));
  message.frame_id = in.frame_id();
  HANZO_ASSIGN_OR_RETURN(message.linear_acceleration, read.vector(in.has_linear_acceleration(), in.linear_acceleration(), "linear_acceleration"));
  HANZO_ASSIGN_OR_RETURN(message.angular_velocity, read.vector(in.has_angular_velocity(), in.angular_velocity(), "angular_velocity"));
  HANZO_ASSIGN_OR_RETURN(message.acceleration_covariance,
               read.matrix<3>(in.has_acceleration_covariance(), in.acceleration_covariance(), "acceleration_covariance"));
  HANZO_ASSIGN_OR_RETURN(message.gyroscope_covariance, read.matrix<3>(in.has_gyroscope_covariance(), in.gyroscope_covariance(), "gyroscope_covariance"));
  if (in.has_orientation()) {
    const v1::Quaternion& q = in.orientation();
    message.orientation = Eigen::Quaterniond(q.w(), q.x(), q.y(), q.z());
  }
  HANZO_ASSIGN_OR_RETURN(message.orientation_covariance,
               read.matrix<3>(in.has_orientation_covariance(), in.orientation_covariance(), "orientation_covariance"));
  return validated(std::move(message));
}

// ---- Point cloud ------------------------------------------------------------------------

v1::PointCloudMessage to_proto(const PointCloudMessage& message) {
  v1::PointCloudMessage out;
  to_proto(message, &out);
  return out;
}

namespace {

// The points as deltas of multiples of `resolution`; false (out untouched) when a coordinate is
// not finite or lies beyond +-2^30 resolutions.
bool quantize_points(const std::vector<Eigen::Vector3f>& points, double resolution, v1::PointCloudMessage* out) {
  constexpr double kLimit = double{1 << 30};
  for (const Eigen::Vector3f& point : points) {
    if (!((point.cast<double>().array().abs() / resolution) < kLimit).all()) return false;
  }
  out->mutable_quantized_points()->Resize(static_cast<int>(3 * points.size()), 0);
  int32_t* delta = out->mutable_quantized_points()->mutable_data();
  Eigen::Vector3i previous = Eigen::Vector3i::Zero();
  for (const Eigen::Vector3f& point : points) {
    for (int axis = 0; axis < 3; ++axis) {
      const auto steps = static_cast<int32_t>(std::llround(static_cast<double>(point[axis]) / resolution));
      *delta++ = steps - previous[axis];  // |steps| < 2^30: the difference fits
      previous[axis] = steps;
    }
  }
  out->set_point_resolution(resolution);
  return true;
}

}  // namespace

void to_proto(const PointCloudMessage& message, v1::PointCloudMessage* out, PointEncoding encoding, double point_resolution) {
  out->Clear();  // keeps the cleared Point3 objects for add_points() to reuse
  out->set_timestamp_ns(write_time(message.timestamp));
  out->set_frame_id(message.frame_id);
  if (encoding == PointEncoding::kQuantized &&
      !(std::isfinite(point_resolution) && point_resolution > 0 && quantize_points(message.points, point_resolution, out))) {
    encoding = PointEncoding::kPacked;
  }
  if (encoding == PointEncoding::kQuantized) {
    // quantize_points() wrote them.
  } else if (encoding == PointEncoding::kPacked) {
    out->mutable_packed_points()->Resize(static_cast<int>(3 * message.points.size()), 0.0f);
    float* packed = out->mutable_packed_points()->mutable_data();
    for (const Eigen::Vector3f& point : message.points) packed = std::copy_n(point.data(), 3, packed);
  } else {
    out->mutable_points()->Reserve(static_cast<int>(message.points.size()));
    for (const Eigen::Vector3f& point : message.points) {
      v1::Point3* p = out->add_points();
      p->set_x(point.x());
      p->set_y(point.y());
      p->set_z(point.z());
    }
  }
  out->mutable_intensities()->Add(message.intensities.begin(), message.intensities.end());
  out->mutable_ring_ids()->Add(message.ring_ids.begin(), message.ring_ids.end());
  if (encoding != PointEncoding::kPoint3) {
    // Offsets when every point is within their +-2.1 s of the stamp, else the absolute times.
    google::protobuf::RepeatedField<int32_t>& offsets = *out->mutable_point_time_offsets_ns();
    offsets.Resize(static_cast<int>(message.point_timestamps.size()), 0);
    int32_t* offset = offsets.mutable_data();
    for (Timestamp time : message.point_timestamps) {
      const int64_t nanoseconds = (time - message.timestamp).nanoseconds();
      if (nanoseconds < std::numeric_limits<int32_t>::min() || nanoseconds > std::numeric_limits<int32_t>::max()) break;
      *offset++ = static_cast<int32_t>(nanoseconds);
    }
    if (offset == offsets.data() + offsets.size()) return;
    offsets.Clear();
  }
  out->mutable_point_timestamps()->Reserve(static_cast<int>(message.point_timestamps.size()));
  for (Timestamp time : message.point_timestamps) out->add_point_timestamps(write_time(time));
}

Result<PointCloudMessage> from_proto(const v1::PointCloudMessage& in) {
  const Reader read("PointCloudMessage");
  PointCloudMessage message;
  HANZO_ASSIGN_OR_RETURN(message.timestamp, read.time(in.timestamp_ns(), "timestamp_ns"));
  message.frame_id = in.frame_id();
  if ((in.points_size() > 0) + (in.packed_points_size() > 0) + (in.quantized_points_size() > 0) > 1) {
    return read.fail("packed_points", "set one of points, packed_points and quantized_points");
  }
  if (in.packed_points_size() % 3 != 0) {
    return read.fail("packed_points", fmt::format("{} values is not x, y, z triplets", in.packed_points_size()));
  }
  if (in.quantized_points_size() % 3 != 0) {
    return read.fail("quantized_points", fmt::format("{} values is not x, y, z triplets", in.quantized_points_size()));
  }
  if (in.quantized_points_size() > 0 && !(std::isfinite(in.point_resolution()) && in.point_resolution() > 0)) {
    return read.fail("point_resolution", fmt::format("{} m: quantized points need a positive resolution", in.point_resolution()));
  }
  message.points.reserve(static_cast<std::size_t>(in.points_size() + in.packed_points_size() / 3 + in.quantized_points_size() / 3));
  for (const v1::Point3& p : in.points()) message.points.emplace_back(p.x(), p.y(), p.z());
  const float* packed = in.packed_points().data();
  for (int i = 0; i < in.packed_points_size(); i += 3) message.points.emplace_back(packed[i], packed[i + 1], packed[i + 2]);
  Eigen::Matrix<int64_t, 3, 1> steps = Eigen::Matrix<int64_t, 3, 1>::Zero();
  for (int i = 0; i < in.quantized_points_size(); i += 3) {
    for (int axis = 0; axis < 3; ++axis) steps[axis] += in.quantized_points(i + axis);
    message.points.push_back((steps.cast<double>() * in.point_resolution()).cast<float>());
  }
  message.intensities.assign(in.intensities().begin(), in.intensities().end());
  message.ring_ids.assign(in.ring_ids().begin(), in.ring_ids().end());
  if (in.point_timestamps_size() > 0 && in.point_time_offsets_ns_size() > 0) {
    return read.fail("point_time_offsets_ns", "set point_timestamps or point_time_offsets_ns, not both");
  }
  if (in.point_time_offsets_ns_size() > 0 && static_cast<std::size_t>(in.point_time_offsets_ns_size()) != message.points.size()) {
    return read.fail("point_time_offsets_ns", fmt::format("{} offsets for {} points (give one per point or none)",
                                                          in.point_time_offsets_ns_size(), message.points.size()));
  }
  message.point_timestamps.reserve(static_cast<std::size_t>(in.point_timestamps_size() + in.point_time_offsets_ns_size()));
  const int64_t stamp = message.timestamp.nanoseconds();
  if (in.point_time_offsets_ns_size() > 0 && stamp > std::numeric_limits<int64_t>::max() - std::numeric_limits<int32_t>::max()) {
    return read.fail("point_time_offsets_ns", "timestamp_ns plus an offset overflows 64-bit nanoseconds");
  }
  for (int i = 0; i < in.point_time_offsets_ns_size(); ++i) {
    const int64_t nanoseconds = stamp + in.point_time_offsets_ns(i);
    if (nanoseconds <= 0) {
      return read.fail(fmt::format("point_time_offsets_ns[{}]", i), fmt::format("{} ns after timestamp_ns is at or before 1970",
                                                                                  in.point_time_offsets_ns(i)));
    }
    message.point_timestamps.push_back(Timestamp::from_nanoseconds(nanoseconds));
  }
  for (int i = 0; i < in.point_timestamps_size(); ++i) {
    const uint64_t nanoseconds = in.point_timestamps(i);
    if (nanoseconds > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) {  // named only when wrong (hot path)
      return read.time(nanoseconds, fmt::format("point_timestamps[{}]", i)).error();
    }
    message.point_timestamps.push_back(Timestamp::from_nanoseconds(static_cast<int64_t>(nanoseconds)));
  }
  return validated(std::move(message));
}

// ---- Image ------------------------------------------------------------------------------

v1::ImageMessage to_proto(const ImageMessage& message) {
  v1::ImageMessage out;
  out.set_timestamp_ns(write_time(message.timestamp));
  out.set_frame_id(message.frame_id);
  out.set_width(message.width);
  out.set_height(message.height);
  out.set_encoding(std::string(to_string(message.encoding)));
  out.set_data(message.data.data(), message.data.size());
  if (message.intrinsics) {
    v1::CameraIntrinsics* intrinsics = out.mutable_intrinsics();
    intrinsics->set_fx(message.intrinsics->fx);
    intrinsics->set_fy(message.intrinsics->fy);
    intrinsics->set_cx(message.intrinsics->cx);
    intrinsics->set_cy(message.intrinsics->cy);
    intrinsics->set_width(message.intrinsics->width);
    intrinsics->set_height(message.intrinsics->height);
  }
  if (message.distortion) {
    v1::DistortionModel* distortion = out.mutable_distortion();
    switch (message.distortion->type) {
      case DistortionType::kNone: distortion->set_model(v1::DistortionModel::MODEL_NONE); break;
      case DistortionType::kRadtan: distortion->set_model(v1::DistortionModel::MODEL_RADTAN); break;
      case DistortionType::kEquidistant: distortion->set_model(v1::DistortionModel::MODEL_EQUIDISTANT); break;
    }
    distortion->mutable_coefficients()->Add(message.distortion->coefficients.begin(), message.distortion->coefficients.end());
  }
  return out;
}

Result<ImageMessage> from_proto(const v1::ImageMessage& in) {
  const Reader read("ImageMessage");
  ImageMessage message;
  HANZO_ASSIGN_OR_RETURN(message.timestamp, read.time(in.timestamp_ns(), "timestamp_ns"));
  message.frame_id = in.frame_id();
  message.width = in.width();
  message.height = in.height();
  const std::optional<ImageEncoding> encoding = image_encoding_from_string(in.encoding());
  if (!encoding) {
    return read.fail("encoding", fmt::format("unknown encoding '{}' (expected rgb8, bgr8, mono8, depth16 or depth32f)", in.encoding()));
  }
  message.encoding = *encoding;
  if (!in.compression().empty()) {
    return read.fail("compression", fmt::format("a '{}' image: send raw pixels (sensor logs decode their compressed images when read)",
                                                in.compression()));
  }
  message.data.assign(in.data().begin(), in.data().end());
  if (in.has_intrinsics()) {
    const v1::CameraIntrinsics& intrinsics = in.intrinsics();
    message.intrinsics = CameraIntrinsics{intrinsics.fx(), intrinsics.fy(), intrinsics.cx(), intrinsics.cy(), intrinsics.width(), intrinsics.height()};
  }
  if (in.has_distortion()) {
    DistortionModel distortion;
    switch (in.distortion().model()) {
      case v1::DistortionModel::MODEL_NONE: distortion.type = DistortionType::kNone; break;
      case v1::DistortionModel::MODEL_RADTAN: distortion.type = DistortionType::kRadtan; break;
      case v1::DistortionModel::MODEL_EQUIDISTANT: distortion.type = DistortionType::kEquidistant; break;
      default: return read.fail("distortion.model", fmt::format("unknown distortion model {}", static_cast<int>(in.distortion().model())));
    }
    distortion.coefficients.assign(in.distortion().coefficients().begin(), in.distortion().coefficients().end());
    message.distortion = std::move(distortion);
  }
  return validated(std::move(message));
}

// ---- GNSS -------------------------------------------------------------------------------

v1::GnssMessage to_proto(const GnssMessage& message) {
  v1::GnssMessage out;
  out.set_timestamp_ns(write_time(message.timestamp));
  out.set_latitude(message.latitude);
  out.set_longitude(message.longitude);
  out.set_altitude(message.altitude);
  out.set_fix_type(static_cast<v1::GnssFixType>(static_cast<int>(message.fix_type)));
  if (message.position_covariance) write(*message.position_covariance, out.mutable_position_covariance());
  out.set_satellites_used(message.satellites_used);
  out.set_hdop(message.hdop);
  return out;
}

Result<GnssMessage> from_proto(const v1::GnssMessage& in) {
  const Reader read("GnssMessage");
  GnssMessage message;
  HANZO_ASSIGN_OR_RETURN(message.timestamp, read.time(in.timestamp_ns(), "timestamp_ns"));
  message.latitude = in.latitude();
  message.longitude = in.longitude();
  message.altitude = in.altitude();
  if (!v1::GnssFixType_IsValid(in.fix_type())) {
    return read.fail("fix_type", fmt::format("unknown fix type {} (expected NO_FIX, FIX_2D, FIX_3D, RTK_FLOAT or RTK_FIXED)",
                                             static_cast<int>(in.fix_type())));
  }
  message.fix_type = static_cast<GnssFixType>(static_cast<int>(in.fix_type()));
  HANZO_ASSIGN_OR_RETURN(message.position_covariance, read.matrix<3>(in.has_position_covariance(), in.position_covariance(), "position_covariance"));
  message.satellites_used = in.satellites_used();
  message.hdop = in.hdop();
  return validated(std::move(message));
}

// ---- Wheel odometry ---------------------------------------------------------------------

v1::WheelOdometryMessage to_proto(const WheelOdometryMessage& message) {
  v1::WheelOdometryMessage out;
  out.set_timestamp_ns(write_time(message.timestamp));
  out.set_frame_id(message.frame_id);
  out.set_left_distance(message.left_distance);
  out.set_right_distance(message.right_distance);
  out.set_wheel_separation(message.wheel_separation);
  out.set_wheel_radius(message.wheel_radius);
  return out;
}

Result<WheelOdometryMessage> from_proto(const v1::WheelOdometryMessage& in) {
  const Reader read("WheelOdometryMessage");
  WheelOdometryMessage message;
  HANZO_ASSIGN_OR_RETURN(message.timestamp, read.time(in.timestamp_ns(), "timestamp_ns"));
  message.frame_id = in.frame_id();
  message.left_distance = in.left_distance();
  message.right_distance = in.right_distance();
  message.wheel_separation = in.wheel_separation();
  message.wheel_radius = in.wheel_radius();
  return validated(std::move(message));
}

// ---- Radar ------------------------------------------------------------------------------

v1::RadarMessage to_proto(const RadarMessage& message) {
  v1::RadarMessage out;
  out.set_timestamp_ns(write_time(message.timestamp));
  out.set_frame_id(message.frame_id);
  out.mutable_targets()->Reserve(static_cast<int>(message.targets.size()));
  for (const RadarTarget& target : message.targets) {
    v1::RadarTarget* t = out.add_targets();
    t->set_range(target.range);
    t->set_azimuth(target.azimuth);
    t->set_elevation(target.elevation);
    t->set_radial_velocity(target.radial_velocity);
    t->set_rcs(target.rcs);
  }
  return out;
}

Result<RadarMessage> from_proto(const v1::RadarMessage& in) {
  const Reader read("RadarMessage");
  RadarMessage message;
  HANZO_ASSIGN_OR_RETURN(message.timestamp, read.time(in.timestamp_ns(), "timestamp_ns"));
  message.frame_id = in.frame_id();
  message.targets.reserve(in.targets_size());
  for (const v1::RadarTarget& t : in.targets()) {
    message.targets.push_back({t.range(), t.azimuth(), t.elevation(), t.radial_velocity(), t.rcs()});
  }
  return validated(std::move(message));
}

// ---- Range ------------------------------------------------------------------------------

v1::RangeMessage to_proto(const RangeMessage& message) {
  v1::RangeMessage out;
  out.set_timestamp_ns(write_time(message.timestamp));
  out.set_frame_id(message.frame_id);
  out.set_radiation_type(static_cast<uint32_t>(message.radiation));
  out.set_field_of_view(message.field_of_view);
  out.set_min_range(message.min_range);
  out.set_max_range(message.max_range);
  out.set_range(message.range);
  out.set_variance(message.variance);
  return out;
}

Result<RangeMessage> from_proto(const v1::RangeMessage& in) {
  const Reader read("RangeMessage");
  RangeMessage message;
  HANZO_ASSIGN_OR_RETURN(message.timestamp, read.time(in.timestamp_ns(), "timestamp_ns"));
  message.frame_id = in.frame_id();
  message.radiation = static_cast<RangeRadiation>(std::min<uint32_t>(in.radiation_type(), 255));
  message.field_of_view = in.field_of_view();
  message.min_range = in.min_range();
  message.max_range = in.max_range();
  message.range = in.range();
  message.variance = in.variance();
  return validated(std::move(message));
}

// ---- Detections -------------------------------------------------------------------------

v1::DetectionsMessage to_proto(const DetectionsMessage& message) {
  v1::DetectionsMessage out;
  out.set_timestamp_ns(write_time(message.timestamp));
  out.set_frame_id(message.frame_id);
  out.set_image_width(message.image_width);
  out.set_image_height(message.image_height);
  for (const Detection2D& detection : message.detections) {
    v1::Detection2D* d = out.add_detections();
    d->set_class_name(detection.class_name);
    d->set_score(detection.score);
    d->set_x_min(detection.x_min);
    d->set_y_min(detection.y_min);
    d->set_x_max(detection.x_max);
    d->set_y_max(detection.y_max);
    d->set_track_id(detection.track_id);
    d->set_mask_width(detection.mask_width);
    d->set_mask_height(detection.mask_height);
    d->set_mask(detection.mask.data(), detection.mask.size());
  }
  out.set_segmentation(message.segmentation.data(), message.segmentation.size());
  for (const std::string& name : message.segmentation_classes) out.add_segmentation_classes(name);
  return out;
}

Result<DetectionsMessage> from_proto(const v1::DetectionsMessage& in) {
  const Reader read("DetectionsMessage");
  DetectionsMessage message;
  HANZO_ASSIGN_OR_RETURN(message.timestamp, read.time(in.timestamp_ns(), "timestamp_ns"));
  message.frame_id = in.frame_id();
  message.image_width = in.image_width();
  message.image_height = in.image_height();
  message.detections.reserve(in.detections_size());
  for (const v1::Detection2D& d : in.detections()) {
    Detection2D& detection = message.detections.emplace_back();
    detection.class_name = d.class_name();
    detection.score = d.score();
    detection.x_min = d.x_min();
    detection.y_min = d.y_min();
    detection.x_max = d.x_max();
    detection.y_max = d.y_max();
    detection.track_id = d.track_id();
    detection.mask_width = d.mask_width();
    detection.mask_height = d.mask_height();
    detection.mask.assign(d.mask().begin(), d.mask().end());
  }
  message.segmentation.assign(in.segmentation().begin(), in.segmentation().end());
  message.segmentation_classes.assign(in.segmentation_classes().begin(), in.segmentation_classes().end());
  return validated(std::move(message));
}

// ---- Pose estimate and keyframe ---------------------------------------------------------

v1::PoseEstimate to_proto(const PoseEstimate& message) {
  v1::PoseEstimate out;
  out.set_timestamp_ns(write_time(message.timestamp));
  out.set_frame_id(message.frame_id);
  out.set_child_frame_id(message.child_frame_id);
  write(message.T_world_body.position, out.mutable_position());
  write(message.T_world_body.orientation, out.mutable_orientation());
  write(message.velocity, out.mutable_velocity());
  if (message.pose_covariance) write(*message.pose_covariance, out.mutable_pose_covariance());
  v1::PoseStatus* status = out.mutable_status();
  status->set_state(static_cast<v1::TrackingState>(static_cast<int>(message.status.state)));
  status->set_active_modalities(message.status.active_modalities);
  for (const std::string& sensor : message.status.active_sensors) status->add_active_sensors(sensor);
  for (const SensorHealthStatus& health : message.status.sensor_health) {
    v1::SensorHealth* entry = status->add_sensor_health();
    entry->set_sensor(health.sensor);
    entry->set_state(static_cast<v1::HealthState>(static_cast<int>(health.state) + 1));
    entry->set_reason(static_cast<v1::HealthReason>(static_cast<int>(health.reason)));
  }
  return out;
}

Result<PoseEstimate> from_proto(const v1::PoseEstimate& in) {
  const Reader read("PoseEstimate");
  PoseEstimate message;
  HANZO_ASSIGN_OR_RETURN(message.timestamp, read.time(in.timestamp_ns(), "timestamp_ns"));
  message.frame_id = in.frame_id();
  message.child_frame_id = in.child_frame_id();
  HANZO_ASSIGN_OR_RETURN(message.T_world_body.position, read.vector(in.has_position(), in.position(), "position"));
  if (!in.has_orientation()) return read.fail("orientation", "missing");
  const v1::Quaternion& q = in.orientation();
  message.T_world_body.orientation = Eigen::Quaterniond(q.w(), q.x(), q.y(), q.z());
  HANZO_ASSIGN_OR_RETURN(message.velocity, read.vector(in.has_velocity(), in.velocity(), "velocity"));
  HANZO_ASSIGN_OR_RETURN(message.pose_covariance, read.matrix<6>(in.has_pose_covariance(), in.pose_covariance(), "pose_covariance"));
  if (!v1::TrackingState_IsValid(in.status().state())) {
    return read.fail("status.state", fmt::format("unknown tracking state {}", static_cast<int>(in.status().state())));
  }
  message.status.state = static_cast<TrackingState>(static_cast<int>(in.status().state()));
  message.status.active_modalities = in.status().active_modalities();
  message.status.active_sensors.assign(in.status().active_sensors().begin(), in.status().active_sensors().end());
  for (const v1::SensorHealth& entry : in.status().sensor_health()) {
    if (!v1::HealthState_IsValid(entry.state()) || entry.state() == v1::HEALTH_STATE_UNSPECIFIED) {
      return read.fail("status.sensor_health.state", fmt::format("unknown health state {} of sensor '{}'", static_cast<int>(entry.state()), entry.sensor()));
    }
    if (!v1::HealthReason_IsValid(entry.reason())) {
      return read.fail("status.sensor_health.reason", fmt::format("unknown health reason {} of sensor '{}'", static_cast<int>(entry.reason()), entry.sensor()));
    }
    message.status.sensor_health.push_back(
        {entry.sensor(), static_cast<HealthState>(static_cast<int>(entry.state()) - 1), static_cast<HealthReason>(static_cast<int>(entry.reason()))});
  }
  return validated(std::move(message));
}

v1::Keyframe to_proto(const Keyframe& message) {
  v1::Keyframe out;
  out.set_keyframe_id(message.keyframe_id);
  out.set_timestamp_ns(write_time(message.timestamp));
  write(message.T_world_body, out.mutable_pose());
  write(message.velocity, out.mutable_velocity());
  if (message.pose_covariance) write(*message.pose_covariance, out.mutable_pose_covariance());
  out.set_previous_keyframe_id(message.previous_keyframe_id);
  if (message.T_previous_current) write(*message.T_previous_current, out.mutable_relative_pose());
  if (message.relative_covariance) write(*message.relative_covariance, out.mutable_relative_covariance());
  return out;
}

Result<Keyframe> from_proto(const v1::Keyframe& in) {
  const Reader read("Keyframe");
  Keyframe message;
  message.keyframe_id = in.keyframe_id();
  HANZO_ASSIGN_OR_RETURN(message.timestamp, read.time(in.timestamp_ns(), "timestamp_ns"));
  HANZO_ASSIGN_OR_RETURN(message.T_world_body, read.pose(in.has_pose(), in.pose(), "pose"));
  HANZO_ASSIGN_OR_RETURN(message.velocity, read.vector(in.has_velocity(), in.velocity(), "velocity"));
  HANZO_ASSIGN_OR_RETURN(message.pose_covariance, read.matrix<6>(in.has_pose_covariance(), in.pose_covariance(), "pose_covariance"));
  message.previous_keyframe_id = in.previous_keyframe_id();
  if (in.has_relative_pose()) {
    Pose relative;
    HANZO_ASSIGN_OR_RETURN(relative, read.pose(true, in.relative_pose(), "relative_pose"));
    message.T_previous_current = relative;
  }
  HANZO_ASSIGN_OR_RETURN(message.relative_covariance,
               read.matrix<6>(in.has_relative_covariance(), in.relative_covariance(), "relative_covariance"));
  return validated(std::move(message));
}

}  // namespace hanzo::fusion::msgs
