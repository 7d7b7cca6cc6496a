// pipeline::Frontend on synthetic data (a robot standing 2 s, then accelerating east to 1 m/s):
// every input rejection with its reason, late messages fused by rollback exactly as if they had
// come in order, deterministic replay, sensor timeouts and the modality status.

#include <cmath>
#include <gtest/gtest.h>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/pipeline/frontend.hpp"

namespace hanzo::fusion::pipeline {
namespace {

constexpr int64_t kStart = 1'700'000'000'000'000'000;
const GeodeticPoint kDatum{48.0, 11.0, 500.0};

Timestamp at(double seconds) { return Timestamp::from_nanoseconds(kStart + static_cast<int64_t>(seconds * 1e9)); }
// m driven: still until 2 s, 0.5 m/s^2 until 4 s, then 1 m/s.
double distance_at(double t) { return t < 2.0 ? 0.0 : t < 4.0 ? 0.25 * (t - 2.0) * (t - 2.0) : 1.0 + (t - 4.0); }
double acceleration_at(double t) { return t >= 2.0 && t < 4.0 ? 0.5 : 0.0; }

config::FusionConfig fusion_config() {
  config::FusionConfig config;
  config.frontend.datum = kDatum;
  config.frontend.initial_yaw = 0.0;  // the test drives go east from a known start heading
  config.frontend.covariance.process_noise_accel = 0.05;
  config.frontend.covariance.process_noise_gyro = 0.002;
  config.sensors.push_back({"imu", config::SensorModality::kImu, "/imu", 100.0, "imu_link", "", {}});
  config.sensors.push_back({"wheels", config::SensorModality::kWheelOdometry, "/wheels", 50.0, "base_link", "", {}});
  config.sensors.push_back({"gnss", config::SensorModality::kGnss, "/gnss", 5.0, "gnss_link", "", {}});
  config.sensors.push_back({"lidar", config::SensorModality::kLidar, "/lidar", 10.0, "lidar_link", "", {}});
  return config;
}

msgs::ImuMessage imu_at(double t) {
  msgs::ImuMessage imu;
  imu.timestamp = at(t);
  imu.linear_acceleration = Eigen::Vector3d(acceleration_at(t), 0.0, 9.80665);
  return imu;
}

msgs::WheelOdometryMessage wheels_at(double t) {
  msgs::WheelOdometryMessage wheels;
  wheels.timestamp = at(t);
  wheels.left_distance = wheels.right_distance = distance_at(t);
  wheels.wheel_separation = 0.5;
  return wheels;
}

// A 3D fix at an ENU position of the datum (0.5 m sigma).
msgs::GnssMessage gnss_at_position(double t, const Eigen::Vector3d& position_enu) {
  const EnuFrame enu = EnuFrame::create(kDatum).value();
  const GeodeticPoint point = enu.to_geodetic(position_enu);
  msgs::GnssMessage gnss;
  gnss.timestamp = at(t);
  gnss.latitude = point.latitude_deg;
  gnss.longitude = point.longitude_deg;
  gnss.altitude = point.altitude_m;
  gnss.fix_type = msgs::GnssFixType::kFix3d;
  gnss.position_covariance = Eigen::Matrix3d::Identity() * 0.25;
  return gnss;
}

msgs::GnssMessage gnss_at(double t, double east_offset = 0.0) {
  return gnss_at_position(t, Eigen::Vector3d(distance_at(t) + east_offset, 0.0, 0.0));
}

struct Message {
  std::string sensor;
  msgs::SensorMessage message;
};

// Every message of `seconds` of driving in time order (IMU 100 Hz, wheels 50 Hz, GNSS 5 Hz).
std::vector<Message> drive(double seconds) {
  std::vector<Message> messages;
  for (int k = 1; k * 0.01 <= seconds + 1e-9; ++k) {
    const double t = k * 0.01;
    messages.push_back({"imu", imu_at(t)});
    if (k % 2 == 0) messages.push_back({"wheels", wheels_at(t + 0.001)});
    if (k % 20 == 0) messages.push_back({"gnss", gnss_at(t + 0.002)});
  }
  return messages;
}

std::unique_ptr<Frontend> make_session() {
  auto session = Frontend::create(fusion_config(), calib::Calibration{});
  EXPECT_TRUE(session.ok()) << session.error().message;
  return std::move(session).value();
}

// The typed reason's name; the message for people starts with it.
std::string reason_of(const PushStatus& status) {
  if (status) return "ok";
  const std::string name(to_string(status.reason()));
  EXPECT_EQ(status.error().message.rfind(name + ": ", 0), 0U) << status.error().message;
  return name;
}

TEST(Frontend, TracksTheDriveWithTwoModalities) {
  auto session = make_session();
  for (const Message& m : drive(10.0)) ASSERT_TRUE(session->push(m.sensor, m.message).ok());
  const msgs::PoseEstimate pose = session->latest_pose().value();
  EXPECT_NEAR(pose.T_world_body.position.x(), 7.0, 0.05);
  EXPECT_NEAR(pose.T_world_body.position.y(), 0.0, 0.05);
  EXPECT_NEAR(pose.velocity.x(), 1.0, 0.02);
  EXPECT_EQ(pose.status.state, msgs::TrackingState::kDegraded);  // the lidar never reported
  EXPECT_EQ(pose.status.active_modalities, 3U);                  // imu, wheels, gnss
  EXPECT_TRUE(pose.status.localization_reliable());
  SessionSummary summary = session->summary();
  EXPECT_EQ(summary.sensors[2].fused, 44U);  // the last fix waits for the IMU to reach its time
  session->flush();                          // end of the data: fuse what waits
  summary = session->summary();
  EXPECT_EQ(summary.poses, 1000U - 100U);  // one per IMU message after 1 s of alignment
  EXPECT_GT(summary.zero_velocity_updates, 40U);  // standing still from 1 s to 2 s
  EXPECT_EQ(summary.sensors[2].fused, 45U);        // the 5 fixes before alignment ended are not fused
  EXPECT_EQ(summary.sensors[2].rejected.at(Rejection::kBeforeInitialization), 5U);
}

TEST(Frontend, RejectsBadInputWithAReasonAndKeepsRunning) {
  auto session = make_session();
  const std::vector<Message> messages = drive(3.0);
  for (const Message& m : messages) ASSERT_TRUE(session->push(m.sensor, m.message).ok());
  const msgs::PoseEstimate before = session->latest_pose().value();

  EXPECT_EQ(reason_of(session->push("sonar", imu_at(3.5))), "unknown_sensor");
  EXPECT_EQ(reason_of(session->push("imu", gnss_at(3.5))), "wrong_type");
  msgs::ImuMessage nan = imu_at(3.5);
  nan.angular_velocity.x() = std::nan("");
  const PushStatus invalid = session->push("imu", nan);
  EXPECT_EQ(reason_of(invalid), "invalid");
  EXPECT_NE(invalid.error().message.find("angular_velocity.x"), std::string::npos);
  EXPECT_EQ(reason_of(session->push("imu", imu_at(3.0))), "duplicate");
  EXPECT_EQ(reason_of(session->push("imu", imu_at(2.5))), "out_of_order");
  EXPECT_EQ(reason_of(session->push("wheels", wheels_at(1000.0))), "future_dated");
  EXPECT_EQ(reason_of(session->push("gnss", gnss_at(1.0))), "out_of_order");  // older than the previous fix
  EXPECT_EQ(reason_of(session->push_pose("lidar", at(1.0), SE3(), msgs::Matrix6d::Identity())), "too_late");  // 2 s late, window 0.5 s
  EXPECT_EQ(session->latest_pose()->T_world_body.position, before.T_world_body.position);

  const SessionSummary summary = session->summary();
  EXPECT_EQ(summary.sensors[0].rejected.at(Rejection::kInvalid), 1U);
  EXPECT_EQ(summary.sensors[0].rejected.at(Rejection::kDuplicate), 1U);
  EXPECT_EQ(summary.sensors[0].rejected.at(Rejection::kOutOfOrder), 1U);
  EXPECT_EQ(summary.sensors[1].rejected.at(Rejection::kFutureDated), 1U);
  EXPECT_EQ(summary.sensors[2].rejected.at(Rejection::kOutOfOrder), 1U);
  EXPECT_EQ(summary.sensors[3].rejected.at(Rejection::kTooLate), 1U);
  // The session keeps running.
  ASSERT_TRUE(session->push("imu", imu_at(3.01)).ok());
  EXPECT_EQ(session->latest_pose()->timestamp, at(3.01));
}

TEST(Frontend, RefusesACalibrationThatLeavesASensorOutOrACameraWithoutIntrinsics) {
  // No calibration at all: every sensor at the body origin (with a warning).
  EXPECT_TRUE(Frontend::create(fusion_config(), calib::Calibration{}).ok());
  // A calibration that names some sensors but not the GNSS: refused, naming the key to add.
  calib::Calibration partial;
  for (const char* sensor : {"imu", "wheels", "lidar"}) partial.sensors.push_back(calib::SensorCalibration::from_transform(sensor, SE3()));
  const auto refused = Frontend::create(fusion_config(), partial);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("no 'gnss_to_body' entry for sensor 'gnss'"), std::string::npos) << refused.error().message;
  EXPECT_EQ(refused.error().field, "gnss_to_body");
  // An explicit identity is an entry: accepted.
  const calib::Calibration explicit_identity =
      calib::parse_calibration("calibration:\n  imu_to_body: identity\n  wheels_to_body: identity\n  lidar_to_body: identity\n"
                               "  gnss_to_body: identity\n",
                               "identity.yaml")
          .value();
  EXPECT_EQ(explicit_identity.find("gnss")->T_body_sensor().translation().norm(), 0.0);
  EXPECT_TRUE(Frontend::create(fusion_config(), explicit_identity).ok());
  // A camera without intrinsics would give no pose from any image: refused by name.
  config::FusionConfig with_camera = fusion_config();
  with_camera.sensors.push_back({"camera", config::SensorModality::kCamera, "/camera", 20.0, "camera_link", "", {}});
  calib::Calibration no_intrinsics = explicit_identity;
  no_intrinsics.sensors.push_back(calib::SensorCalibration::from_transform("camera", SE3()));
  const auto blind = Frontend::create(with_camera, no_intrinsics);
  ASSERT_FALSE(blind.ok());
  EXPECT_NE(blind.error().message.find("camera 'camera' has no intrinsics"), std::string::npos) << blind.error().message;
  EXPECT_EQ(blind.error().field, "camera_to_body.intrinsics");
}

TEST(Frontend, AGnssJumpOf50MetersIsGatedAndTheEstimateDoesNotMove) {
  auto session = make_session();
  for (const Message& m : drive(5.0)) ASSERT_TRUE(session->push(m.sensor, m.message).ok());
  ASSERT_TRUE(session->push("imu", imu_at(5.01)).ok());
  const msgs::PoseEstimate before = session->latest_pose().value();
  ASSERT_TRUE(session->push("gnss", gnss_at(5.005, 50.0)).ok());  // accepted input, rejected by the gate
  ASSERT_TRUE(session->push("imu", imu_at(5.02)).ok());
  const msgs::PoseEstimate after = session->latest_pose().value();
  EXPECT_EQ(session->summary().sensors[2].rejected.at(Rejection::kGated), 1U);
  // Only the 10 ms of motion between the two poses: no pull towards the jump.
  EXPECT_NEAR(after.T_world_body.position.x() - before.T_world_body.position.x(), 0.01, 0.002);
}

// Frontend::set_gnss_positions_to_backend: fixes drifting east of the drive (0.2 m/s from 2 s
// on) pass the gate and go to the GNSS callback, and the filter stays on the IMU and the wheels
// (fused, it moves onto them); a 50 m jump is gated and not passed on.
TEST(Frontend, GnssPositionsForTheBackendAreGatedAndPassedOnWithoutMovingTheFilter) {
  const auto drift = [](double t) { return t > 2.0 ? 0.2 * (t - 2.0) : 0.0; };
  const auto east_after = [&drift](bool to_backend, std::vector<FusedGnssFix>& fixes) {
    auto session = make_session();
    session->set_gnss_positions_to_backend(to_backend);
    session->set_gnss_callback([&fixes](const FusedGnssFix& fix) { fixes.push_back(fix); });
    for (const Message& m : drive(6.0)) {
      msgs::SensorMessage message = m.message;
      if (m.sensor == "gnss") {
        const double t = (std::get<msgs::GnssMessage>(message).timestamp - at(0.0)).seconds();
        message = gnss_at(t, drift(t));
      }
      EXPECT_TRUE(session->push(m.sensor, message).ok());
    }
    EXPECT_TRUE(session->push("imu", imu_at(6.004)).ok());  // the last fix (6.002 s) is fused
    const std::size_t reported = fixes.size();
    EXPECT_TRUE(session->push("gnss", gnss_at(6.005, 50.0)).ok());
    EXPECT_TRUE(session->push("imu", imu_at(6.01)).ok());
    EXPECT_EQ(fixes.size(), reported) << "the jump was passed on";
    EXPECT_EQ(session->summary().sensors[2].rejected.at(Rejection::kGated), 1U);
    return session->latest_pose().value().T_world_body.position.x() - distance_at(6.01);
  };
  std::vector<FusedGnssFix> fused, passed_on;
  const double east_fused = east_after(false, fused);
  const double east_passed_on = east_after(true, passed_on);
  EXPECT_GT(east_fused, 0.25);               // pulled towards the fixes (0.8 m east by now; 0.33 m)
  EXPECT_NEAR(east_passed_on, 0.0, 0.05);    // the IMU and the wheels only
  EXPECT_EQ(passed_on.size(), fused.size());  // the same fixes pass the gate
  ASSERT_FALSE(passed_on.empty());
  const double last = (passed_on.back().timestamp - at(0.0)).seconds();
  EXPECT_NEAR(passed_on.back().antenna_world.x(), distance_at(last) + drift(last), 1e-6);
}

TEST(Frontend, AnImuSpikeIsRejectedAndTheEstimateDoesNotMove) {
  std::vector<Message> clean = drive(5.0);
  std::vector<Message> spiked;
  for (const Message& m : clean) {
    spiked.push_back(m);
    if (m.sensor == "imu" && msgs::timestamp_of(m.message) == at(4.0)) {
      msgs::ImuMessage spike = imu_at(4.005);
      spike.linear_acceleration = Eigen::Vector3d(60.0, -40.0, 9.8);
      spike.angular_velocity = Eigen::Vector3d(0.0, 0.0, 25.0);
      spiked.push_back({"imu", spike});
    }
  }
  auto clean_session = make_session();
  auto spiked_session = make_session();
  for (const Message& m : clean) ASSERT_TRUE(clean_session->push(m.sensor, m.message).ok());
  for (const Message& m : spiked) ASSERT_TRUE(spiked_session->push(m.sensor, m.message).ok());
  EXPECT_EQ(spiked_session->summary().sensors[0].rejected.at(Rejection::kSpike), 1U);
  EXPECT_EQ(spiked_session->summary().poses, clean_session->summary().poses);  // no pose for the dropped sample
  // The spike is dropped: the estimate is exactly the one without it.
  EXPECT_EQ(spiked_session->latest_pose()->T_world_body.position, clean_session->latest_pose()->T_world_body.position);
  EXPECT_EQ(spiked_session->latest_pose()->velocity, clean_session->latest_pose()->velocity);
}

TEST(Frontend, LateMessagesInsideTheLagWindowGiveTheInOrderResult) {
  std::vector<Message> in_order = drive(6.0);
  // Delay every GNSS fix by 0.3 s of arrival (inside the 0.5 s lag window).
  std::vector<Message> delayed;
  std::vector<std::pair<double, Message>> held;
  for (const Message& m : in_order) {
    const double t = (msgs::timestamp_of(m.message) - at(0)).seconds();
    while (!held.empty() && held.front().first <= t) {
      delayed.push_back(held.front().second);
      held.erase(held.begin());
    }
    if (m.sensor == "gnss") {
      held.emplace_back(t + 0.3, m);
    } else {
      delayed.push_back(m);
    }
  }
  for (const auto& [arrival, m] : held) delayed.push_back(m);
  auto ordered_session = make_session();
  auto delayed_session = make_session();
  for (const Message& m : in_order) ASSERT_TRUE(ordered_session->push(m.sensor, m.message).ok());
  for (const Message& m : delayed) ASSERT_TRUE(delayed_session->push(m.sensor, m.message).ok());
  const msgs::PoseEstimate a = ordered_session->latest_pose().value();
  const msgs::PoseEstimate b = delayed_session->latest_pose().value();
  EXPECT_EQ(a.timestamp, b.timestamp);
  EXPECT_NEAR((a.T_world_body.position - b.T_world_body.position).norm(), 0.0, 1e-9);
  EXPECT_GT(delayed_session->summary().rollbacks, 20U);
  EXPECT_EQ(delayed_session->summary().sensors[2].fused, ordered_session->summary().sensors[2].fused);
}

// The IMU's stream runs 0.3 s behind the others (separate gRPC streams replayed as fast as
// possible): the wheels, waiting for the IMU only up to its 0.1 s timeout, are fused ahead of
// it and every IMU message comes late. Each still gives its pose, as of its own time and equal
// to the in-order pose at that time, and the pose stream stays in time order.
TEST(Frontend, ALaggingImuStreamStillGivesOnePosePerImuMessageInTimeOrder) {
  const std::vector<Message> in_order = drive(6.0);
  std::vector<Message> imu_behind;
  std::vector<Message> held;  // IMU messages, in order
  for (const Message& m : in_order) {
    const Timestamp t = msgs::timestamp_of(m.message);
    while (!held.empty() && (t - msgs::timestamp_of(held.front().message)).seconds() >= 0.3) {
      imu_behind.push_back(held.front());
      held.erase(held.begin());
    }
    (m.sensor == "imu" ? held : imu_behind).push_back(m);
  }
  imu_behind.insert(imu_behind.end(), held.begin(), held.end());

  const auto run = [](const std::vector<Message>& messages, std::vector<msgs::PoseEstimate>& poses) {
    auto session = make_session();
    session->set_pose_callback([&poses](const msgs::PoseEstimate& pose) { poses.push_back(pose); });
    for (const Message& m : messages) EXPECT_TRUE(session->push(m.sensor, m.message).ok());
    return session->summary();
  };
  std::vector<msgs::PoseEstimate> ordered_poses, lagging_poses;
  const SessionSummary ordered = run(in_order, ordered_poses);
  const SessionSummary lagging = run(imu_behind, lagging_poses);
  EXPECT_GT(lagging.rollbacks, 400U);  // the IMU messages came late
  EXPECT_EQ(lagging.sensors[0].fused, ordered.sensors[0].fused);
  ASSERT_EQ(lagging_poses.size(), ordered_poses.size());
  EXPECT_EQ(lagging.poses, lagging_poses.size());
  for (size_t i = 0; i < lagging_poses.size(); ++i) {
    ASSERT_EQ(lagging_poses[i].timestamp, ordered_poses[i].timestamp) << i;
    ASSERT_NEAR((lagging_poses[i].T_world_body.position - ordered_poses[i].T_world_body.position).norm(), 0.0, 1e-9) << i;
  }
}

TEST(Frontend, SensorsStreamingBehindTheImuAreNotTimedOutWithTheLiveGrace) {
  // Live, one stream per sensor: the wheels and GNSS arrive 0.3 s after the IMU of their time
  // (inside the 0.5 s lag window). Judged by data time alone the wheels (timeout 0.1 s) look
  // silent; with the grace a live session gets, they do not.
  const std::vector<Message> messages = drive(6.0);
  std::vector<Message> imu_first;
  std::vector<std::pair<double, Message>> waiting;  // (IMU time after which it arrives, message)
  for (const Message& m : messages) {
    const double t = std::visit([](const auto& typed) { return (typed.timestamp - at(0.0)).seconds(); }, m.message);
    if (m.sensor != "imu") {
      waiting.emplace_back(t + 0.3, m);
      continue;
    }
    imu_first.push_back(m);
    while (!waiting.empty() && waiting.front().first <= t) {
      imu_first.push_back(waiting.front().second);
      waiting.erase(waiting.begin());
    }
  }
  const auto wheel_timeouts = [&](double grace) {
    auto session = make_session();
    session->set_timeout_grace(grace);
    for (const Message& m : imu_first) (void)session->push(m.sensor, m.message);
    return session->summary().sensors[1].timeouts;
  };
  EXPECT_GT(wheel_timeouts(0.0), 0U);
  EXPECT_EQ(wheel_timeouts(fusion_config().frontend.lag_window_s), 0U);
}

TEST(Frontend, ReplayIsDeterministicBitForBit) {
  const std::vector<Message> messages = drive(4.0);
  std::vector<msgs::PoseEstimate> first, second;
  for (auto* poses : {&first, &second}) {
    auto session = make_session();
    session->set_pose_callback([poses](const msgs::PoseEstimate& pose) { poses->push_back(pose); });
    for (const Message& m : messages) ASSERT_TRUE(session->push(m.sensor, m.message).ok());
  }
  ASSERT_EQ(first.size(), second.size());
  for (size_t i = 0; i < first.size(); ++i) {
    ASSERT_EQ(first[i].T_world_body.position, second[i].T_world_body.position);
    ASSERT_EQ(*first[i].pose_covariance, *second[i].pose_covariance);
  }
}

TEST(Frontend, ASilentSensorIsReportedAndTheFilterKeepsRunning) {
  auto session = make_session();
  for (const Message& m : drive(4.0)) ASSERT_TRUE(session->push(m.sensor, m.message).ok());
  // GNSS and wheels go silent; only the IMU keeps coming for 2 s.
  for (int k = 401; k <= 600; ++k) ASSERT_TRUE(session->push("imu", imu_at(k * 0.01)).ok());
  const msgs::PoseEstimate pose = session->latest_pose().value();
  EXPECT_EQ(pose.status.state, msgs::TrackingState::kDegraded);
  EXPECT_EQ(pose.status.active_modalities, 1U);
  EXPECT_FALSE(pose.status.localization_reliable());
  const SessionSummary summary = session->summary();
  EXPECT_TRUE(summary.sensors[1].timed_out);
  EXPECT_EQ(summary.sensors[1].timeouts, 1U);
  EXPECT_TRUE(summary.sensors[2].timed_out);
  EXPECT_EQ(pose.timestamp, at(6.0));
}

TEST(Frontend, EmitsKeyframesWithRelativeMotionAndTakesBackendCorrections) {
  auto session = make_session();
  std::vector<msgs::Keyframe> keyframes;
  session->set_keyframe_callback([&keyframes](const msgs::Keyframe& keyframe) { keyframes.push_back(keyframe); });
  // GNSS off: the absolute uncertainty grows, the keyframe-to-keyframe one must not.
  for (const Message& m : drive(30.0)) {
    if (m.sensor != "gnss") {
      ASSERT_TRUE(session->push(m.sensor, m.message).ok());
    }
  }
  ASSERT_EQ(keyframes.size(), 29U);  // 1 Hz from the end of alignment (1.01 s) to 30 s
  for (size_t i = 1; i < keyframes.size(); ++i) {
    const msgs::Keyframe& k = keyframes[i];
    EXPECT_EQ(k.keyframe_id, i);
    EXPECT_EQ(k.previous_keyframe_id, i - 1);
    EXPECT_NEAR((k.timestamp - keyframes[i - 1].timestamp).seconds(), 1.0, 1e-9);
    ASSERT_TRUE(k.T_previous_current && k.relative_covariance);
    const SE3 expected = keyframes[i - 1].T_world_body.to_se3().inverse() * k.T_world_body.to_se3();
    EXPECT_LT((k.T_previous_current->position - expected.translation()).norm(), 0.01);
  }
  const msgs::Keyframe& last = keyframes.back();
  EXPECT_NEAR(last.T_previous_current->position.x(), 1.0, 0.02);  // 1 m/s for 1 s
  const double relative_variance = last.relative_covariance->topLeftCorner<3, 3>().trace();
  const double absolute_variance = last.pose_covariance->topLeftCorner<3, 3>().trace();
  EXPECT_LT(relative_variance, 0.05 * absolute_variance);
  EXPECT_GT(relative_variance, 0.0);
  EXPECT_GT(last.relative_covariance->ldlt().vectorD().minCoeff(), -1e-12);  // positive semi-definite

  // The backend says keyframe 20 is 1 m further north: the estimate moves with it.
  const SE3 keyframe_pose = keyframes[20].T_world_body.to_se3();
  const Eigen::Vector3d before = session->latest_pose()->T_world_body.position;
  const uint64_t imu_fused = session->summary().sensors[0].fused;
  ASSERT_TRUE(session->apply_correction(20, SE3(keyframe_pose.rotation(), keyframe_pose.translation() + Eigen::Vector3d(0, 1, 0))).ok());
  ASSERT_TRUE(session->push("imu", imu_at(30.01)).ok());
  EXPECT_NEAR(session->latest_pose()->T_world_body.position.y() - before.y(), 1.0, 0.01);
  EXPECT_EQ(session->summary().corrections, 1U);
  EXPECT_EQ(session->summary().sensors[0].fused, imu_fused + 1);  // the IMU message, not the correction
  const Status unknown = session->apply_correction(999, SE3());
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.error().message.rfind("unknown_keyframe: ", 0), 0U);
}

TEST(Frontend, EveryFilterGivesKeyframesARelativeCovarianceWithCrossTerms) {
  for (const config::FrontendType type : {config::FrontendType::kEkf, config::FrontendType::kUkf, config::FrontendType::kParticle}) {
    config::FusionConfig config = fusion_config();
    config.frontend.type = type;
    config.frontend.particle_filter.particles = 500;
    auto session = Frontend::create(config, calib::Calibration{}).value();
    std::vector<msgs::Keyframe> keyframes;
    session->set_keyframe_callback([&keyframes](const msgs::Keyframe& keyframe) { keyframes.push_back(keyframe); });
    for (const Message& m : drive(15.0)) {
      if (m.sensor != "gnss") {
        ASSERT_TRUE(session->push(m.sensor, m.message).ok());
      }
    }
    ASSERT_EQ(keyframes.size(), 14U) << config::to_string(type);
    const msgs::Keyframe& last = keyframes.back();
    const double relative_variance = last.relative_covariance->topLeftCorner<3, 3>().trace();
    const double absolute_variance = last.pose_covariance->topLeftCorner<3, 3>().trace();
    std::printf("%s: keyframe relative position variance %.3g m^2, absolute %.3g m^2\n", std::string(config::to_string(type)).c_str(),
                relative_variance, absolute_variance);
    EXPECT_LT(relative_variance, 0.25 * absolute_variance) << config::to_string(type);
    EXPECT_NEAR(last.T_previous_current->position.x(), 1.0, 0.05) << config::to_string(type);
  }
}

TEST(Frontend, FusesLidarPosesAndRelativePoses) {
  auto session = make_session();
  msgs::Matrix6d covariance = msgs::Matrix6d::Identity() * 1e-4;
  // IMU + LiDAR odometry only (relative poses at 10 Hz), then one absolute pose.
  for (const Message& m : drive(12.0)) {
    if (m.sensor == "imu") {
      ASSERT_TRUE(session->push(m.sensor, m.message).ok());
    }
    const double t = (msgs::timestamp_of(m.message) - at(0)).seconds();
    const int tick = static_cast<int>(std::lround(t * 100.0));
    if (m.sensor == "imu" && tick % 10 == 5 && t > 0.1) {
      const SE3 motion(SO3(), Eigen::Vector3d(distance_at(t) - distance_at(t - 0.1), 0.0, 0.0));
      ASSERT_TRUE(session->push_relative_pose("lidar", at(t - 0.1), at(t), motion, covariance).ok());
    }
  }
  EXPECT_NEAR(session->latest_pose()->T_world_body.position.x(), 9.0, 0.1);  // still 2 s, then 0.5 m/s^2 to 1 m/s
  EXPECT_NEAR(session->latest_pose()->velocity.x(), 1.0, 0.02);
  EXPECT_GT(session->summary().sensors[3].fused, 100U);

  ASSERT_TRUE(session->push_pose("lidar", at(12.005), SE3(SO3(), Eigen::Vector3d(9.005, 0.5, 0.0)), covariance).ok());
  ASSERT_TRUE(session->push("imu", imu_at(12.01)).ok());
  EXPECT_NEAR(session->latest_pose()->T_world_body.position.y(), 0.5, 0.05);  // the absolute pose pulls it over

  EXPECT_EQ(reason_of(session->push_relative_pose("lidar", at(13.0), at(13.0), SE3(), covariance)), "invalid");
  EXPECT_EQ(reason_of(session->push_pose("lidar", at(12.5), SE3(), msgs::Matrix6d::Zero())), "invalid");
}

// A pose far from the estimate is gated; the same pose pushed ungated (a visual-inertial
// filter's, which the EKF must follow) is fused.
TEST(Frontend, UngatedPosesAreFusedWhereTheGateRefusesThem) {
  auto session = make_session();
  const msgs::Matrix6d covariance = msgs::Matrix6d::Identity() * 1e-4;
  for (const Message& m : drive(12.0)) {
    if (m.sensor != "imu") continue;
    ASSERT_TRUE(session->push(m.sensor, m.message).ok());
    const double t = (msgs::timestamp_of(m.message) - at(0)).seconds();
    if (std::lround(t * 100.0) % 10 == 5 && t > 0.1) {
      const SE3 motion(SO3(), Eigen::Vector3d(distance_at(t) - distance_at(t - 0.1), 0.0, 0.0));
      ASSERT_TRUE(session->push_relative_pose("lidar", at(t - 0.1), at(t), motion, covariance).ok());
    }
  }
  const SE3 off_by_two_metres(SO3(), Eigen::Vector3d(9.005, 2.0, 0.0));
  ASSERT_TRUE(session->push_pose("lidar", at(12.005), off_by_two_metres, covariance).ok());
  ASSERT_TRUE(session->push("imu", imu_at(12.01)).ok());
  EXPECT_NEAR(session->latest_pose()->T_world_body.position.y(), 0.0, 0.05);
  EXPECT_EQ(session->summary().sensors[3].rejected.at(Rejection::kGated), 1U);

  ASSERT_TRUE(session->push_pose("lidar", at(12.015), off_by_two_metres, covariance, false).ok());
  ASSERT_TRUE(session->push("imu", imu_at(12.02)).ok());
  EXPECT_NEAR(session->latest_pose()->T_world_body.position.y(), 2.0, 0.1);
  EXPECT_EQ(session->summary().sensors[3].rejected.at(Rejection::kGated), 1U);
}

// Without an IMU a pose comes with every measurement the filter takes up: a gated one (a pose
// 2 m off the wheels' track) still gets the motion model's pose at its time, DEGRADED, so the
// pose stream does not thin out.
TEST(Frontend, WithoutAnImuAGatedMeasurementStillGetsADegradedPose) {
  config::FusionConfig config;
  config.frontend.initial_yaw = 0.0;
  config.sensors.push_back({"wheels", config::SensorModality::kWheelOdometry, "/wheels", 50.0, "base_link", "", {}});
  config.sensors.push_back({"lidar", config::SensorModality::kLidar, "/points", 10.0, "lidar_link", "", {}});
  auto frontend = Frontend::create(config, {});
  ASSERT_TRUE(frontend.ok()) << frontend.error().message;
  std::vector<msgs::PoseEstimate> poses;
  (*frontend)->set_pose_callback([&poses](const msgs::PoseEstimate& pose) { poses.push_back(pose); });
  const msgs::Matrix6d covariance = msgs::Matrix6d::Identity() * 1e-4;
  for (int k = 0; k <= 100; ++k) {  // 1 m/s east for 2 s
    const double t = 0.02 * k;
    msgs::WheelOdometryMessage wheels;
    wheels.timestamp = at(t);
    wheels.left_distance = wheels.right_distance = t;
    wheels.wheel_separation = 0.5;
    ASSERT_TRUE((*frontend)->push("wheels", wheels).ok());
    if (k == 95) {
      ASSERT_TRUE((*frontend)->push_pose("lidar", at(1.91), SE3(SO3(), Eigen::Vector3d(1.91, 0.0, 0.0)), covariance).ok());
    }
  }
  EXPECT_EQ(poses.back().status.state, msgs::TrackingState::kTracking);  // wheels and LiDAR
  const size_t before = poses.size();
  ASSERT_TRUE((*frontend)->push_pose("lidar", at(2.01), SE3(SO3(), Eigen::Vector3d(2.01, 2.0, 0.0)), covariance).ok());
  EXPECT_EQ((*frontend)->summary().sensors[1].rejected.at(Rejection::kGated), 1U);
  ASSERT_EQ(poses.size(), before + 1);
  EXPECT_EQ(poses.back().timestamp, at(2.01));
  EXPECT_EQ(poses.back().status.state, msgs::TrackingState::kDegraded);
  EXPECT_NEAR(poses.back().T_world_body.position.y(), 0.0, 0.05);  // the prediction, not the pose
  EXPECT_NEAR(poses.back().T_world_body.position.x(), 2.01, 0.05);
  ASSERT_TRUE((*frontend)->push_pose("lidar", at(2.03), SE3(SO3(), Eigen::Vector3d(2.03, 0.0, 0.0)), covariance).ok());
  ASSERT_EQ(poses.size(), before + 2);
  EXPECT_EQ(poses.back().status.state, msgs::TrackingState::kTracking);
  EXPECT_EQ((*frontend)->summary().sensors[1].fused, 2U);
}

// Without an IMU the motion model propagates: wheels alone dead-reckon a drive with a turn
// (speed, yaw rate and the non-holonomic constraint), GNSS added bounds the position.
TEST(Frontend, RunsWithoutAnImuOnTheMotionModel) {
  // 1 m/s straight for 5 s, then a 0.2 rad/s left turn at 1 m/s for 5 s (wheels 0.5 m apart).
  const double separation = 0.5;
  const auto heading_at = [](double t) { return t < 5.0 ? 0.0 : 0.2 * (t - 5.0); };
  const auto position_at = [&](double t) -> Eigen::Vector2d {
    if (t < 5.0) return {t, 0.0};
    const double radius = 1.0 / 0.2;
    return {5.0 + radius * std::sin(heading_at(t)), radius * (1.0 - std::cos(heading_at(t)))};
  };
  const auto wheels_of = [&](double t) {
    msgs::WheelOdometryMessage wheels;
    wheels.timestamp = at(t);
    const double turned = heading_at(t) * 0.5 * separation;  // each wheel's extra (or missing) travel
    wheels.left_distance = t - turned;
    wheels.right_distance = t + turned;
    wheels.wheel_separation = separation;
    return wheels;
  };
  for (const bool with_gnss : {false, true}) {
    SCOPED_TRACE(with_gnss ? "wheels + GNSS" : "wheels");
    config::FusionConfig config;
    config.frontend.datum = kDatum;
    config.frontend.initial_yaw = 0.0;  // it starts facing east (10 m are too short for a GNSS course)
    config.sensors.push_back({"wheels", config::SensorModality::kWheelOdometry, "/wheels", 50.0, "base_link", "", {}});
    if (with_gnss) config.sensors.push_back({"gnss", config::SensorModality::kGnss, "/gnss", 5.0, "gnss_link", "", {}});
    auto frontend = Frontend::create(config, {});
    ASSERT_TRUE(frontend.ok()) << frontend.error().message;
    EXPECT_FALSE((*frontend)->has_imu());
    std::vector<msgs::PoseEstimate> poses;
    (*frontend)->set_pose_callback([&poses](const msgs::PoseEstimate& pose) { poses.push_back(pose); });
    for (int k = 0; k <= 500; ++k) {
      const double t = 0.02 * k;
      ASSERT_TRUE((*frontend)->push("wheels", wheels_of(t)).ok());
      if (with_gnss && k % 10 == 5) {
        const Eigen::Vector2d position = position_at(t);
        ASSERT_TRUE((*frontend)->push("gnss", gnss_at_position(t, Eigen::Vector3d(position.x(), position.y(), 0.0))).ok());
      }
    }
    // A pose for every fused measurement (the first wheel reading is only a reference), in time order.
    ASSERT_GE(poses.size(), 500u);
    for (std::size_t i = 1; i < poses.size(); ++i) ASSERT_LT(poses[i - 1].timestamp, poses[i].timestamp);
    const msgs::PoseEstimate& last = poses.back();
    const SE3 T_world_body = last.T_world_body.to_se3();
    const Eigen::Vector2d expected = position_at(10.0);
    EXPECT_LT((T_world_body.translation().head<2>() - expected).norm(), 0.05);
    const Eigen::Vector3d rpy = T_world_body.rotation().matrix().eulerAngles(2, 1, 0);
    EXPECT_NEAR(std::remainder(rpy.x() - heading_at(10.0), 2.0 * M_PI), 0.0, 0.01);
    EXPECT_NEAR(last.velocity.norm(), 1.0, 0.05);
    // Wheels alone are one modality (DEGRADED); with GNSS two (TRACKING).
    EXPECT_EQ(last.status.state, with_gnss ? msgs::TrackingState::kTracking : msgs::TrackingState::kDegraded);
    EXPECT_EQ((*frontend)->summary().sensors[0].fused, 500u);
  }
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
