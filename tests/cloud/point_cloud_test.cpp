// PointCloud invariants, conversions and file round trips (PCD, PLY, KITTI .bin) with bad files.

#include <cmath>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::cloud {
namespace {

PointCloud sample_cloud() {
  PointCloud cloud;
  for (int i = 0; i < 50; ++i) {
    cloud.positions.emplace_back(0.5f * static_cast<float>(i), -0.25f * static_cast<float>(i), 1.0f + 0.01f * static_cast<float>(i));
    cloud.intensities.push_back(static_cast<float>(i) / 50.0f);
    cloud.rings.push_back(static_cast<uint16_t>(i % 16));
    cloud.times.push_back(0.002f * static_cast<float>(i));
  }
  return cloud;
}

std::string temp_path(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / "hanzo_cloud_test";
  std::filesystem::create_directories(dir);
  return (dir / name).string();
}

TEST(PointCloud, ValidateNamesTheProblem) {
  PointCloud cloud = sample_cloud();
  EXPECT_TRUE(cloud.validate().ok());
  cloud.times.pop_back();
  auto status = cloud.validate();
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().message, "PointCloud.times: 49 values for 50 points");
  cloud = sample_cloud();
  cloud.positions[7].y() = NAN;
  status = cloud.validate();
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().message, "PointCloud.positions[7].y: nan");
}

TEST(PointCloud, SelectTransformAndCrop) {
  const PointCloud cloud = sample_cloud();
  const PointCloud picked = select(cloud, {4, 2});
  ASSERT_EQ(picked.size(), 2u);
  EXPECT_EQ(picked.positions[0], cloud.positions[4]);
  EXPECT_EQ(picked.rings[1], cloud.rings[2]);
  EXPECT_FALSE(picked.has_normals());

  const SE3 T(SO3::exp(Eigen::Vector3d(0.1, 0.2, 0.3)), Eigen::Vector3d(1, 2, 3));
  const PointCloud moved = transformed(cloud, T);
  for (size_t i = 0; i < cloud.size(); ++i) {
    EXPECT_LT((moved.positions[i].cast<double>() - T * cloud.positions[i].cast<double>()).norm(), 1e-5);
  }
  const PointCloud back = transformed(moved, T.inverse());
  EXPECT_LT((back.positions[10] - cloud.positions[10]).norm(), 1e-5f);

  PointCloud with_nan = cloud;
  with_nan.positions[0].x() = NAN;
  const PointCloud cropped = crop_range(with_nan, 2.0, 10.0);
  for (const auto& p : cropped.positions) {
    EXPECT_GE(p.norm(), 2.0f);
    EXPECT_LE(p.norm(), 10.0f);
  }
  EXPECT_GT(cropped.size(), 5u);
}

TEST(PointCloud, FromMessageMakesTimesRelative) {
  msgs::PointCloudMessage message;
  message.timestamp = Timestamp::from_seconds(100.0);
  message.frame_id = "lidar";
  message.points = {{1, 0, 0}, {0, 1, 0}};
  message.ring_ids = {3, 4};
  message.point_timestamps = {Timestamp::from_seconds(100.0), Timestamp::from_seconds(100.05)};
  auto cloud = from_message(message);
  ASSERT_TRUE(cloud.ok()) << cloud.error().message;
  EXPECT_EQ(cloud->rings[1], 4);
  EXPECT_NEAR(cloud->times[1], 0.05f, 1e-6f);
  message.points.clear();
  EXPECT_FALSE(from_message(message).ok());
}

TEST(CloudIo, RoundTripsEveryFormat) {
  const PointCloud cloud = sample_cloud();
  for (const char* name : {"cloud.pcd", "cloud.ply"}) {
    const std::string path = temp_path(name);
    ASSERT_TRUE(write_cloud(path, cloud).ok()) << name;
    auto read = read_cloud(path);
    ASSERT_TRUE(read.ok()) << read.error().message;
    ASSERT_EQ(read->size(), cloud.size());
    EXPECT_EQ(read->positions, cloud.positions) << name;
    EXPECT_EQ(read->intensities, cloud.intensities) << name;
    EXPECT_EQ(read->rings, cloud.rings) << name;
    EXPECT_EQ(read->times, cloud.times) << name;
  }
  const std::string bin = temp_path("cloud.bin");
  ASSERT_TRUE(write_cloud(bin, cloud).ok());
  auto read = read_cloud(bin);
  ASSERT_TRUE(read.ok()) << read.error().message;
  EXPECT_EQ(read->positions, cloud.positions);
  EXPECT_EQ(read->intensities, cloud.intensities);
}

TEST(CloudIo, RejectsBadFiles) {
  auto result = read_cloud(temp_path("missing.pcd"));
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("no such file"), std::string::npos);

  result = read_cloud(temp_path("cloud.xyz"));
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("unknown point-cloud format"), std::string::npos);

  const std::string truncated = temp_path("truncated.bin");
  std::ofstream(truncated, std::ios::binary) << std::string(18, 'x');
  result = read_cloud(truncated);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("16-byte KITTI points"), std::string::npos);

  const std::string garbage = temp_path("garbage.pcd");
  std::ofstream(garbage) << "this is not a point cloud\n";
  result = read_cloud(garbage);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("garbage.pcd"), std::string::npos);

  const std::string garbage_ply = temp_path("garbage.ply");
  std::ofstream(garbage_ply) << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n";
  result = read_cloud(garbage_ply);
  ASSERT_FALSE(result.ok());

  // A header that promises more points than the file holds.
  const std::string short_pcd = temp_path("short.pcd");
  std::ofstream(short_pcd) << "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 5\nHEIGHT 1\n"
                              "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 5\nDATA ascii\n1 2 3\n4 5 6\n";
  result = read_cloud(short_pcd);
  ASSERT_FALSE(result.ok());

  // Headers that announce far more data than the file holds (PCL 1.13 aborts on the first).
  const std::string huge_ply = temp_path("huge.ply");
  std::ofstream(huge_ply) << "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\n"
                             "property float y\nproperty float z\nend_header\n";
  result = read_cloud(huge_ply);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("vertex data holds 0 bytes"), std::string::npos) << result.error().message;
  // An ascii header declaring 2.1 billion vertices over two lines (found by fuzzing: the reader
  // took 56 GB for them before reading a line).
  const std::string huge_ascii_ply = temp_path("huge_ascii.ply");
  std::ofstream(huge_ascii_ply) << "ply\nformat ascii 1.0\nelement vertex 2111111111\nproperty float x\nproperty float y\n"
                                   "property float z\nproperty uchar r)ng\nend_header\n1 2 3 4\n5 6 7 8\n";
  result = read_cloud(huge_ascii_ply);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("too few for the 2111111111 vertices"), std::string::npos) << result.error().message;
  const std::string lying_pcd = temp_path("lying.pcd");
  std::ofstream(lying_pcd) << "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1000\nHEIGHT 1\n"
                              "POINTS 1000\nDATA binary\n0123456789ab";
  result = read_cloud(lying_pcd);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("binary data holds 12 bytes"), std::string::npos) << result.error().message;
  const std::string no_xyz = temp_path("no_xyz.pcd");
  std::ofstream(no_xyz) << "VERSION .7\nFIELDS a b\nSIZE 4 4\nTYPE F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2\n";
  result = read_cloud(no_xyz);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("no x, y, z"), std::string::npos) << result.error().message;

  // Missing returns (NaN coordinates) are dropped; a NaN intensity names the point as in the file.
  const std::string with_nan = temp_path("with_nan.pcd");
  std::ofstream(with_nan) << "VERSION .7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nWIDTH 4\nPOINTS 4\nDATA ascii\n"
                             "1 2 3 10\nnan nan nan 0\n4 5 6 11\n7 8 9 12\n";
  auto dropped = read_cloud(with_nan);
  ASSERT_TRUE(dropped.ok()) << dropped.error().message;
  EXPECT_EQ(dropped->size(), 3u);
  EXPECT_EQ(dropped->positions[1], Eigen::Vector3f(4, 5, 6));
  EXPECT_FALSE(read_cloud(with_nan, false).ok());
  const std::string nan_intensity = temp_path("nan_intensity.pcd");
  std::ofstream(nan_intensity) << "VERSION .7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nWIDTH 4\nPOINTS 4\nDATA ascii\n"
                                  "1 2 3 10\nnan nan nan 0\n4 5 6 11\n7 8 9 nan\n";
  result = read_cloud(nan_intensity);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("point 3 of the file has a non-finite intensity"), std::string::npos) << result.error().message;

  // Writing an invalid cloud fails and leaves the previous file untouched.
  const std::string path = temp_path("kept.pcd");
  ASSERT_TRUE(write_cloud(path, sample_cloud()).ok());
  PointCloud broken = sample_cloud();
  broken.intensities.pop_back();
  EXPECT_FALSE(write_cloud(path, broken).ok());
  auto kept = read_cloud(path);
  ASSERT_TRUE(kept.ok());
  EXPECT_EQ(kept->size(), 50u);
}

}  // namespace
}  // namespace hanzo::fusion::cloud
