#include "hanzo/fusion/msgs/convert.hpp"

#include <google/protobuf/util/message_differencer.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "msgs/test_messages.hpp"

namespace hanzo::fusion::msgs {
namespace {

using ::testing::HasSubstr;
using google::protobuf::util::MessageDifferencer;

// Field-by-field equality of the structs (exact: conversion must be lossless).
bool equal(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) { return a.coeffs() == b.coeffs(); }
bool equal(const Pose& a, const Pose& b) { return a.position == b.position && equal(a.orientation, b.orientation); }

void expect_equal(const ImuMessage& a, const ImuMessage& b) {
  EXPECT_EQ(a.timestamp, b.timestamp);
  EXPECT_EQ(a.frame_id, b.frame_id);
  EXPECT_EQ(a.linear_acceleration, b.linear_acceleration);
  EXPECT_EQ(a.angular_velocity, b.angular_velocity);
  EXPECT_EQ(a.acceleration_covariance, b.acceleration_covariance);
  EXPECT_EQ(a.gyroscope_covariance, b.gyroscope_covariance);
  ASSERT_EQ(a.orientation.has_value(), b.orientation.has_value());
  if (a.orientation) {
    EXPECT_TRUE(equal(*a.orientation, *b.orientation));
  }
  EXPECT_EQ(a.orientation_covariance, b.orientation_covariance);
}

void expect_equal(const PointCloudMessage& a, const PointCloudMessage& b) {
  EXPECT_EQ(a.timestamp, b.timestamp);
  EXPECT_EQ(a.frame_id, b.frame_id);
  EXPECT_EQ(a.points, b.points);
  EXPECT_EQ(a.intensities, b.intensities);
  EXPECT_EQ(a.ring_ids, b.ring_ids);
  EXPECT_EQ(a.point_timestamps, b.point_timestamps);
}

void expect_equal(const ImageMessage& a, const ImageMessage& b) {
  EXPECT_EQ(a.timestamp, b.timestamp);
  EXPECT_EQ(a.frame_id, b.frame_id);
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_EQ(a.encoding, b.encoding);
  EXPECT_EQ(a.data, b.data);
  ASSERT_EQ(a.intrinsics.has_value(), b.intrinsics.has_value());
  if (a.intrinsics) {
    EXPECT_EQ(a.intrinsics->fx, b.intrinsics->fx);
    EXPECT_EQ(a.intrinsics->fy, b.intrinsics->fy);
    EXPECT_EQ(a.intrinsics->cx, b.intrinsics->cx);
    EXPECT_EQ(a.intrinsics->cy, b.intrinsics->cy);
    EXPECT_EQ(a.intrinsics->width, b.intrinsics->width);
    EXPECT_EQ(a.intrinsics->height, b.intrinsics->height);
  }
  ASSERT_EQ(a.distortion.has_value(), b.distortion.has_value());
  if (a.distortion) {
    EXPECT_EQ(a.distortion->type, b.distortion->type);
    EXPECT_EQ(a.distortion->coefficients, b.distortion->coefficients);
  }
}

void expect_equal(const GnssMessage& a, const GnssMessage& b) {
  EXPECT_EQ(a.timestamp, b.timestamp);
  EXPECT_EQ(a.latitude, b.latitude);
  EXPECT_EQ(a.longitude, b.longitude);
  EXPECT_EQ(a.altitude, b.altitude);
  EXPECT_EQ(a.fix_type, b.fix_type);
  EXPECT_EQ(a.position_covariance, b.position_covariance);
  EXPECT_EQ(a.satellites_used, b.satellites_used);
  EXPECT_EQ(a.hdop, b.hdop);
}

void expect_equal(const WheelOdometryMessage& a, const WheelOdometryMessage& b) {
  EXPECT_EQ(a.timestamp, b.timestamp);
  EXPECT_EQ(a.frame_id, b.frame_id);
  EXPECT_EQ(a.left_distance, b.left_distance);
  EXPECT_EQ(a.right_distance, b.right_distance);
  EXPECT_EQ(a.wheel_separation, b.wheel_separation);
  EXPECT_EQ(a.wheel_radius, b.wheel_radius);
}

void expect_equal(const RadarMessage& a, const RadarMessage& b) {
  EXPECT_EQ(a.timestamp, b.timestamp);
  EXPECT_EQ(a.frame_id, b.frame_id);
  ASSERT_EQ(a.targets.size(), b.targets.size());
  for (size_t i = 0; i < a.targets.size(); ++i) {
    EXPECT_EQ(a.targets[i].range, b.targets[i].range);
    EXPECT_EQ(a.targets[i].azimuth, b.targets[i].azimuth);
    EXPECT_EQ(a.targets[i].elevation, b.targets[i].elevation);
    EXPECT_EQ(a.targets[i].radial_velocity, b.targets[i].radial_velocity);
    EXPECT_EQ(a.targets[i].rcs, b.targets[i].rcs);
  }
}

void expect_equal(const RangeMessage& a, const RangeMessage& b) {
  EXPECT_EQ(a.timestamp, b.timestamp);
  EXPECT_EQ(a.frame_id, b.frame_id);
  EXPECT_EQ(a.radiation, b.radiation);
  EXPECT_EQ(a.field_of_view, b.field_of_view);
  EXPECT_EQ(a.min_range, b.min_range);
  EXPECT_EQ(a.max_range, b.max_range);
  EXPECT_EQ(a.range, b.range);
  EXPECT_EQ(a.variance, b.variance);
}

void expect_equal(const DetectionsMessage& a, const DetectionsMessage& b) {
  EXPECT_EQ(a.timestamp, b.timestamp);
  EXPECT_EQ(a.frame_id, b.frame_id);
  EXPECT_EQ(a.image_width, b.image_width);
  EXPECT_EQ(a.image_height, b.image_height);
  ASSERT_EQ(a.detections.size(), b.detections.size());
  for (std::size_t i = 0; i < a.detections.size(); ++i) {
    const Detection2D &x = a.detections[i], &y = b.detections[i];
    EXPECT_EQ(x.class_name, y.class_name);
    EXPECT_EQ(x.score, y.score);
    EXPECT_EQ(x.x_min, y.x_min);
    EXPECT_EQ(x.y_min, y.y_min);
    EXPECT_EQ(x.x_max, y.x_max);
    EXPECT_EQ(x.y_max, y.y_max);
    EXPECT_EQ(x.track_id, y.track_id);
    EXPECT_EQ(x.mask_width, y.mask_width);
    EXPECT_EQ(x.mask_height, y.mask_height);
    EXPECT_EQ(x.mask, y.mask);
  }
  EXPECT_EQ(a.segmentation, b.segmentation);
  EXPECT_EQ(a.segmentation_classes, b.segmentation_classes);
}

void expect_equal(const PoseEstimate& a, const PoseEstimate& b) {
  EXPECT_EQ(a.timestamp, b.timestamp);
  EXPECT_EQ(a.frame_id, b.frame_id);
  EXPECT_EQ(a.child_frame_id, b.child_frame_id);
  EXPECT_TRUE(equal(a.T_world_body, b.T_world_body));
  EXPECT_EQ(a.velocity, b.velocity);
  EXPECT_EQ(a.pose_covariance, b.pose_covariance);
  EXPECT_EQ(a.status.state, b.status.state);
  EXPECT_EQ(a.status.active_modalities, b.status.active_modalities);
  EXPECT_EQ(a.status.active_sensors, b.status.active_sensors);
  ASSERT_EQ(a.status.sensor_health.size(), b.status.sensor_health.size());
  for (std::size_t i = 0; i < a.status.sensor_health.size(); ++i) {
    EXPECT_EQ(a.status.sensor_health[i].sensor, b.status.sensor_health[i].sensor);
    EXPECT_EQ(a.status.sensor_health[i].state, b.status.sensor_health[i].state);
    EXPECT_EQ(a.status.sensor_health[i].reason, b.status.sensor_health[i].reason);
  }
}

void expect_equal(const Keyframe& a, const Keyframe& b) {
  EXPECT_EQ(a.keyframe_id, b.keyframe_id);
  EXPECT_EQ(a.timestamp, b.timestamp);
  EXPECT_TRUE(equal(a.T_world_body, b.T_world_body));
  EXPECT_EQ(a.velocity, b.velocity);
  EXPECT_EQ(a.pose_covariance, b.pose_covariance);
  EXPECT_EQ(a.previous_keyframe_id, b.previous_keyframe_id);
  ASSERT_EQ(a.T_previous_current.has_value(), b.T_previous_current.has_value());
  if (a.T_previous_current) {
    EXPECT_TRUE(equal(*a.T_previous_current, *b.T_previous_current));
  }
  EXPECT_EQ(a.relative_covariance, b.relative_covariance);
}

// struct -> proto -> bytes -> proto -> struct is exact, and proto -> struct -> proto gives the
// same wire bytes.
template <typename Message>
void check_round_trip(const Message& message) {
  const auto proto = to_proto(message);
  std::string bytes;
  ASSERT_TRUE(proto.SerializeToString(&bytes));
  decltype(to_proto(message)) parsed;
  ASSERT_TRUE(parsed.ParseFromString(bytes));
  auto back = from_proto(parsed);
  ASSERT_TRUE(back.ok()) << back.error().message;
  expect_equal(message, back.value());
  const auto again = to_proto(back.value());
  EXPECT_TRUE(MessageDifferencer::Equals(proto, again));
  EXPECT_EQ(again.SerializeAsString(), bytes);
}

TEST(Convert, ImuRoundTrip) {
  check_round_trip(testing::imu());
  ImuMessage without_optionals = testing::imu();
  without_optionals.acceleration_covariance.reset();
  without_optionals.gyroscope_covariance.reset();
  without_optionals.orientation.reset();
  without_optionals.orientation_covariance.reset();
  check_round_trip(without_optionals);
  // Absence stays explicit on the wire.
  const v1::ImuMessage proto = to_proto(without_optionals);
  EXPECT_FALSE(proto.has_orientation());
  EXPECT_FALSE(proto.has_acceleration_covariance());
}

TEST(Convert, PointCloudRoundTrip) {
  check_round_trip(testing::point_cloud());
  PointCloudMessage bare = testing::point_cloud();
  bare.intensities.clear();
  bare.ring_ids.clear();
  bare.point_timestamps.clear();
  check_round_trip(bare);
}

TEST(Convert, PackedPointsCarryTheSameSweepAsPoint3AndReuseTheMessage) {
  const PointCloudMessage sweep = testing::point_cloud();
  v1::PointCloudMessage packed;
  to_proto(sweep, &packed, PointEncoding::kPacked);
  EXPECT_EQ(packed.points_size(), 0);
  ASSERT_EQ(packed.packed_points_size(), static_cast<int>(3 * sweep.points.size()));
  std::string bytes;
  ASSERT_TRUE(packed.SerializeToString(&bytes));
  v1::PointCloudMessage parsed;
  ASSERT_TRUE(parsed.ParseFromString(bytes));
  auto back = from_proto(parsed);
  ASSERT_TRUE(back.ok()) << back.error().message;
  expect_equal(sweep, back.value());
  EXPECT_LT(bytes.size(), to_proto(sweep).SerializeAsString().size());

  // Writing another sweep into the same message replaces everything (either encoding).
  PointCloudMessage shorter = sweep;
  shorter.points.resize(1);
  shorter.intensities.resize(1);
  shorter.ring_ids.resize(1);
  shorter.point_timestamps.resize(1);
  to_proto(shorter, &packed, PointEncoding::kPoint3);
  EXPECT_EQ(packed.packed_points_size(), 0);
  expect_equal(shorter, from_proto(packed).value());
  to_proto(sweep, &packed, PointEncoding::kPacked);
  EXPECT_EQ(packed.points_size(), 0);
  expect_equal(sweep, from_proto(packed).value());
}

TEST(Convert, PackedPointsMustBeTripletsAndNotMixedWithPoint3) {
  v1::PointCloudMessage packed;
  to_proto(testing::point_cloud(), &packed, PointEncoding::kPacked);
  v1::PointCloudMessage ragged = packed;
  ragged.mutable_packed_points()->RemoveLast();
  auto result = from_proto(ragged);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().field, "packed_points");
  EXPECT_THAT(result.error().message, HasSubstr("not x, y, z triplets"));

  v1::PointCloudMessage both = packed;
  both.add_points()->set_x(1.0f);
  result = from_proto(both);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().field, "packed_points");
  EXPECT_THAT(result.error().message, HasSubstr("set one of"));

  v1::PointCloudMessage not_finite = packed;
  not_finite.set_packed_points(4, std::numeric_limits<float>::quiet_NaN());
  EXPECT_FALSE(from_proto(not_finite).ok());  // validated as any sweep
}

TEST(Convert, QuantizedPointsComeBackWithinHalfTheResolutionAndFallBackToPackedFarAway) {
  PointCloudMessage sweep = testing::point_cloud();
  sweep.points.push_back({-120.0004f, 85.2f, -3.0f});  // a far return: large steps either way
  sweep.intensities.push_back(0.5f);
  sweep.ring_ids.push_back(2);
  sweep.point_timestamps.push_back(sweep.point_timestamps.back());
  v1::PointCloudMessage quantized;
  to_proto(sweep, &quantized, PointEncoding::kQuantized, 0.001);
  EXPECT_EQ(quantized.points_size() + quantized.packed_points_size(), 0);
  ASSERT_EQ(quantized.quantized_points_size(), static_cast<int>(3 * sweep.points.size()));
  EXPECT_EQ(quantized.point_resolution(), 0.001);
  EXPECT_LT(quantized.ByteSizeLong(), [&] {
    v1::PointCloudMessage packed;
    to_proto(sweep, &packed, PointEncoding::kPacked);
    return packed.ByteSizeLong();
  }());
  auto back = from_proto(quantized);
  ASSERT_TRUE(back.ok()) << back.error().message;
  ASSERT_EQ(back->points.size(), sweep.points.size());
  for (std::size_t i = 0; i < sweep.points.size(); ++i) EXPECT_LE((back->points[i] - sweep.points[i]).cwiseAbs().maxCoeff(), 0.0005f + 2e-5f) << i;
  EXPECT_EQ(back->point_timestamps, sweep.point_timestamps);

  // Beyond 2^30 resolutions (1074 km at 1 mm), or no usable resolution: packed, exact.
  PointCloudMessage far = sweep;
  far.points[0].x() = 2.0e6f;
  to_proto(far, &quantized, PointEncoding::kQuantized, 0.001);
  EXPECT_EQ(quantized.quantized_points_size(), 0);
  expect_equal(far, from_proto(quantized).value());
  to_proto(sweep, &quantized, PointEncoding::kQuantized, 0.0);
  EXPECT_EQ(quantized.quantized_points_size(), 0);

  // Malformed: not triplets, no resolution, mixed with packed points.
  to_proto(sweep, &quantized, PointEncoding::kQuantized, 0.001);
  v1::PointCloudMessage ragged = quantized;
  ragged.mutable_quantized_points()->RemoveLast();
  EXPECT_EQ(from_proto(ragged).error().field, "quantized_points");
  v1::PointCloudMessage no_resolution = quantized;
  no_resolution.set_point_resolution(0.0);
  EXPECT_EQ(from_proto(no_resolution).error().field, "point_resolution");
  v1::PointCloudMessage mixed = quantized;
  mixed.add_packed_points(1.0f);
  EXPECT_THAT(from_proto(mixed).error().message, HasSubstr("set one of points, packed_points and quantized_points"));
}

TEST(Convert, PackedSweepsCarryPointTimesAsFixedWidthOffsetsWhenTheyFit) {
  PointCloudMessage sweep = testing::point_cloud();
  sweep.point_timestamps[3] = sweep.timestamp - Duration::from_microseconds(250);  // before the stamp: a negative offset
  v1::PointCloudMessage packed;
  to_proto(sweep, &packed, PointEncoding::kPacked);
  EXPECT_EQ(packed.point_timestamps_size(), 0);
  ASSERT_EQ(packed.point_time_offsets_ns_size(), static_cast<int>(sweep.points.size()));
  EXPECT_EQ(packed.point_time_offsets_ns(3), -250000);
  EXPECT_LT(packed.ByteSizeLong(), to_proto(sweep).ByteSizeLong() - 3 * sweep.points.size());
  expect_equal(sweep, from_proto(packed).value());  // exact to the nanosecond

  // A point more than 2.1 s from the stamp: the whole sweep keeps absolute times, still exact.
  PointCloudMessage long_sweep = sweep;
  long_sweep.point_timestamps.back() = sweep.timestamp + Duration::from_seconds(3.0);
  to_proto(long_sweep, &packed, PointEncoding::kPacked);
  EXPECT_EQ(packed.point_time_offsets_ns_size(), 0);
  EXPECT_EQ(packed.point_timestamps_size(), static_cast<int>(sweep.points.size()));
  expect_equal(long_sweep, from_proto(packed).value());
}

TEST(Convert, PointTimeOffsetsAreRefusedWithAbsoluteTimesMiscountedBeforeTheEpochOrOverflowing) {
  v1::PointCloudMessage packed;
  to_proto(testing::point_cloud(), &packed, PointEncoding::kPacked);
  ASSERT_GT(packed.point_time_offsets_ns_size(), 0);

  v1::PointCloudMessage both = packed;
  both.add_point_timestamps(packed.timestamp_ns());
  auto result = from_proto(both);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().field, "point_time_offsets_ns");
  EXPECT_THAT(result.error().message, HasSubstr("not both"));

  v1::PointCloudMessage one_short = packed;
  one_short.mutable_point_time_offsets_ns()->RemoveLast();
  result = from_proto(one_short);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().field, "point_time_offsets_ns");
  EXPECT_THAT(result.error().message, HasSubstr("99 offsets for 100 points"));

  v1::PointCloudMessage before_epoch = packed;
  before_epoch.set_timestamp_ns(1000);
  before_epoch.set_point_time_offsets_ns(7, -1000);
  result = from_proto(before_epoch);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().field, "point_time_offsets_ns[7]");

  v1::PointCloudMessage overflowing = packed;
  overflowing.set_timestamp_ns(static_cast<uint64_t>(std::numeric_limits<int64_t>::max()) - 5);
  result = from_proto(overflowing);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().field, "point_time_offsets_ns");
  EXPECT_THAT(result.error().message, HasSubstr("overflows"));
}

TEST(Convert, ImageRoundTrip) {
  check_round_trip(testing::image());
  ImageMessage depth = testing::image();
  depth.encoding = ImageEncoding::kDepth16;
  depth.data.resize(8 * 4 * 2);
  depth.intrinsics.reset();
  depth.distortion.reset();
  check_round_trip(depth);
}

TEST(Convert, GnssRoundTrip) { check_round_trip(testing::gnss()); }
TEST(Convert, WheelOdometryRoundTrip) { check_round_trip(testing::wheel_odometry()); }
TEST(Convert, RadarRoundTrip) {
  check_round_trip(testing::radar());
  RadarMessage empty = testing::radar();
  empty.targets.clear();
  check_round_trip(empty);
}
// Finite readings, REP 117's +inf (nothing in range) and -inf (too near), infrared.
TEST(Convert, RangeRoundTrip) {
  check_round_trip(testing::range());
  RangeMessage none = testing::range();
  none.range = std::numeric_limits<float>::infinity();
  check_round_trip(none);
  none.range = -std::numeric_limits<float>::infinity();
  none.radiation = RangeRadiation::kInfrared;
  check_round_trip(none);
}
// Boxes, scores, track ids and instance masks; an image without detections; a dense
// segmentation with its label table.
TEST(Convert, DetectionsRoundTrip) {
  check_round_trip(testing::detections());
  DetectionsMessage none = testing::detections();
  none.detections.clear();
  check_round_trip(none);
  check_round_trip(testing::segmentation());
}
TEST(Convert, PoseEstimateRoundTrip) { check_round_trip(testing::pose_estimate()); }
TEST(Convert, KeyframeRoundTrip) {
  check_round_trip(testing::keyframe());
  Keyframe first = testing::keyframe();
  first.previous_keyframe_id = 0;
  first.T_previous_current.reset();
  first.relative_covariance.reset();
  check_round_trip(first);
}

TEST(Convert, RejectsWhatTheStructCannotHold) {
  v1::ImuMessage imu = to_proto(testing::imu());
  imu.mutable_acceleration_covariance()->mutable_data()->RemoveLast();
  auto result = from_proto(imu);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().field, "acceleration_covariance");
  EXPECT_THAT(result.error().message, HasSubstr("8 values (expected 9"));

  imu = to_proto(testing::imu());
  imu.clear_angular_velocity();
  EXPECT_EQ(from_proto(imu).error().field, "angular_velocity");

  imu = to_proto(testing::imu());
  imu.set_timestamp_ns(uint64_t{1} << 63);
  EXPECT_THAT(from_proto(imu).error().message, HasSubstr("beyond the year 2262"));

  v1::ImageMessage image = to_proto(testing::image());
  image.set_encoding("yuv422");
  EXPECT_THAT(from_proto(image).error().message, HasSubstr("unknown encoding 'yuv422'"));

  v1::GnssMessage gnss = to_proto(testing::gnss());
  gnss.set_fix_type(static_cast<v1::GnssFixType>(42));
  EXPECT_EQ(from_proto(gnss).error().field, "fix_type");

  v1::PoseEstimate pose = to_proto(testing::pose_estimate());
  pose.mutable_pose_covariance()->add_data(1.0);
  EXPECT_EQ(from_proto(pose).error().field, "pose_covariance");
  v1::PoseEstimate health = to_proto(testing::pose_estimate());
  health.mutable_status()->mutable_sensor_health(1)->set_state(static_cast<v1::HealthState>(9));
  EXPECT_THAT(from_proto(health).error().message, HasSubstr("unknown health state 9 of sensor 'gnss'"));
}

TEST(Convert, FromProtoValidates) {
  v1::ImuMessage imu = to_proto(testing::imu());
  imu.mutable_linear_acceleration()->set_y(std::numeric_limits<double>::quiet_NaN());
  auto result = from_proto(imu);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().field, "linear_acceleration.y");
}

}  // namespace
}  // namespace hanzo::fusion::msgs
