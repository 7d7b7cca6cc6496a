// Our PCD/PLY files against PCL's reader and writer (the reference implementation of both
// formats), and the pcl::PointCloud conversions.

#include <filesystem>

#include <gtest/gtest.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>

#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/cloud/pcl_conversion.hpp"

namespace hanzo::fusion::cloud {
namespace {

std::string temp_path(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / "hanzo_pcl_interop_test";
  std::filesystem::create_directories(dir);
  return (dir / name).string();
}

pcl::PointCloud<pcl::PointXYZI> pcl_sample() {
  pcl::PointCloud<pcl::PointXYZI> cloud;
  for (int i = 0; i < 300; ++i) {
    pcl::PointXYZI point;
    point.x = 0.1f * static_cast<float>(i);
    point.y = -0.05f * static_cast<float>(i);
    point.z = 2.0f + 0.001f * static_cast<float>(i * i);
    point.intensity = static_cast<float>(i % 17);
    cloud.push_back(point);
  }
  return cloud;
}

void expect_same(const PointCloud& ours, const pcl::PointCloud<pcl::PointXYZI>& theirs) {
  ASSERT_EQ(ours.size(), theirs.size());
  for (size_t i = 0; i < ours.size(); ++i) {
    EXPECT_EQ(ours.positions[i], Eigen::Vector3f(theirs[i].x, theirs[i].y, theirs[i].z));
    EXPECT_EQ(ours.intensities[i], theirs[i].intensity);
  }
}

TEST(PclInterop, WeReadWhatPclWrites) {
  const auto reference = pcl_sample();
  const std::string ascii = temp_path("ascii.pcd"), binary = temp_path("binary.pcd"), compressed = temp_path("compressed.pcd");
  ASSERT_EQ(pcl::io::savePCDFileASCII(ascii, reference), 0);
  ASSERT_EQ(pcl::io::savePCDFileBinary(binary, reference), 0);
  ASSERT_EQ(pcl::io::savePCDFileBinaryCompressed(compressed, reference), 0);
  for (const std::string& path : {binary, compressed}) {
    auto read = read_cloud(path);
    ASSERT_TRUE(read.ok()) << read.error().message;
    expect_same(*read, reference);
  }
  auto read = read_cloud(ascii);  // ascii rounds to PCL's printed precision
  ASSERT_TRUE(read.ok()) << read.error().message;
  ASSERT_EQ(read->size(), reference.size());
  EXPECT_LT((read->positions[123] - Eigen::Vector3f(reference[123].x, reference[123].y, reference[123].z)).norm(), 1e-4f);

  const std::string ply = temp_path("pcl.ply");
  ASSERT_EQ(pcl::io::savePLYFileBinary(ply, reference), 0);
  read = read_cloud(ply);
  ASSERT_TRUE(read.ok()) << read.error().message;
  expect_same(*read, reference);
}

TEST(PclInterop, PclReadsWhatWeWrite) {
  const PointCloud ours = from_pcl(pcl_sample());
  for (const char* name : {"ours.pcd", "ours.ply"}) {
    const std::string path = temp_path(name);
    ASSERT_TRUE(write_cloud(path, ours).ok());
    pcl::PointCloud<pcl::PointXYZI> theirs;
    const int code = std::string(name).ends_with(".pcd") ? pcl::io::loadPCDFile(path, theirs) : pcl::io::loadPLYFile(path, theirs);
    ASSERT_EQ(code, 0) << name;
    expect_same(ours, theirs);
  }
}

TEST(PclInterop, ConversionsKeepPointsAndFields) {
  const auto reference = pcl_sample();
  const PointCloud ours = from_pcl(reference);
  expect_same(ours, reference);
  const auto back = to_pcl<pcl::PointXYZI>(ours);
  expect_same(ours, back);
  const auto xyz = to_pcl<pcl::PointXYZ>(ours);  // a point type without intensity
  EXPECT_EQ(xyz.size(), ours.size());
  EXPECT_FALSE(from_pcl(xyz).has_intensities());
}

}  // namespace
}  // namespace hanzo::fusion::cloud
