#include "hanzo/fusion/msgs/validate.hpp"

#include <cmath>
#include <functional>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "msgs/test_messages.hpp"

namespace hanzo::fusion::msgs {
namespace {

using ::testing::HasSubstr;
constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Expects validate() to fail naming `field`, with `text` in the message.
template <typename Message>
void expect_rejected(const Message& message, const std::string& field, const std::string& text) {
  const Status status = validate(message);
  ASSERT_FALSE(status.ok()) << "expected rejection of " << field;
  EXPECT_EQ(status.error().field, field) << status.error().message;
  EXPECT_THAT(status.error().message, HasSubstr(text));
}

TEST(Validate, ExampleMessagesAreValid) {
  EXPECT_TRUE(validate(testing::imu()).ok());
  EXPECT_TRUE(validate(testing::point_cloud()).ok());
  EXPECT_TRUE(validate(testing::image()).ok());
  EXPECT_TRUE(validate(testing::gnss()).ok());
  EXPECT_TRUE(validate(testing::wheel_odometry()).ok());
  EXPECT_TRUE(validate(testing::radar()).ok());
  EXPECT_TRUE(validate(testing::range()).ok());
  EXPECT_TRUE(validate(testing::pose_estimate()).ok());
  EXPECT_TRUE(validate(testing::keyframe()).ok());
  EXPECT_TRUE(validate(SensorMessage(testing::gnss())).ok());
}

// A rangefinder's reading: finite within [min_range, max_range] or +-inf (REP 117), never NaN;
// a cone under 180 degrees; a range interval; a known radiation type.
TEST(Validate, RangeReadingsFollowRep117) {
  RangeMessage range = testing::range();
  range.range = static_cast<float>(kInf);
  EXPECT_TRUE(validate(range).ok());
  range.range = -static_cast<float>(kInf);
  EXPECT_TRUE(validate(range).ok());
  range.range = static_cast<float>(kNan);
  expect_rejected(range, "range", "NaN");
  range.range = 5.0F;
  expect_rejected(range, "range", "outside [0.02, 4] m");
  range = testing::range();
  range.field_of_view = 4.0F;
  expect_rejected(range, "field_of_view", "outside (0, pi)");
  range = testing::range();
  range.max_range = 0.01F;
  expect_rejected(range, "max_range", "is not a range");
  range = testing::range();
  range.radiation = static_cast<RangeRadiation>(7);
  expect_rejected(range, "radiation_type", "expected 0 ultrasound or 1 infrared");
  range = testing::range();
  range.variance = -1.0F;
  expect_rejected(range, "variance", "negative");
}

// Why `message` is refused once `edit` changed it ("accepted" when it validates).
std::string refusal(DetectionsMessage message, const std::function<void(DetectionsMessage&)>& edit) {
  edit(message);
  const Status status = validate(message);
  return status.ok() ? std::string("accepted") : status.error().message;
}

// A detector's boxes must lie in its image, be ordered, scored in [0, 1] and named; a mask
// must have its stated size. Each refusal names the detection and field.
TEST(Validate, DetectionsAreBoxesInsideTheirImage) {
  EXPECT_TRUE(validate(testing::detections()).ok());
  const auto refused = [](const std::function<void(DetectionsMessage&)>& edit) { return refusal(testing::detections(), edit); };
  EXPECT_THAT(refused([](DetectionsMessage& m) { m.image_width = 0; }), HasSubstr("image size 0 x 480"));
  EXPECT_THAT(refused([](DetectionsMessage& m) { m.detections[1].class_name.clear(); }), HasSubstr("detections[1].class_name"));
  EXPECT_THAT(refused([](DetectionsMessage& m) { m.detections[0].score = 1.5F; }), HasSubstr("detections[0].score"));
  EXPECT_THAT(refused([](DetectionsMessage& m) { m.detections[0].x_max = std::numeric_limits<float>::quiet_NaN(); }), HasSubstr("not finite"));
  EXPECT_THAT(refused([](DetectionsMessage& m) { std::swap(m.detections[0].y_min, m.detections[0].y_max); }), HasSubstr("corners swapped"));
  EXPECT_THAT(refused([](DetectionsMessage& m) { m.detections[1].x_max = 700.0F; }), HasSubstr("outside the 640 x 480 image"));
  EXPECT_THAT(refused([](DetectionsMessage& m) { m.detections[1].mask.pop_back(); }), HasSubstr("5 bytes for a 3 x 2 mask"));
}

// A segmentation has one class id per pixel, each in its label table (or 255: unlabelled), and a
// table of named classes.
TEST(Validate, SegmentationsHaveAClassOfTheirTablePerPixel) {
  EXPECT_TRUE(validate(testing::segmentation()).ok());
  const auto refused = [](const std::function<void(DetectionsMessage&)>& edit) { return refusal(testing::segmentation(), edit); };
  EXPECT_THAT(refused([](DetectionsMessage& m) { m.segmentation.pop_back(); }), HasSubstr("segmentation: 11 class ids for a 4 x 3 image"));
  EXPECT_THAT(refused([](DetectionsMessage& m) { m.segmentation[6] = 3; }), HasSubstr("pixel (2, 1) has class id 3, the label table has 3 classes"));
  EXPECT_THAT(refused([](DetectionsMessage& m) { m.segmentation_classes.clear(); }), HasSubstr("segmentation_classes: 0 classes"));
  EXPECT_THAT(refused([](DetectionsMessage& m) { m.segmentation_classes[1].clear(); }), HasSubstr("segmentation_classes[1]: empty"));
  EXPECT_THAT(refused([](DetectionsMessage& m) { m.segmentation.clear(); }), HasSubstr("a label table without a segmentation image"));
}

TEST(Validate, ZeroTimestampIsRejectedEverywhere) {
  auto imu = testing::imu();
  imu.timestamp = Timestamp();
  expect_rejected(imu, "timestamp_ns", "ImuMessage.timestamp_ns: zero timestamp");
  auto cloud = testing::point_cloud();
  cloud.timestamp = Timestamp();
  expect_rejected(cloud, "timestamp_ns", "zero timestamp");
  auto image = testing::image();
  image.timestamp = Timestamp();
  expect_rejected(image, "timestamp_ns", "zero timestamp");
  auto gnss = testing::gnss();
  gnss.timestamp = Timestamp();
  expect_rejected(gnss, "timestamp_ns", "zero timestamp");
  auto wheels = testing::wheel_odometry();
  wheels.timestamp = Timestamp();
  expect_rejected(wheels, "timestamp_ns", "zero timestamp");
  auto radar = testing::radar();
  radar.timestamp = Timestamp();
  expect_rejected(SensorMessage(radar), "timestamp_ns", "RadarMessage.timestamp_ns");
  cloud = testing::point_cloud();
  cloud.point_timestamps[3] = Timestamp();
  expect_rejected(cloud, "point_timestamps[3]", "zero timestamp");
}

TEST(Validate, NonFiniteValuesNameTheComponent) {
  auto imu = testing::imu();
  imu.angular_velocity.x() = kNan;
  expect_rejected(imu, "angular_velocity.x", "ImuMessage.angular_velocity.x: non-finite value nan");
  imu = testing::imu();
  imu.linear_acceleration.z() = kInf;
  expect_rejected(imu, "linear_acceleration.z", "non-finite value inf");
  imu = testing::imu();
  (*imu.gyroscope_covariance)(1, 2) = kNan;
  expect_rejected(imu, "gyroscope_covariance.data[5]", "non-finite");
  auto cloud = testing::point_cloud();
  cloud.points[42].y() = std::numeric_limits<float>::quiet_NaN();
  expect_rejected(cloud, "points[42].y", "non-finite");
  auto gnss = testing::gnss();
  gnss.altitude = kNan;
  expect_rejected(gnss, "altitude", "non-finite");
  auto wheels = testing::wheel_odometry();
  wheels.left_distance = kInf;
  expect_rejected(wheels, "left_distance", "non-finite");
  auto radar = testing::radar();
  radar.targets[1].radial_velocity = std::numeric_limits<float>::quiet_NaN();
  expect_rejected(radar, "targets[1].radial_velocity", "non-finite");
  auto pose = testing::pose_estimate();
  pose.velocity.y() = kNan;
  expect_rejected(pose, "velocity.y", "PoseEstimate.velocity.y");
  auto keyframe = testing::keyframe();
  keyframe.T_previous_current->position.x() = kNan;
  expect_rejected(keyframe, "relative_pose.position.x", "non-finite");
}

TEST(Validate, PointCloudArraysMustMatch) {
  auto cloud = testing::point_cloud();
  cloud.points.clear();
  cloud.intensities.clear();
  cloud.ring_ids.clear();
  cloud.point_timestamps.clear();
  expect_rejected(cloud, "points", "empty");
  cloud = testing::point_cloud();
  cloud.intensities.pop_back();
  expect_rejected(cloud, "intensities", "99 values for 100 points");
  cloud = testing::point_cloud();
  cloud.ring_ids.push_back(0);
  expect_rejected(cloud, "ring_ids", "101 values for 100 points");
  cloud = testing::point_cloud();
  cloud.point_timestamps.resize(10);
  expect_rejected(cloud, "point_timestamps", "10 values for 100 points");
  cloud = testing::point_cloud();
  cloud.intensities[5] = 1.5F;
  expect_rejected(cloud, "intensities[5]", "outside [0, 1]");
}

TEST(Validate, ImageBufferMustMatchSizeAndEncoding) {
  auto image = testing::image();
  image.data.pop_back();
  expect_rejected(image, "data", "95 bytes, but 8x4 rgb8 needs 96");
  image = testing::image();
  image.encoding = ImageEncoding::kMono8;
  expect_rejected(image, "data", "8x4 mono8 needs 32");
  image = testing::image();
  image.width = 0;
  expect_rejected(image, "width", "zero");
  image = testing::image();
  image.intrinsics->fx = -1.0;
  expect_rejected(image, "intrinsics.fx", "must be positive");
  image = testing::image();
  image.intrinsics->cx = 100.0;
  expect_rejected(image, "intrinsics.cx", "outside the image width");
  image = testing::image();
  image.distortion->coefficients.pop_back();
  expect_rejected(image, "distortion.coefficients", "equidistant takes 4 coefficients");
  image = testing::image();
  image.distortion->type = DistortionType::kRadtan;
  image.distortion->coefficients.push_back(0.001);
  EXPECT_TRUE(validate(image).ok());  // radtan with 5 coefficients (k3)
}

TEST(Validate, ImpossibleUnits) {
  auto gnss = testing::gnss();
  gnss.latitude = 91.0;
  expect_rejected(gnss, "latitude", "91 outside [-90, 90]");
  gnss = testing::gnss();
  gnss.longitude = -200.0;
  expect_rejected(gnss, "longitude", "outside [-180, 180]");
  gnss = testing::gnss();
  gnss.hdop = -1.0F;
  expect_rejected(gnss, "hdop", "expected a finite value >= 0");
  auto wheels = testing::wheel_odometry();
  wheels.wheel_separation = 0.0;
  expect_rejected(wheels, "wheel_separation", "expected > 0");
  auto radar = testing::radar();
  radar.targets[0].range = -1.0F;
  expect_rejected(radar, "targets[0].range", "negative range");
  radar = testing::radar();
  radar.targets[0].elevation = 2.0F;
  expect_rejected(radar, "targets[0].elevation", "outside [-pi/2, pi/2]");
}

TEST(Validate, CovarianceMustBeSymmetricWithNonNegativeDiagonal) {
  auto gnss = testing::gnss();
  (*gnss.position_covariance)(1, 1) = -0.01;
  expect_rejected(gnss, "position_covariance.data[4]", "negative variance -0.01");
  gnss = testing::gnss();
  (*gnss.position_covariance)(0, 2) = 0.5;
  expect_rejected(gnss, "position_covariance.data[2]", "not symmetric");
  auto pose = testing::pose_estimate();
  (*pose.pose_covariance)(4, 1) = 0.3;
  expect_rejected(pose, "pose_covariance.data[10]", "not symmetric");
}

TEST(Validate, QuaternionsMustBeUnit) {
  auto imu = testing::imu();
  imu.orientation = Eigen::Quaterniond(0.9, 0.0, 0.0, 0.0);
  expect_rejected(imu, "orientation", "has norm 0.9");
  imu = testing::imu();
  imu.orientation.reset();
  expect_rejected(imu, "orientation_covariance", "given without an orientation");
  auto keyframe = testing::keyframe();
  keyframe.T_world_body.orientation = Eigen::Quaterniond(0.0, 0.0, 0.0, 0.0);
  expect_rejected(keyframe, "pose.orientation", "norm 0");
}

}  // namespace
}  // namespace hanzo::fusion::msgs
