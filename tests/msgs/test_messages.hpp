#pragma once
// Valid example messages with every optional field filled, shared by the msgs tests.

#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::msgs::testing {

inline Timestamp t0() { return Timestamp::from_nanoseconds(1'771'842'930'123'456'789); }

inline Eigen::Matrix3d covariance3() {
  Eigen::Matrix3d m;
  m << 0.04, 0.001, -0.002, 0.001, 0.05, 0.0005, -0.002, 0.0005, 0.09;
  return m;
}

inline Matrix6d covariance6() {
  Matrix6d m = Matrix6d::Identity() * 0.01;
  m(0, 5) = m(5, 0) = 0.0007;
  m(2, 3) = m(3, 2) = -0.0003;
  return m;
}

inline ImuMessage imu() {
  ImuMessage m;
  m.timestamp = t0();
  m.frame_id = "imu_link";
  m.linear_acceleration = {0.1, -0.2, 9.81};
  m.angular_velocity = {0.01, 0.02, -0.03};
  m.acceleration_covariance = covariance3();
  m.gyroscope_covariance = covariance3() * 1e-4;
  m.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()));
  m.orientation_covariance = covariance3() * 1e-3;
  return m;
}

inline PointCloudMessage point_cloud() {
  PointCloudMessage m;
  m.timestamp = t0();
  m.frame_id = "lidar_link";
  for (int i = 0; i < 100; ++i) {
    m.points.emplace_back(0.1F * i, -0.05F * i, 1.5F);
    m.intensities.push_back(static_cast<float>(i) / 100.0F);
    m.ring_ids.push_back(static_cast<uint32_t>(i % 16));
    m.point_timestamps.push_back(t0() + Duration::from_microseconds(i * 10));
  }
  return m;
}

inline ImageMessage image() {
  ImageMessage m;
  m.timestamp = t0();
  m.frame_id = "camera_left_link";
  m.width = 8;
  m.height = 4;
  m.encoding = ImageEncoding::kRgb8;
  m.data.resize(8 * 4 * 3);
  for (size_t i = 0; i < m.data.size(); ++i) m.data[i] = static_cast<uint8_t>(i * 7);
  m.intrinsics = CameraIntrinsics{458.654, 457.296, 3.5, 2.0, 8, 4};
  m.distortion = DistortionModel{DistortionType::kEquidistant, {-0.2834, 0.07395, 0.00019, 0.00001}};
  return m;
}

inline GnssMessage gnss() {
  GnssMessage m;
  m.timestamp = t0();
  m.latitude = 47.378177;
  m.longitude = 8.540192;
  m.altitude = 408.25;
  m.fix_type = GnssFixType::kRtkFixed;
  m.position_covariance = covariance3() * 1e-2;
  m.satellites_used = 14;
  m.hdop = 0.8F;
  return m;
}

inline WheelOdometryMessage wheel_odometry() {
  WheelOdometryMessage m;
  m.timestamp = t0();
  m.frame_id = "base_link";
  m.left_distance = 12.345;
  m.right_distance = 12.678;
  m.wheel_separation = 0.5;
  m.wheel_radius = 0.1;
  return m;
}

inline RadarMessage radar() {
  RadarMessage m;
  m.timestamp = t0();
  m.frame_id = "radar_link";
  m.targets = {{12.5F, 0.1F, -0.02F, -3.2F, 10.5F}, {40.0F, -0.7F, 0.05F, 0.0F, -5.0F}};
  return m;
}

inline RangeMessage range() {
  RangeMessage m;
  m.timestamp = t0();
  m.frame_id = "sonar_link";
  m.field_of_view = 0.26F;
  m.min_range = 0.02F;
  m.max_range = 4.0F;
  m.range = 1.37F;
  m.variance = 1e-4F;
  return m;
}

// A person (box only, tracked) and a car with a 3 x 2 instance mask in a 640 x 480 image.
inline DetectionsMessage detections() {
  DetectionsMessage m;
  m.timestamp = t0();
  m.frame_id = "camera_front";
  m.image_width = 640;
  m.image_height = 480;
  Detection2D person;
  person.class_name = "person";
  person.score = 0.91F;
  person.x_min = 100.25F;
  person.y_min = 50.0F;
  person.x_max = 140.5F;
  person.y_max = 200.0F;
  person.track_id = 17;
  m.detections.push_back(person);
  Detection2D car = person;
  car.class_name = "car";
  car.score = 0.55F;
  car.x_min = 300.0F;
  car.x_max = 420.0F;
  car.track_id = -1;
  car.mask_width = 3;
  car.mask_height = 2;
  car.mask = {0, 255, 255, 255, 255, 0};
  m.detections.push_back(car);
  return m;
}

// A segmenter's output for a 4 x 3 image: floor below, a wall above, a person in the middle,
// one pixel unlabelled.
inline DetectionsMessage segmentation() {
  DetectionsMessage m;
  m.timestamp = t0();
  m.frame_id = "camera_front";
  m.image_width = 4;
  m.image_height = 3;
  m.segmentation_classes = {"floor", "wall", "person"};
  m.segmentation = {1, 1, 1, kUnlabelledPixel, 1, 2, 2, 1, 0, 0, 0, 0};
  return m;
}

inline PoseEstimate pose_estimate() {
  PoseEstimate m;
  m.timestamp = t0();
  m.frame_id = "world";
  m.child_frame_id = "base_link";
  m.T_world_body = Pose::from_se3(SE3(SO3::exp({0.1, -0.2, 0.3}), {1.0, 2.0, 3.0}));
  m.velocity = {0.5, -0.1, 0.02};
  m.pose_covariance = covariance6();
  m.status = {TrackingState::kTracking, 2, {"imu", "gnss"},
              {{"imu", HealthState::kOk, HealthReason::kNone}, {"gnss", HealthState::kDegraded, HealthReason::kNoFix}}};
  return m;
}

inline Keyframe keyframe() {
  Keyframe m;
  m.keyframe_id = 7;
  m.timestamp = t0();
  m.T_world_body = Pose::from_se3(SE3(SO3::exp({0.0, 0.0, 1.0}), {10.0, -5.0, 0.5}));
  m.velocity = {1.0, 0.0, 0.0};
  m.pose_covariance = covariance6();
  m.previous_keyframe_id = 6;
  m.T_previous_current = Pose::from_se3(SE3(SO3::exp({0.0, 0.0, 0.1}), {1.0, 0.0, 0.0}));
  m.relative_covariance = covariance6() * 0.1;
  return m;
}

}  // namespace hanzo::fusion::msgs::testing
