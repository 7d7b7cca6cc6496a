// ROS 2 bags written by io/ros2_bag_writer.hpp, read back by Foxglove's libraries alone
// (tests/conformance/rosbag2_read.mjs: the schemas parsed from the bag's own message
// definitions, the CDR decoded by @foxglove/rosmsg2-serialization): every value comes back.

#include <unistd.h>

#include <filesystem>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/io/ros2_bag.hpp"
#include "hanzo/fusion/io/ros2_bag_writer.hpp"
#include "node_runner.hpp"

namespace hanzo::fusion::io::ros2 {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

class Rosbag2Export : public ::testing::TestWithParam<BagStorage> {};

TEST_P(Rosbag2Export, FoxgloveReadsEveryValueWritten) {
  const bool sqlite = GetParam() == BagStorage::kSqlite3;
  const fs::path dir = fs::temp_directory_path() / fmt::format("hanzo_ros2_export_{}_{}", ::getpid(), sqlite ? "db3" : "mcap");
  fs::remove_all(dir);
  std::vector<StampedPose> path;
  for (int i = 0; i < 20; ++i) {
    const Timestamp t = Timestamp::from_nanoseconds(1'700'000'000'000'000'000 + i * 100'000'000LL);
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d(0.2, 0.3, 1.0).normalized()));
    path.push_back({t, {Eigen::Vector3d(0.5 * i, -0.25 * i, 0.01 * i * i), q}});
  }
  Eigen::Matrix<double, 6, 6> covariance;
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) covariance(r, c) = r == c ? 0.01 * (r + 1) : 1e-4 * (r + c);
  }
  std::vector<Eigen::Vector3f> points;
  std::vector<float> intensities;
  for (int i = 0; i < 500; ++i) {
    points.emplace_back(0.1f * static_cast<float>(i), std::sin(0.1f * static_cast<float>(i)), -1.5f);
    intensities.push_back(static_cast<float>(i % 7) / 7.0f);
  }
  msgs::OccupancyGridLayer grid;
  grid.resolution = 0.05;
  grid.size_x = 7;
  grid.size_y = 5;
  grid.origin.position = {-1.0, 2.0, 0.0};
  grid.origin.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()));
  for (uint32_t i = 0; i < grid.size_x * grid.size_y; ++i) grid.occupancy.push_back(i % 3 == 0 ? 0.5f : static_cast<float>(i) / 35.0f);

  const std::vector<ros::FrameTransform> transforms = {
      {path[0].stamp, "base_link", "lidar", SE3(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 0.4), Eigen::Vector3d(0.3, -0.1, 1.2))},
      {path[0].stamp, "base_link", "cam_optical", SE3(SO3::from_wxyz(Eigen::Vector4d(0.5, -0.5, 0.5, -0.5)), Eigen::Vector3d(0.1, 0.05, 0.0))}};
  const calib::CameraCalibration fisheye{{458.6, 457.3, 367.2, 248.4, 752, 480}, {msgs::DistortionType::kEquidistant, {0.01, -0.02, 0.003, -0.0004}}};
  const calib::CameraCalibration pinhole{{500.0, 501.0, 320.5, 180.5, 640, 360}, {}};
  const std::string compressed_file("\x89PNG\r\n\x1a\n\0\xff", 10);  // the bytes are passed on as they are
  {
    auto writer = BagWriter::create(dir.string(), GetParam());
    ASSERT_TRUE(writer.ok()) << writer.error().message;
    for (const StampedPose& p : path) {
      ASSERT_TRUE((*writer)->write("/pose", "geometry_msgs/msg/PoseStamped", p.stamp, pose_stamped_cdr(p.stamp, "map", p.pose)).ok());
      ASSERT_TRUE((*writer)->write("/pose_cov", "geometry_msgs/msg/PoseWithCovarianceStamped", p.stamp,
                                   pose_with_covariance_stamped_cdr(p.stamp, "map", p.pose, covariance)).ok());
    }
    ASSERT_TRUE((*writer)->write("/trajectory", "nav_msgs/msg/Path", path.back().stamp, path_cdr(path.back().stamp, "map", path)).ok());
    ASSERT_TRUE((*writer)->write("/map/points", "sensor_msgs/msg/PointCloud2", path.back().stamp,
                                 point_cloud_cdr(path.back().stamp, "map", points, intensities)).ok());
    auto occupancy = occupancy_grid_cdr(path.back().stamp, "map", grid);
    ASSERT_TRUE(occupancy.ok()) << occupancy.error().message;
    ASSERT_TRUE((*writer)->write("/map/occupancy", "nav_msgs/msg/OccupancyGrid", path.back().stamp, *occupancy).ok());
    ASSERT_TRUE((*writer)->write("/tf_static", "tf2_msgs/msg/TFMessage", path[0].stamp, tf_message_cdr(transforms)).ok());
    ASSERT_TRUE((*writer)->write("/cam/camera_info", "sensor_msgs/msg/CameraInfo", path[0].stamp,
                                 camera_info_cdr(path[0].stamp, "cam_optical", fisheye, 752, 480)).ok());
    ASSERT_TRUE((*writer)->write("/cam2/camera_info", "sensor_msgs/msg/CameraInfo", path[0].stamp,
                                 camera_info_cdr(path[0].stamp, "cam2", pinhole, 640, 360)).ok());
    msgs::ImageMessage image;
    image.timestamp = path[1].stamp;
    image.frame_id = "cam2";
    image.encoding = msgs::ImageEncoding::kMono8;
    ASSERT_TRUE((*writer)->write("/cam2", "sensor_msgs/msg/CompressedImage", image.timestamp,
                                 compressed_image_cdr(image, "png", compressed_file)).ok());
    EXPECT_THAT((*writer)->write("/pose", "nav_msgs/msg/Path", path[0].stamp, "").error().message, HasSubstr("has type"));
    EXPECT_THAT((*writer)->write("/x", "std_msgs/msg/String", path[0].stamp, "").error().message, HasSubstr("not one it writes"));
    ASSERT_TRUE((*writer)->close().ok());
  }
  EXPECT_THAT(BagWriter::create(dir.string()).error().message, HasSubstr("exists"));

  // Our own reader sees the bag as rosbag2 describes it.
  auto bag = open_bag(dir.string());
  ASSERT_TRUE(bag.ok()) << bag.error().message;
  EXPECT_EQ(bag->storage, sqlite ? "sqlite3" : "mcap");
  ASSERT_EQ(bag->topics.size(), 9u);

  const nlohmann::json read = test::run_node("rosbag2_read.mjs", bag->files.front());
  ASSERT_FALSE(read.is_null());
  if (sqlite) {  // Humble's layout; the types' definitions are Foxglove's own (a .db3 stores none)
    EXPECT_EQ(read["schema_version"], 3);
    EXPECT_EQ(read["ros_distro"], "humble");
  } else {
    EXPECT_EQ(read["profile"], "ros2");
  }
  const auto& topics = read["topics"];
  auto expect_pose = [](const nlohmann::json& json, const msgs::Pose& pose) {
    EXPECT_EQ(json["position"]["x"].get<double>(), pose.position.x());
    EXPECT_EQ(json["position"]["y"].get<double>(), pose.position.y());
    EXPECT_EQ(json["position"]["z"].get<double>(), pose.position.z());
    const Eigen::Quaterniond q = pose.orientation.normalized();
    EXPECT_EQ(json["orientation"]["w"].get<double>(), q.w());
    EXPECT_EQ(json["orientation"]["x"].get<double>(), q.x());
    EXPECT_EQ(json["orientation"]["z"].get<double>(), q.z());
  };
  auto expect_stamp = [](const nlohmann::json& header, Timestamp t) {
    EXPECT_EQ(header["stamp"]["sec"].get<int64_t>() * 1'000'000'000 + header["stamp"]["nanosec"].get<int64_t>(), t.nanoseconds());
  };
  ASSERT_EQ(topics["/pose"]["messages"].size(), path.size());
  EXPECT_EQ(topics["/pose"]["schema"], "geometry_msgs/msg/PoseStamped");
  EXPECT_EQ(topics["/pose"]["schemaEncoding"], sqlite ? "" : "ros2msg");
  EXPECT_EQ(topics["/pose"]["messageEncoding"], "cdr");
  for (std::size_t i = 0; i < path.size(); ++i) {
    const auto& m = topics["/pose"]["messages"][i];
    EXPECT_EQ(m["header"]["frame_id"], "map");
    expect_stamp(m["header"], path[i].stamp);
    EXPECT_EQ(topics["/pose"]["logTimes"][i], std::to_string(path[i].stamp.nanoseconds()));
    expect_pose(m["pose"], path[i].pose);
    const auto& c = topics["/pose_cov"]["messages"][i]["pose"];
    expect_pose(c["pose"], path[i].pose);
    for (int k = 0; k < 36; ++k) EXPECT_EQ(c["covariance"][k].get<double>(), covariance(k / 6, k % 6));
  }
  const auto& trajectory = topics["/trajectory"]["messages"][0];
  ASSERT_EQ(trajectory["poses"].size(), path.size());
  for (std::size_t i = 0; i < path.size(); ++i) {
    expect_stamp(trajectory["poses"][i]["header"], path[i].stamp);
    expect_pose(trajectory["poses"][i]["pose"], path[i].pose);
  }
  const auto& cloud = topics["/map/points"]["messages"][0];
  EXPECT_EQ(cloud["height"], 1);
  EXPECT_EQ(cloud["is_dense"], true);
  ASSERT_EQ(cloud["points"].size(), points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    for (int a = 0; a < 3; ++a) EXPECT_EQ(cloud["points"][i][a].get<float>(), points[i][a]);
    EXPECT_EQ(cloud["points"][i][3].get<float>(), intensities[i]);
  }
  const auto& occupancy = topics["/map/occupancy"]["messages"][0];
  EXPECT_EQ(occupancy["info"]["width"], 7);
  EXPECT_EQ(occupancy["info"]["height"], 5);
  EXPECT_EQ(occupancy["info"]["resolution"].get<float>(), 0.05f);
  expect_pose(occupancy["info"]["origin"], grid.origin);
  ASSERT_EQ(occupancy["data"].size(), grid.occupancy.size());
  for (std::size_t i = 0; i < grid.occupancy.size(); ++i) {
    const int expected = i % 3 == 0 ? -1 : static_cast<int>(std::lround(grid.occupancy[i] * 100.0f));
    EXPECT_EQ(occupancy["data"][i].get<int>(), expected) << i;
  }
  const auto& tf = topics["/tf_static"]["messages"][0]["transforms"];
  ASSERT_EQ(tf.size(), transforms.size());
  for (std::size_t i = 0; i < transforms.size(); ++i) {
    EXPECT_EQ(tf[i]["header"]["frame_id"], "base_link");
    EXPECT_EQ(tf[i]["child_frame_id"], transforms[i].child_frame);
    expect_stamp(tf[i]["header"], transforms[i].stamp);
    const Eigen::Vector3d& t = transforms[i].T_parent_child.translation();
    const Eigen::Quaterniond& q = transforms[i].T_parent_child.rotation().quaternion();
    EXPECT_EQ(tf[i]["transform"]["translation"]["x"].get<double>(), t.x());
    EXPECT_EQ(tf[i]["transform"]["translation"]["z"].get<double>(), t.z());
    EXPECT_EQ(tf[i]["transform"]["rotation"]["w"].get<double>(), q.w());
    EXPECT_EQ(tf[i]["transform"]["rotation"]["y"].get<double>(), q.y());
  }
  const auto& info = topics["/cam/camera_info"]["messages"][0];
  EXPECT_EQ(info["header"]["frame_id"], "cam_optical");
  EXPECT_EQ(info["width"], 752);
  EXPECT_EQ(info["height"], 480);
  EXPECT_EQ(info["distortion_model"], "equidistant");
  EXPECT_EQ(info["d"].get<std::vector<double>>(), fisheye.distortion.coefficients);
  EXPECT_EQ(info["k"].get<std::vector<double>>(), (std::vector<double>{458.6, 0, 367.2, 0, 457.3, 248.4, 0, 0, 1}));
  EXPECT_EQ(info["p"][2].get<double>(), 367.2);
  EXPECT_EQ(info["roi"]["do_rectify"], false);
  const auto& plain = topics["/cam2/camera_info"]["messages"][0];
  EXPECT_EQ(plain["distortion_model"], "plumb_bob");
  EXPECT_EQ(plain["d"].get<std::vector<double>>(), std::vector<double>(5, 0.0));
  const auto& compressed = topics["/cam2"]["messages"][0];
  EXPECT_EQ(compressed["header"]["frame_id"], "cam2");
  expect_stamp(compressed["header"], path[1].stamp);
  EXPECT_EQ(compressed["format"], "mono8; png compressed mono8");
  std::vector<int> file_bytes;
  for (const char c : compressed_file) file_bytes.push_back(static_cast<uint8_t>(c));
  EXPECT_EQ(compressed["data"].get<std::vector<int>>(), file_bytes);
  // Our importer's decoders take them back as they were.
  auto camera_back = ros::camera_info_from_ros(camera_info_cdr(path[0].stamp, "cam_optical", fisheye, 752, 480), ros::Serialization::kCdr);
  ASSERT_TRUE(camera_back.ok()) << camera_back.error().message;
  EXPECT_EQ(camera_back->frame_id, "cam_optical");
  EXPECT_EQ(camera_back->camera.intrinsics.fx, fisheye.intrinsics.fx);
  EXPECT_EQ(camera_back->camera.intrinsics.cy, fisheye.intrinsics.cy);
  EXPECT_EQ(camera_back->camera.intrinsics.width, 752u);
  EXPECT_EQ(camera_back->camera.distortion.type, msgs::DistortionType::kEquidistant);
  EXPECT_EQ(camera_back->camera.distortion.coefficients, fisheye.distortion.coefficients);
  auto tf_back = ros::transforms_from_ros(tf_message_cdr(transforms), ros::Serialization::kCdr);
  ASSERT_TRUE(tf_back.ok()) << tf_back.error().message;
  ASSERT_EQ(tf_back->size(), transforms.size());
  for (std::size_t i = 0; i < transforms.size(); ++i) {
    EXPECT_EQ((*tf_back)[i].child_frame, transforms[i].child_frame);
    EXPECT_TRUE((*tf_back)[i].T_parent_child.matrix().isApprox(transforms[i].T_parent_child.matrix(), 1e-15));
  }
  fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Storages, Rosbag2Export, ::testing::Values(BagStorage::kMcap, BagStorage::kSqlite3),
                         [](const auto& storage) { return storage.param == BagStorage::kMcap ? "mcap" : "sqlite3"; });

TEST(Rosbag2ExportGrid, ThreeDimensionalGridsAreRefused) {
  msgs::OccupancyGridLayer grid;
  grid.size_x = 2;
  grid.size_y = 2;
  grid.size_z = 2;
  grid.occupancy.assign(8, 0.5f);
  EXPECT_THAT(occupancy_grid_cdr(Timestamp(), "map", grid).error().message, HasSubstr("flatten"));
  grid.size_z = 1;
  EXPECT_THAT(occupancy_grid_cdr(Timestamp(), "map", grid).error().message, HasSubstr("8 cells for 2 x 2"));
}

}  // namespace
}  // namespace hanzo::fusion::io::ros2
