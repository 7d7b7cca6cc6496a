// Geometric labels on a synthetic room: a floor, two walls, a table top and a ceiling sampled
// on grids with 1 cm of noise; every surface's points get its label, bad configurations are
// refused naming the field.

#include "hanzo/fusion/maps/geometric_labels.hpp"

#include <fstream>
#include <iterator>

#include <array>
#include <cstring>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/maps/label_export.hpp"
#include "hanzo/fusion/maps/map_export.hpp"
#include "maps/map_fixtures.hpp"

namespace hanzo::fusion::maps {
namespace {

using msgs::SemanticLabel;

struct Surface {
  SemanticLabel expected;
  std::size_t first = 0, count = 0;
};

TEST(GeometricLabels, EverySurfaceOfARoomGetsItsLabel) {
  std::mt19937 random(3);
  std::normal_distribution<float> noise(0.0f, 0.01f);
  msgs::PointLayer layer;
  std::vector<Surface> surfaces;
  const auto sample = [&](SemanticLabel expected, const std::function<Eigen::Vector3f(float, float)>& at, float u_size, float v_size) {
    Surface surface{expected, layer.points.size(), 0};
    for (float u = 0.0f; u <= u_size; u += 0.1f) {
      for (float v = 0.0f; v <= v_size; v += 0.1f) {
        layer.points.push_back(at(u, v) + Eigen::Vector3f(noise(random), noise(random), noise(random)));
        ++surface.count;
      }
    }
    surfaces.push_back(surface);
  };
  const float floor_z = 0.3f;  // the floor need not be at z = 0
  sample(SemanticLabel::kFloor, [&](float u, float v) { return Eigen::Vector3f(u, v, floor_z); }, 8.0f, 6.0f);
  sample(SemanticLabel::kWall, [&](float u, float v) { return Eigen::Vector3f(-0.2f, u, floor_z + 0.2f + v); }, 6.0f, 2.5f);
  sample(SemanticLabel::kWall, [&](float u, float v) { return Eigen::Vector3f(u, 6.2f, floor_z + 0.2f + v); }, 8.0f, 2.5f);
  sample(SemanticLabel::kObstacle, [&](float u, float v) { return Eigen::Vector3f(3.0f + u, 2.0f + v, floor_z + 0.8f); }, 1.5f, 1.0f);
  sample(SemanticLabel::kUnknown, [&](float u, float v) { return Eigen::Vector3f(u, v, floor_z + 3.5f); }, 8.0f, 6.0f);

  const GeometricLabelSummary summary = label_points(layer).value();
  ASSERT_TRUE(summary.floor_height);
  EXPECT_NEAR(*summary.floor_height, floor_z, 0.05);
  ASSERT_EQ(layer.labels.size(), layer.points.size());
  for (const Surface& surface : surfaces) {
    std::size_t right = 0;
    for (std::size_t i = surface.first; i < surface.first + surface.count; ++i) right += layer.labels[i] == surface.expected;
    // Points within a neighbourhood of an edge get a blend of two normals.
    EXPECT_GT(static_cast<double>(right), 0.95 * static_cast<double>(surface.count)) << "label " << static_cast<int>(surface.expected);
  }
  std::size_t counted = 0;
  for (const std::size_t count : summary.counts) counted += count;
  EXPECT_EQ(counted, layer.points.size());
}

TEST(GeometricLabels, WithoutAHorizontalSurfaceThereIsNoFloor) {
  msgs::PointLayer layer;
  for (float y = 0.0f; y < 3.0f; y += 0.1f) {
    for (float z = 0.0f; z < 2.0f; z += 0.1f) layer.points.emplace_back(1.0f, y, z);
  }
  const GeometricLabelSummary summary = label_points(layer).value();
  EXPECT_FALSE(summary.floor_height);
  EXPECT_EQ(summary.counts[static_cast<std::size_t>(SemanticLabel::kWall)], layer.points.size());
  msgs::PointLayer tiny;
  tiny.points = {Eigen::Vector3f::Zero(), Eigen::Vector3f::Ones()};
  EXPECT_EQ(label_points(tiny).value().counts[static_cast<std::size_t>(SemanticLabel::kUnknown)], 2u);
  EXPECT_EQ(tiny.labels.size(), 2u);
}

TEST(GeometricLabels, RefusesABadConfigurationNamingTheField) {
  msgs::PointLayer layer;
  GeometricLabelConfig config;
  config.robot_height_m = 0.1;
  const auto refused = label_points(layer, config);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("robot_height_m"), std::string::npos) << refused.error().message;
  config = {};
  config.normal_neighbours = 2;
  EXPECT_NE(label_points(layer, config).error().message.find("normal_neighbours"), std::string::npos);
}

// Labels leave the map as a PLY of coloured, labelled points (read back byte for byte) and as one
// ROS map per label of the grid (read back: the label's cells occupied, the rest free); layers
// without labels are refused.
TEST(LabelExport, PointsAsColouredPlyAndTheGridAsOneMapPerLabel) {
  msgs::PointLayer points;
  points.points = {Eigen::Vector3f(1.0F, 2.0F, 0.0F), Eigen::Vector3f(3.0F, 2.0F, 1.5F)};
  points.labels = {msgs::SemanticLabel::kFloor, msgs::SemanticLabel::kWall};
  const std::string ply = testing_maps::temp_path("labels.ply");
  ASSERT_TRUE(write_labelled_points_ply(ply, points));
  std::ifstream file(ply, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  const std::size_t body = bytes.find("end_header\n") + 11;
  ASSERT_EQ(bytes.size() - body, 2u * 16u);
  float xyz[3];
  std::memcpy(xyz, bytes.data() + body + 16, sizeof(xyz));
  EXPECT_EQ(xyz[2], 1.5F);
  const std::array<uint8_t, 3> wall = semantic_label_color(msgs::SemanticLabel::kWall);
  EXPECT_EQ(static_cast<uint8_t>(bytes[body + 16 + 12]), wall[0]);
  EXPECT_EQ(static_cast<uint8_t>(bytes[body + 16 + 15]), static_cast<uint8_t>(msgs::SemanticLabel::kWall));

  msgs::OccupancyGridLayer grid;
  grid.resolution = 0.1;
  grid.size_x = 3;
  grid.size_y = 2;
  grid.occupancy = {0.1F, 0.1F, 0.9F, 0.1F, 0.5F, 0.9F};
  grid.labels = {msgs::SemanticLabel::kTraversable, msgs::SemanticLabel::kTraversable, msgs::SemanticLabel::kWall,
                 msgs::SemanticLabel::kTraversable, msgs::SemanticLabel::kUnknown,     msgs::SemanticLabel::kObstacle};
  const Result<std::vector<std::string>> files = write_label_maps(testing_maps::temp_path("labels"), grid);
  ASSERT_TRUE(files.ok()) << files.error().message;
  ASSERT_EQ(files->size(), 8u);  // unknown, wall, obstacle, traversable: YAML + PGM each
  const Result<msgs::OccupancyGridLayer> traversable = read_ros_map(testing_maps::temp_path("labels_traversable.yaml"));
  ASSERT_TRUE(traversable.ok()) << traversable.error().message;
  for (std::size_t i = 0; i < grid.labels.size(); ++i) {
    EXPECT_EQ(traversable->occupancy[i] > 0.5F, grid.labels[i] == msgs::SemanticLabel::kTraversable) << i;
  }

  points.labels.clear();
  EXPECT_FALSE(write_labelled_points_ply(ply, points));
  grid.labels.clear();
  EXPECT_FALSE(write_label_maps(testing_maps::temp_path("labels"), grid).ok());
}

// Segmentation classes as a PLY: the label table in the header, per point its class colour, the
// class index and its probability.
TEST(LabelExport, SegmentationClassesAsColouredPlyWithTheLabelTable) {
  msgs::PointLayer points;
  points.points = {Eigen::Vector3f(1.0F, 2.0F, 0.0F), Eigen::Vector3f(3.0F, 2.0F, 1.5F)};
  points.classes = {1, msgs::kNoClass};
  points.class_probability = {0.875F, 0.0F};
  const std::string ply = testing_maps::temp_path("classes.ply");
  ASSERT_TRUE(write_classified_points_ply(ply, points, {"floor", "shelf"}));
  std::ifstream file(ply, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  EXPECT_NE(bytes.find("comment class 1 shelf\n"), std::string::npos);
  EXPECT_NE(bytes.find("property ushort class\nproperty float class_probability\n"), std::string::npos);
  const std::size_t body = bytes.find("end_header\n") + 11;
  ASSERT_EQ(bytes.size() - body, 2u * 21u);
  const std::array<uint8_t, 3> shelf = semantic_class_color(1);
  EXPECT_EQ(static_cast<uint8_t>(bytes[body + 12]), shelf[0]);
  uint16_t class_index = 0;
  float probability = 0.0F;
  std::memcpy(&class_index, bytes.data() + body + 15, sizeof(class_index));
  std::memcpy(&probability, bytes.data() + body + 17, sizeof(probability));
  EXPECT_EQ(class_index, 1);
  EXPECT_EQ(probability, 0.875F);
  std::memcpy(&class_index, bytes.data() + body + 21 + 15, sizeof(class_index));
  EXPECT_EQ(class_index, msgs::kNoClass);
  EXPECT_EQ(static_cast<uint8_t>(bytes[body + 21 + 12]), 128);
  points.classes.clear();
  EXPECT_FALSE(write_classified_points_ply(ply, points, {}));
}

}  // namespace
}  // namespace hanzo::fusion::maps
