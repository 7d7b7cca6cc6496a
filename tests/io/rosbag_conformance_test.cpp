// The ROS1 bag importer against Foxglove's independent bag reader (@foxglove/rosbag, run with
// node by tests/conformance/rosbag_read.mjs) on robot_localization's test2.bag (bz2 chunks).

#include <cstdio>
#include <filesystem>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/io/rosbag_import.hpp"
#include "node_runner.hpp"

namespace hanzo::fusion::io {
namespace {

TEST(RosbagConformance, Test2BagImportsExactlyWhatFoxgloveReads) {
  const std::string bag = std::string(HANZO_DATA_DIR) + "/robot_localization/test2.bag";
  const std::string log = (std::filesystem::temp_directory_path() / fmt::format("hanzo_test2_{}.mcap", ::getpid())).string();
  constexpr double kWheelSeparation = 0.37;
  RosbagImportReport report;
  {
    auto writer = SensorLogWriter::open(log);
    ASSERT_TRUE(writer.ok());
    RosbagImportConfig config;
    config.topic_map = {{"/imu/data", "/imu"}, {"/jackal_velocity_controller/odom", "/wheels"}};
    config.wheel_separation = kWheelSeparation;
    auto imported = import_rosbag(bag, **writer, config);
    ASSERT_TRUE(imported.ok()) << imported.error().message;
    report = *imported;
    ASSERT_TRUE((*writer)->close().ok());
  }
  EXPECT_TRUE(report.bag.complete);
  EXPECT_EQ(report.bag.chunk_compressions.at("bz2"), report.bag.chunks);
  ASSERT_EQ(report.topics.size(), 2u);
  for (const auto& topic : report.topics) EXPECT_EQ(topic.rejected, 0u) << topic.first_rejection;

  const nlohmann::json foxglove = test::run_node("rosbag_read.mjs", bag);
  ASSERT_FALSE(foxglove.is_null());
  const auto& imu_ref = foxglove["topics"]["/imu/data"];
  const auto& odom_ref = foxglove["topics"]["/jackal_velocity_controller/odom"];
  EXPECT_EQ(imu_ref["count"], 3061);  // SOURCE.md
  EXPECT_EQ(odom_ref["count"], 3060);

  auto reader = SensorLogReader::open(log);
  ASSERT_TRUE(reader.ok());
  std::vector<msgs::ImuMessage> imu;
  std::vector<msgs::WheelOdometryMessage> wheels;
  LogEntry entry;
  while (*(*reader)->next(entry)) {
    const auto& message = std::get<msgs::SensorMessage>(entry.message);
    if (entry.topic == "/imu") imu.push_back(std::get<msgs::ImuMessage>(message));
    if (entry.topic == "/wheels") wheels.push_back(std::get<msgs::WheelOdometryMessage>(message));
  }
  ASSERT_EQ(imu.size(), imu_ref["imu"].size());
  for (std::size_t i = 0; i < imu.size(); ++i) {
    const auto& ref = imu_ref["imu"][i];
    ASSERT_EQ(std::to_string(imu[i].timestamp.nanoseconds()), ref["stamp"]) << i;
    EXPECT_EQ(imu[i].frame_id, ref["frame_id"]);
    for (int k = 0; k < 3; ++k) {
      ASSERT_EQ(imu[i].angular_velocity[k], ref["angular_velocity"][k].get<double>()) << i;
      ASSERT_EQ(imu[i].linear_acceleration[k], ref["linear_acceleration"][k].get<double>()) << i;
    }
    ASSERT_TRUE(imu[i].orientation.has_value());
    const Eigen::Quaterniond q(ref["orientation"][0], ref["orientation"][1], ref["orientation"][2], ref["orientation"][3]);
    EXPECT_NEAR(imu[i].orientation->angularDistance(q.normalized()), 0.0, 1e-9) << i;
    ASSERT_TRUE(imu[i].gyroscope_covariance.has_value());
    EXPECT_EQ((*imu[i].gyroscope_covariance)(0, 0), ref["gyroscope_covariance_xx"].get<double>());
  }
  // Wheel distances: the trapezoid integral of Foxglove's twists. Foxglove yields messages in
  // record-time order, in which 163 odometry stamps of this bag go back; the log is in stamp order.
  std::vector<nlohmann::json> odometry = odom_ref["odometry"];
  std::stable_sort(odometry.begin(), odometry.end(), [](const nlohmann::json& a, const nlohmann::json& b) {
    return std::stoll(a["stamp"].get<std::string>()) < std::stoll(b["stamp"].get<std::string>());
  });
  ASSERT_EQ(wheels.size(), odometry.size());
  double left = 0.0, right = 0.0;
  for (std::size_t i = 0; i < wheels.size(); ++i) {
    const auto& now = odometry[i];
    ASSERT_EQ(std::to_string(wheels[i].timestamp.nanoseconds()), now["stamp"]) << i;
    if (i > 0) {
      const auto& before = odometry[i - 1];
      const double dt = static_cast<double>(std::stoll(now["stamp"].get<std::string>()) -
                                            std::stoll(before["stamp"].get<std::string>())) * 1e-9;
      const double v0 = before["forward_speed"], w0 = before["yaw_rate"], v1 = now["forward_speed"], w1 = now["yaw_rate"];
      left += 0.5 * ((v0 - w0 * kWheelSeparation / 2) + (v1 - w1 * kWheelSeparation / 2)) * dt;
      right += 0.5 * ((v0 + w0 * kWheelSeparation / 2) + (v1 + w1 * kWheelSeparation / 2)) * dt;
    }
    ASSERT_NEAR(wheels[i].left_distance, left, 1e-9) << i;
    ASSERT_NEAR(wheels[i].right_distance, right, 1e-9) << i;
    EXPECT_EQ(wheels[i].wheel_separation, kWheelSeparation);
  }
  // SOURCE.md: the odometry path is 84.2 m long; the wheels' mean distance is that path.
  EXPECT_NEAR(0.5 * (wheels.back().left_distance + wheels.back().right_distance), 84.2, 0.5);
  std::filesystem::remove(log);
}

}  // namespace
}  // namespace hanzo::fusion::io
