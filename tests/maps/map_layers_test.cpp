// Map layers built from scans: the intel CARMEN log with its corrected poses, the point map
// under pose corrections, the builder's height band, and the exports (ROS map, PNG).
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/io/carmen_import.hpp"
#include "hanzo/fusion/maps/cell_classes.hpp"
#include "hanzo/fusion/maps/map_builder.hpp"
#include "hanzo/fusion/maps/map_export.hpp"
#include "map_fixtures.hpp"

namespace hanzo::fusion::maps {
namespace {

using ::testing::HasSubstr;

struct LaserLog {
  std::vector<msgs::PointCloudMessage> scans;
  io::Trajectory poses;
};

Result<LaserLog> read_intel() {
  const std::string log = testing_maps::temp_path("intel.mcap");
  LaserLog out;
  {
    std::unique_ptr<io::SensorLogWriter> writer;
    HANZO_ASSIGN_OR_RETURN(writer, io::SensorLogWriter::open(log));
    io::CarmenImportReport report;
    HANZO_ASSIGN_OR_RETURN(report, io::import_carmen(std::string(HANZO_DATA_DIR) + "/laser2d_carmen/intel-corrected.log.gz",
                                                     *writer, io::CarmenImportConfig{}));
    out.poses = report.scan_poses;
    HANZO_RETURN_IF_ERROR(writer->close());
  }
  std::unique_ptr<io::SensorLogReader> reader;
  HANZO_ASSIGN_OR_RETURN(reader, io::SensorLogReader::open(log));
  io::LogEntry entry;
  while (*reader->next(entry)) {
    out.scans.push_back(std::get<msgs::PointCloudMessage>(std::get<msgs::SensorMessage>(entry.message)));
  }
  std::filesystem::remove(log);
  return out;
}

TEST(MapLayers, IntelOccupancyGridWallsLineUpWithTheScans) {
  auto log = read_intel();
  ASSERT_TRUE(log.ok()) << log.error().message;
  ASSERT_EQ(log->scans.size(), log->poses.size());
  MapBuilderConfig config;
  config.points = false;
  config.occupancy_2d_config.resolution = 0.05;  // the spec's indoor default
  auto builder = MapBuilder::create(config);
  ASSERT_TRUE(builder.ok());
  for (std::size_t i = 0; i < log->scans.size(); ++i) {
    ASSERT_EQ(log->scans[i].timestamp, log->poses.timestamps[i]);
    auto scan = cloud::from_message(log->scans[i]);
    ASSERT_TRUE(scan.ok());
    ASSERT_TRUE(builder->insert(log->poses.pose_se3(i), *scan));
  }
  const OccupancyGrid2D& grid = *builder->occupancy_2d();
  // Every logged end point, placed with its scan's corrected pose: at least 95 % land in
  // occupied cells (the criterion).
  std::size_t end_points = 0;
  std::size_t in_occupied = 0;
  for (std::size_t i = 0; i < log->scans.size(); ++i) {
    const SE3 pose = log->poses.pose_se3(i);
    for (const Eigen::Vector3f& point : log->scans[i].points) {
      const Eigen::Vector3d world = pose * point.cast<double>();
      ++end_points;
      if (grid.state(Eigen::Vector2d(world.head<2>())) == CellState::kOccupied) ++in_occupied;
    }
  }
  const double fraction = static_cast<double>(in_occupied) / static_cast<double>(end_points);
  std::printf("intel: %zu end points, %.2f %% in occupied cells, %zu observed cells, %.1f MB\n", end_points, 100.0 * fraction,
              grid.observed_cell_count(), static_cast<double>(grid.memory_bytes()) / 1e6);
  EXPECT_GE(fraction, 0.95);
  // The building is about 30 m x 30 m.
  const auto bounds = grid.observed_bounds();
  ASSERT_TRUE(bounds.has_value());
  const Eigen::Vector2d extent = (bounds->second - bounds->first).cast<double>() * 0.05;
  EXPECT_GT(extent.minCoeff(), 20.0);
  EXPECT_LT(extent.maxCoeff(), 60.0);
}

cloud::PointCloud plane_cloud(double x) {
  cloud::PointCloud cloud;
  for (double y = -1.0; y <= 1.0; y += 0.02) {
    for (double z = 0.0; z <= 1.0; z += 0.02) {
      cloud.positions.emplace_back(x, y, z);
      cloud.intensities.push_back(0.5f);
    }
  }
  return cloud;
}

TEST(MapLayers, PointMapFollowsCorrectedPoses) {
  auto map = PointMap::create(PointMapConfig{.voxel_size = 0.1, .moving_points = {}});
  ASSERT_TRUE(map.ok());
  const SE3 first(SO3::identity(), Eigen::Vector3d::Zero());
  const SE3 second(SO3::identity(), Eigen::Vector3d(0.0, 5.0, 0.0));
  ASSERT_TRUE(map->add_keyframe(0, first, plane_cloud(2.0)));
  ASSERT_TRUE(map->add_keyframe(1, second, plane_cloud(2.0)));
  const std::size_t voxels = map->cloud().size();
  // Two 2 m x 1 m walls at 0.1 m: about 21 x 11 voxels each.
  EXPECT_GE(voxels, 2u * 200u);
  EXPECT_LT(voxels, 2u * 300u);
  for (const Eigen::Vector3f& point : map->cloud().positions) EXPECT_NEAR(point.x(), 2.0, 1e-4);

  // A loop closure moves keyframe 1 by 3 m in x: its wall moves, keyframe 0's does not.
  ASSERT_TRUE(map->set_poses({{1, SE3(SO3::identity(), Eigen::Vector3d(3.0, 5.0, 0.0))}}));
  std::size_t moved = 0;
  for (const Eigen::Vector3f& point : map->cloud().positions) {
    EXPECT_TRUE(std::abs(point.x() - 2.0f) < 1e-4f || std::abs(point.x() - 5.0f) < 1e-4f);
    if (point.x() > 4.0f) {
      ++moved;
      EXPECT_GT(point.y(), 3.9f);
    }
  }
  EXPECT_GE(moved, 200u);
  const msgs::PointLayer layer = map->to_layer();
  ASSERT_EQ(layer.position_std.size(), layer.points.size());
  ASSERT_EQ(layer.intensities.size(), layer.points.size());
  // Points of a plane spread within a voxel: about voxel / sqrt(12) in two axes.
  for (float spread : layer.position_std) EXPECT_LT(spread, 0.1f);
  EXPECT_THAT(map->set_poses({{9, first}}).error().message, HasSubstr("no keyframe 9"));

  cloud::PointCloud bad = plane_cloud(1.0);
  bad.positions[3].x() = NAN;
  EXPECT_FALSE(map->add_keyframe(2, first, bad));
  EXPECT_EQ(map->keyframe_count(), 2u);
}

// Segmentation classes: a keyframe's point and later scans' votes for it fuse into the voxel's
// class with the posterior of point_map.hpp; the grid's cells take their points' classes.
TEST(MapLayers, PointMapFusesSegmentationClassesPerVoxel) {
  auto map = PointMap::create(PointMapConfig{.voxel_size = 0.1, .segmentation_accuracy = 0.9, .moving_points = {}});
  ASSERT_TRUE(map.ok());
  const uint16_t floor = map->class_index("floor"), shelf = map->class_index("shelf");
  EXPECT_EQ(map->class_index("person"), 2);
  EXPECT_EQ(map->class_index("floor"), floor);
  cloud::PointCloud scan;
  scan.positions = {{0.02F, 0.02F, 0.02F}, {0.52F, 0.02F, 0.02F}, {1.02F, 0.02F, 0.02F}};
  const std::vector<uint16_t> classes{floor, shelf, msgs::kNoClass};
  ASSERT_TRUE(map->add_keyframe(0, SE3(), scan, classes));
  // A later scan from 1 m back sees the first point as floor again and the second as floor
  // once; a point where the keyframe has none is dropped.
  const SE3 T_world_later(SO3::identity(), Eigen::Vector3d(-1.0, 0.0, 0.0));
  const std::vector<Eigen::Vector3f> later{{1.02F, 0.02F, 0.02F}, {1.52F, 0.02F, 0.02F}, {3.0F, 0.0F, 0.0F}};
  ASSERT_TRUE(map->add_class_votes(0, T_world_later, later, std::vector<uint16_t>{floor, floor, shelf}));
  ASSERT_TRUE(map->add_class_votes(0, T_world_later, later, std::vector<uint16_t>{floor, shelf, shelf}));
  const msgs::PointLayer layer = map->to_layer();
  ASSERT_EQ(layer.points.size(), 3u);
  ASSERT_EQ(layer.classes.size(), 3u);
  // Point 0: floor 3 times. r = 0.9 * 2 / 0.1 = 18: P = 18^3 / (18^3 + 1 + 1).
  EXPECT_EQ(layer.classes[0], floor);
  EXPECT_NEAR(layer.class_probability[0], 5832.0 / 5834.0, 1e-6);
  // Point 1: shelf twice, floor once: 18^2 / (18^2 + 18 + 1).
  EXPECT_EQ(layer.classes[1], shelf);
  EXPECT_NEAR(layer.class_probability[1], 324.0 / 343.0, 1e-6);
  EXPECT_EQ(layer.classes[2], msgs::kNoClass);
  EXPECT_EQ(layer.class_probability[2], 0.0F);
  // Refused, nothing changed.
  EXPECT_THAT(map->add_class_votes(0, SE3(), later, std::vector<uint16_t>{floor}).error().message, HasSubstr("1 classes for 3 points"));
  EXPECT_THAT(map->add_class_votes(0, SE3(), later, std::vector<uint16_t>{7, 0, 0}).error().message, HasSubstr("class 7 past the label table's 3 classes"));
  EXPECT_THAT(map->add_class_votes(5, SE3(), later, classes).error().message, HasSubstr("no keyframe 5"));
  EXPECT_EQ(map->to_layer().classes, layer.classes);

  msgs::OccupancyGridLayer grid;
  grid.resolution = 0.5;
  grid.size_x = 4;
  grid.size_y = 1;
  grid.occupancy.assign(4, 0.5F);
  grid.origin.position = Eigen::Vector3d(0.0, -0.25, 0.0);
  classify_cells(grid, layer);
  EXPECT_EQ(grid.classes, (std::vector<uint16_t>{floor, shelf, msgs::kNoClass, msgs::kNoClass}));
}

TEST(MapLayers, BuilderHeightBandKeepsObstaclesAndDropsTheGround) {
  MapBuilderConfig config;
  config.occupancy_2d_config.resolution = 0.1;
  config.occupancy_3d = true;
  config.min_height = -0.5;
  config.max_height = 0.5;
  config.tsdf = true;
  config.tsdf_config.voxel_size = 0.1;
  auto builder = MapBuilder::create(config);
  ASSERT_TRUE(builder.ok());
  cloud::PointCloud scan = plane_cloud(3.0);  // a wall 3 m ahead, z 0 .. 1 in the sensor frame
  for (double x = 0.5; x < 3.0; x += 0.05) scan.positions.emplace_back(x, 0.0, -1.0);  // ground, 1 m below
  scan.intensities.resize(scan.positions.size(), 0.2f);
  const SE3 pose(SO3::identity(), Eigen::Vector3d(0.05, 0.05, 1.0));
  for (int i = 0; i < 15; ++i) ASSERT_TRUE(builder->insert(pose, scan));
  const OccupancyGrid2D& grid = *builder->occupancy_2d();
  EXPECT_EQ(grid.state(Eigen::Vector2d(3.02, 0.0)), CellState::kOccupied);
  EXPECT_EQ(grid.state(Eigen::Vector2d(1.5, 0.0)), CellState::kFree);  // ground returns left out
  EXPECT_EQ(builder->occupancy_3d()->state(Eigen::Vector3d(1.52, 0.02, 0.02)), CellState::kOccupied);
  EXPECT_EQ(builder->summary().scans, 15u);

  msgs::FusionMap map;
  map.map_id = "built";
  builder->write_layers(map);
  ASSERT_TRUE(map.points.has_value());
  ASSERT_TRUE(map.occupancy.has_value());
  EXPECT_GT(map.occupancy->size_z, 1u);  // the 3D grid when both are built
  ASSERT_TRUE(map.tsdf.has_value() && map.mesh.has_value());
  std::size_t on_wall = 0;
  for (const Eigen::Vector3f& vertex : map.mesh->vertices) on_wall += std::abs(vertex.x() - 3.05f) < 0.1f ? 1 : 0;
  EXPECT_GT(on_wall, 100u);  // the wall 3 m ahead of the sensor at x = 0.05

  // Labelled (write_map): the wall's occupied voxels and mesh vertices are walls.
  msgs::FusionMap labelled;
  builder->write_map(labelled);
  ASSERT_EQ(labelled.occupancy->labels.size(), labelled.occupancy->occupancy.size());
  std::size_t occupied = 0, occupied_walls = 0;
  for (std::size_t voxel = 0; voxel < labelled.occupancy->occupancy.size(); ++voxel) {
    if (labelled.occupancy->occupancy[voxel] < config.occupancy_3d_config.occupied_threshold) {
      EXPECT_EQ(labelled.occupancy->labels[voxel], msgs::SemanticLabel::kUnknown);
      continue;
    }
    ++occupied;
    occupied_walls += labelled.occupancy->labels[voxel] == msgs::SemanticLabel::kWall;
  }
  EXPECT_GT(occupied, 10u);
  EXPECT_GT(static_cast<double>(occupied_walls), 0.9 * static_cast<double>(occupied)) << occupied_walls << " of " << occupied;
  ASSERT_EQ(labelled.mesh->vertex_labels.size(), labelled.mesh->vertices.size());
  std::size_t wall_vertices = 0, wall_vertices_labelled = 0;
  for (std::size_t v = 0; v < labelled.mesh->vertices.size(); ++v) {
    if (std::abs(labelled.mesh->vertices[v].x() - 3.05f) >= 0.1f || std::abs(labelled.mesh->vertices[v].z() - 1.5f) > 0.4f) continue;
    ++wall_vertices;
    wall_vertices_labelled += labelled.mesh->vertex_labels[v] == msgs::SemanticLabel::kWall;
  }
  EXPECT_GT(wall_vertices, 50u);
  EXPECT_GT(static_cast<double>(wall_vertices_labelled), 0.9 * static_cast<double>(wall_vertices)) << wall_vertices_labelled << " of " << wall_vertices;

  cloud::PointCloud far = scan;
  far.positions[0].x() = 1e9f;
  EXPECT_FALSE(builder->insert(pose, far));
  EXPECT_EQ(builder->summary().scans, 15u);
}

TEST(MapLayers, RosMapExportReadsBackCellByCell) {
  OccupancyGrid2D grid(OccupancyConfig{.resolution = 0.05});
  std::vector<Eigen::Vector2d> scan;
  for (double y = -1.0; y <= 1.0; y += 0.01) scan.emplace_back(2.001, y);
  for (int i = 0; i < 15; ++i) ASSERT_TRUE(grid.insert_scan(Eigen::Vector2d(-0.49, -0.49), scan));
  const msgs::OccupancyGridLayer layer = grid.to_layer();

  const std::string yaml = testing_maps::temp_path("ros_map.yaml");
  ASSERT_TRUE(write_ros_map(yaml, layer));
  std::ifstream text(yaml);
  const std::string contents((std::istreambuf_iterator<char>(text)), std::istreambuf_iterator<char>());
  EXPECT_THAT(contents, HasSubstr("image: hanzo_maps_"));
  EXPECT_THAT(contents, HasSubstr("resolution: 0.05"));
  EXPECT_THAT(contents, HasSubstr("mode: trinary"));

  auto read = read_ros_map(yaml);
  ASSERT_TRUE(read.ok()) << read.error().message;
  EXPECT_EQ(read->size_x, layer.size_x);
  EXPECT_EQ(read->size_y, layer.size_y);
  EXPECT_NEAR((read->origin.position - layer.origin.position).norm(), 0.0, 1e-12);
  auto restored = OccupancyGrid2D::from_layer(*read, OccupancyConfig{});
  ASSERT_TRUE(restored.ok()) << restored.error().message;
  std::size_t compared = 0;
  grid.for_each_observed([&](const Eigen::Vector2i& cell, float) {
    EXPECT_EQ(restored->state(cell), grid.state(cell));
    ++compared;
  });
  EXPECT_GT(compared, 1000u);

  const std::string png = testing_maps::temp_path("grid.png");
  ASSERT_TRUE(write_occupancy_png(png, layer));
  const cv::Mat image = cv::imread(png, cv::IMREAD_UNCHANGED);
  EXPECT_EQ(image.cols, static_cast<int>(layer.size_x));
  EXPECT_EQ(image.rows, static_cast<int>(layer.size_y));

  std::ofstream(yaml) << "image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n";
  EXPECT_THAT(read_ros_map(yaml).error().message, HasSubstr("missing.pgm"));
  std::ofstream(yaml) << "image: x.pgm\nresolution: 0.05\norigin: [0, 0]\n";
  EXPECT_THAT(read_ros_map(yaml).error().message, HasSubstr("origin"));
  for (const auto& path : {yaml, png, std::filesystem::path(yaml).replace_extension(".pgm").string()}) {
    std::filesystem::remove(path);
  }
}

TEST(MapLayers, PointsPictureIsTopDown) {
  msgs::PointLayer layer;
  for (int i = 0; i < 100; ++i) layer.points.emplace_back(0.1f * static_cast<float>(i), 0.0f, 0.01f * static_cast<float>(i));
  layer.points.emplace_back(0.0f, 5.0f, 0.0f);
  const std::string png = testing_maps::temp_path("points.png");
  ASSERT_TRUE(write_points_png(png, layer, 0.1));
  const cv::Mat image = cv::imread(png, cv::IMREAD_COLOR);
  EXPECT_EQ(image.cols, 101);  // 9.9 m / 0.1 m + 1
  EXPECT_EQ(image.rows, 51);
  EXPECT_EQ(image.at<cv::Vec3b>(25, 50), cv::Vec3b(255, 255, 255));  // empty: white
  EXPECT_NE(image.at<cv::Vec3b>(50, 50), cv::Vec3b(255, 255, 255));  // the row of points at y = 0
  EXPECT_FALSE(write_points_png(png, msgs::PointLayer{}));
  std::filesystem::remove(png);
}

TEST(MapLayers, MeshFilesHoldEveryVertexAndTriangle) {
  msgs::MeshLayer mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  mesh.triangle_indices = {0, 1, 2, 0, 1, 3, 0, 2, 3, 1, 2, 3};
  const std::string ply = testing_maps::temp_path("mesh.ply");
  const std::string obj = testing_maps::temp_path("mesh.obj");
  ASSERT_TRUE(write_mesh(ply, mesh));
  ASSERT_TRUE(write_mesh(obj, mesh));
  std::ifstream ply_file(ply, std::ios::binary);
  const std::string ply_bytes((std::istreambuf_iterator<char>(ply_file)), std::istreambuf_iterator<char>());
  const std::size_t header_end = ply_bytes.find("end_header\n") + 11;
  EXPECT_THAT(ply_bytes.substr(0, header_end), HasSubstr("element vertex 4\n"));
  EXPECT_THAT(ply_bytes.substr(0, header_end), HasSubstr("element face 4\n"));
  EXPECT_EQ(ply_bytes.size(), header_end + 4 * 12 + 4 * 13);
  float third_vertex_y = 0.0f;
  std::memcpy(&third_vertex_y, ply_bytes.data() + header_end + 2 * 12 + 4, sizeof(float));
  EXPECT_EQ(third_vertex_y, 1.0f);
  std::ifstream obj_file(obj);
  const std::string obj_text((std::istreambuf_iterator<char>(obj_file)), std::istreambuf_iterator<char>());
  EXPECT_THAT(obj_text, HasSubstr("v 0 0 1\n"));
  EXPECT_THAT(obj_text, HasSubstr("f 2 3 4\n"));  // 1-based
  mesh.triangle_indices.push_back(9);
  EXPECT_FALSE(write_mesh(ply, mesh));
  EXPECT_THAT(write_mesh(testing_maps::temp_path("mesh.stl"), msgs::MeshLayer{}).error().message, HasSubstr(".ply or .obj"));
  std::filesystem::remove(ply);
  std::filesystem::remove(obj);
}

}  // namespace
}  // namespace hanzo::fusion::maps
