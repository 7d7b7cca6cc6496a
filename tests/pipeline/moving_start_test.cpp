// Starting the visual-inertial odometry in motion (src/pipeline/moving_start.hpp): the tilt from
// a turning, accelerating IMU; stereo points and the velocity from two stereo frames, exact on
// noise-free data and robust to outlier tracks.

#include <gtest/gtest.h>

#include "hanzo/fusion/estimate/attitude_models.hpp"
#include "hanzo/fusion/estimate/static_alignment.hpp"
#include "moving_start.hpp"
#include "msckf_odometry.hpp"

namespace hanzo::fusion::pipeline {
namespace {

TEST(MovingStart, TiltFromATurningImuWithASmallMeanAcceleration) {
  // Rolled 10 and pitched -5 degrees, yawing at 0.8 rad/s, swaying +-0.5 m/s^2 sideways (mean 0)
  // for one second at 200 Hz.
  const double roll = 10.0 * M_PI / 180.0, pitch = -5.0 * M_PI / 180.0;
  std::vector<estimate::ImuSample> samples;
  for (int i = 0; i <= 200; ++i) {
    const double t = i * 0.005;
    const SO3 R_world_body = estimate::rotation_from_roll_pitch_yaw(roll, pitch, 0.8 * t);
    const Eigen::Vector3d acceleration_world(0.5 * std::sin(2.0 * M_PI * t), 0.0, 0.0);
    estimate::ImuSample sample;
    sample.timestamp = Timestamp::from_seconds(100.0 + t);
    sample.angular_velocity = R_world_body.inverse() * Eigen::Vector3d(0.0, 0.0, 0.8);  // yaw rate in the body
    sample.linear_acceleration = R_world_body.inverse() * (acceleration_world + Eigen::Vector3d(0.0, 0.0, estimate::kStandardGravity));
    samples.push_back(sample);
  }
  const Eigen::Vector3d rpy = estimate::roll_pitch_yaw(tilt_from_moving_imu(samples).matrix());
  EXPECT_NEAR(rpy.x(), roll, 0.3 * M_PI / 180.0);
  EXPECT_NEAR(rpy.y(), pitch, 0.3 * M_PI / 180.0);
  EXPECT_NEAR(rpy.z(), 0.0, 1e-9);
  const SO3 turned = gyro_rotation(samples, samples.front().timestamp, samples.back().timestamp);
  EXPECT_NEAR(turned.log().norm(), 0.8, 1e-3);
}

TEST(MovingStart, StereoVelocityFromTwoFramesDespiteOutliers) {
  // A rig 11 cm wide looking forward (z) from the body, moving at (1.5, 0, 0.4) m/s in the body
  // frame of the second frame and turning 0.05 rad about y between frames 0.1 s apart.
  const SE3 T_body_left(SO3(), Eigen::Vector3d(0.0, 0.0, 0.05));
  const SE3 T_body_right(SO3(), Eigen::Vector3d(0.11, 0.0, 0.05));
  const std::vector<vision::MsckfCamera> cameras{{T_body_left, 400.0}, {T_body_right, 400.0}};
  const SO3 R_previous_current = SO3::exp(Eigen::Vector3d(0.0, 0.05, 0.0));
  const Eigen::Vector3d velocity_current(1.5, 0.0, 0.4);
  const double dt = 0.1;
  const SE3 T_previous_current(R_previous_current, R_previous_current * velocity_current * dt);
  const auto observe = [&](const SE3& T_frame_previous, uint64_t id, const Eigen::Vector3d& point_previous) {
    std::vector<vision::FeatureObservation> observations;
    const Eigen::Vector3d body = T_frame_previous * point_previous;
    for (int camera = 0; camera < 2; ++camera) {
      const Eigen::Vector3d in_camera = cameras[camera].T_body_camera.inverse() * body;
      observations.push_back({id, camera, in_camera.head<2>() / in_camera.z()});
    }
    return observations;
  };
  std::vector<vision::FeatureObservation> previous, current;
  std::map<uint64_t, Eigen::Vector3d> truth;
  for (uint64_t id = 0; id < 40; ++id) {
    const Eigen::Vector3d point(-1.5 + 0.075 * static_cast<double>(id), 0.4 * std::sin(static_cast<double>(id)), 2.0 + 0.05 * static_cast<double>(id));
    truth[id] = point;
    for (const auto& o : observe(SE3(), id, point)) previous.push_back(o);
    // Every fifth track is wrong in the current frame (a mismatch 0.5 m off).
    const Eigen::Vector3d moved = id % 5 == 0 ? point + Eigen::Vector3d(0.5, 0.2, 0.0) : point;
    for (const auto& o : observe(T_previous_current.inverse(), id, moved)) current.push_back(o);
  }
  const auto previous_points = triangulate_stereo(previous, cameras);
  ASSERT_EQ(previous_points.size(), 40u);
  for (const auto& [id, point] : previous_points) EXPECT_LT((point - truth[id]).norm(), 1e-9) << id;
  const auto current_points = triangulate_stereo(current, cameras);
  const std::optional<Eigen::Vector3d> velocity = stereo_velocity(previous_points, current_points, R_previous_current, dt);
  ASSERT_TRUE(velocity.has_value());
  EXPECT_LT((*velocity - velocity_current).norm(), 0.05) << velocity->transpose();

  // Too few shared points, or no time between the frames: none.
  EXPECT_FALSE(stereo_velocity(previous_points, {}, R_previous_current, dt).has_value());
  EXPECT_FALSE(stereo_velocity(previous_points, current_points, R_previous_current, 0.0).has_value());
  // A single camera gives no stereo points.
  EXPECT_TRUE(triangulate_stereo(previous, {cameras[0]}).empty());
}

// A stereo rig moving in front of a blank wall: no tracks for the visual-inertial alignment and
// no stereo points for a velocity; after 1.5 s of frames for the alignment and 2 s of failed
// alignments it starts anyway with the velocity unknown instead of waiting for ever.
TEST(MovingStart, AStereoRigThatSeesNothingStartsWithTheVelocityUnknown) {
  PinholeCamera camera;
  camera.fx = camera.fy = 400.0;
  camera.cx = 319.5;
  camera.cy = 239.5;
  const MsckfRigSetup rig{{{camera, SE3(SO3(), Eigen::Vector3d(0.0, 0.0, 0.05))}, {camera, SE3(SO3(), Eigen::Vector3d(0.11, 0.0, 0.05))}},
                          cv::Size(640, 480)};
  auto odometry = MsckfOdometry::create({rig}, SE3(), estimate::ImuNoise{}).value();
  const cv::Mat blank(480, 640, CV_8UC1, cv::Scalar(128));
  int aligning = 0;
  std::optional<double> started;
  for (int i = 0; i <= 1000; ++i) {  // 5 s at 200 Hz, swaying: 2 m/s^2 and 0.5 rad/s
    const double t = 0.005 * i;
    estimate::ImuSample sample;
    sample.timestamp = Timestamp::from_seconds(50.0 + t);
    sample.angular_velocity = Eigen::Vector3d(0.0, 0.0, 0.5 * std::sin(3.0 * t));
    sample.linear_acceleration = Eigen::Vector3d(2.0 * std::sin(4.0 * t), 0.0, estimate::kStandardGravity);
    odometry->add_imu(sample);
    if (i % 20 != 0 || i == 0) continue;  // frames at 10 Hz
    const MsckfOdometry::Frame frame = odometry->track(sample.timestamp, blank, blank).value();
    if (frame.tracking && !started) started = t;
    if (!frame.tracking && frame.reason.find("aligning the images with the IMU") != std::string::npos) ++aligning;
  }
  ASSERT_TRUE(started.has_value());
  EXPECT_GE(aligning, 25);  // from 0.8 s (the least IMU the static check takes) to the start
  EXPECT_NEAR(*started, 3.6, 0.15);  // the first frame at 0.1 s, its window full at 1.6 s, 2 s of failures
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
