#include <cmath>
#include <filesystem>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/maps/map_diff.hpp"
#include "hanzo/fusion/maps/occupancy_grid.hpp"
#include "hanzo/fusion/maps/redaction.hpp"
#include "map_fixtures.hpp"

namespace hanzo::fusion::maps {
namespace {

using ::testing::HasSubstr;

/// A room scanned from its centre: walls of a 6 m x 6 m square, plus optional boxes (centres).
msgs::FusionMap room(const std::vector<Eigen::Vector2d>& boxes) {
  OccupancyGrid2D grid(OccupancyConfig{.resolution = 0.1});
  std::vector<Eigen::Vector2d> scan;
  for (int i = 0; i < 3600; ++i) {
    const double angle = 2.0 * M_PI * i / 3600.0;
    const Eigen::Vector2d direction(std::cos(angle), std::sin(angle));
    double range = 3.0 / std::max(std::abs(direction.x()), std::abs(direction.y()));  // the square's wall
    for (const Eigen::Vector2d& box : boxes) {
      // A 0.4 m box seen as a circle of radius 0.2 m.
      const double along = box.dot(direction);
      const double across = (box - along * direction).norm();
      if (along > 0.0 && across < 0.2) range = std::min(range, along - std::sqrt(0.04 - across * across));
    }
    scan.push_back(0.001 * Eigen::Vector2d(1, 1) + range * direction);
  }
  for (int i = 0; i < 20; ++i) EXPECT_TRUE(grid.insert_scan(Eigen::Vector2d(0.05, 0.05), scan));
  msgs::FusionMap map;
  map.map_id = "room";
  map.occupancy = grid.to_layer();
  msgs::PointLayer points;
  for (const Eigen::Vector2d& point : scan) points.points.emplace_back(point.x(), point.y(), 0.5f);
  points.voxel_size = 0.1;
  map.points = points;
  return map;
}

TEST(MapDiff, APlacedBoxAppearsAndARemovedOneVanishes) {
  const msgs::FusionMap before = room({{1.5, 0.0}});
  const msgs::FusionMap after = room({{-1.0, 1.0}});
  auto diff = diff_maps(before, after);
  ASSERT_TRUE(diff.ok()) << diff.error().message;
  ASSERT_TRUE(diff->occupancy.has_value());
  const OccupancyDiff& occupancy = *diff->occupancy;
  EXPECT_GT(occupancy.became_occupied, 3u);
  EXPECT_GT(occupancy.became_free, 3u);
  // Every appeared cell is at the new box, every vanished one at the old box.
  for (const Eigen::Vector3i& cell : occupancy.appeared_cells) {
    EXPECT_LT(((cell.head<2>().cast<double>().array() + 0.5) * 0.1 - Eigen::Array2d(-1.0, 1.0)).matrix().norm(), 0.35);
  }
  for (const Eigen::Vector3i& cell : occupancy.vanished_cells) {
    EXPECT_LT(((cell.head<2>().cast<double>().array() + 0.5) * 0.1 - Eigen::Array2d(1.5, 0.0)).matrix().norm(), 0.35);
  }
  ASSERT_TRUE(diff->points.has_value());
  // Points added: the new box, and the wall that the old box hid.
  std::size_t at_new_box = 0;
  for (const Eigen::Vector3f& point : diff->points->added) {
    const bool on_box = (point.head<2>().cast<double>() - Eigen::Vector2d(-1.0, 1.0)).norm() < 0.5;
    const bool on_wall = point.head<2>().cwiseAbs().maxCoeff() > 2.8f;
    EXPECT_TRUE(on_box || on_wall) << point.transpose();
    at_new_box += on_box ? 1 : 0;
  }
  EXPECT_GT(at_new_box, 2u);

  // Same map twice: nothing changed.
  auto same = diff_maps(before, before);
  ASSERT_TRUE(same.ok());
  EXPECT_EQ(same->occupancy->became_occupied + same->occupancy->became_free + same->occupancy->newly_observed, 0u);
  EXPECT_TRUE(same->points->added.empty());
  EXPECT_TRUE(same->points->removed.empty());

  const std::string png = testing_maps::temp_path("diff.png");
  EXPECT_TRUE(write_diff_png(png, *after.occupancy, occupancy));
  EXPECT_TRUE(std::filesystem::exists(png));
  std::filesystem::remove(png);
}

TEST(MapDiff, GridsThatDoNotLineUpAreRefused) {
  msgs::FusionMap before = room({});
  msgs::FusionMap after = before;
  after.occupancy->resolution = 0.2;
  after.occupancy->origin.position = before.occupancy->origin.position * 2.0;
  EXPECT_THAT(diff_maps(before, after).error().message, HasSubstr("resolutions differ"));
  msgs::FusionMap no_layers;
  no_layers.map_id = "empty";
  EXPECT_THAT(diff_maps(before, no_layers).error().message, HasSubstr("no occupancy or point layer"));
}

TEST(Redaction, LabelsGoAndGeometryCoarsensWithoutLosingObstacles) {
  msgs::FusionMap map = testing_maps::full_map();
  for (std::size_t i = 0; i < map.mesh->vertices.size(); ++i) {  // a strip of 0.1 m triangles
    map.mesh->vertices[i] = Eigen::Vector3f(0.1f * static_cast<float>(i / 2), 0.1f * static_cast<float>(i % 2), 0.5f);
  }
  RedactionReport report;
  auto redacted = redact_map(map, RedactionConfig{.drop_labels = true, .resolution = 0.5, .drop_sensor_details = true}, &report);
  ASSERT_TRUE(redacted.ok()) << redacted.error().message;
  EXPECT_TRUE(redacted->points->labels.empty());
  EXPECT_TRUE(redacted->occupancy->labels.empty());
  EXPECT_TRUE(redacted->mesh->vertex_labels.empty());
  EXPECT_EQ(redacted->occupancy->resolution, 0.5);
  EXPECT_LT(redacted->points->points.size(), map.points->points.size());
  EXPECT_EQ(redacted->points->voxel_size, 0.5);
  EXPECT_FALSE(redacted->tsdf.has_value());
  EXPECT_FALSE(redacted->gaussian_splats.has_value());  // photorealistic: gone at any resolution
  EXPECT_FALSE(redacted->neural_field.has_value());
  EXPECT_THAT(report.actions, ::testing::Contains("gaussian_splats: layer removed"));
  EXPECT_TRUE(redacted->sensor_configuration.empty());
  EXPECT_EQ(redacted->provenance.input_logs[0].uri, "redacted");
  EXPECT_THAT(redacted->provenance.parameters, HasSubstr("redaction: {drop_labels: true, resolution: 0.5"));
  EXPECT_EQ(redacted->map_id, map.map_id);  // a store makes it the next version, derived from this one
  EXPECT_EQ(redacted->version, map.version);
  EXPECT_GE(report.actions.size(), 5u);

  // Occupancy: every fine occupied cell lies in a coarse cell at least as occupied.
  auto fine = OccupancyGrid3D::from_layer(*map.occupancy, OccupancyConfig{.probability_min = 0.001, .probability_max = 0.999});
  auto coarse = OccupancyGrid3D::from_layer(*redacted->occupancy, OccupancyConfig{.probability_min = 0.001, .probability_max = 0.999});
  ASSERT_TRUE(fine.ok() && coarse.ok());
  fine->for_each_observed([&](const Eigen::Vector3i& cell, float) {
    const Eigen::Vector3d centre = fine->cell_center(cell);
    EXPECT_GE(coarse->probability(centre) + 1e-6, fine->probability(cell));
  });
  // The mesh keeps only triangles whose corners fell in different 0.5 m voxels.
  for (uint32_t index : redacted->mesh->triangle_indices) EXPECT_LT(index, redacted->mesh->vertices.size());
  EXPECT_LT(redacted->mesh->vertices.size(), map.mesh->vertices.size());

  EXPECT_FALSE(redact_map(map, RedactionConfig{.resolution = -1.0}).ok());
}

// Without drop_labels the coarse points keep the most frequent geometric label and segmentation
// class of the points they merge, and the map its label table; with it both go.
TEST(Redaction, LabelsAndSegmentationClassesSurviveCoarseningUnlessDropped) {
  msgs::FusionMap map;
  map.map_id = "labelled";
  map.semantic_classes = {"floor", "person"};
  msgs::PointLayer points;
  points.voxel_size = 0.1;
  // Five points in one 0.5 m voxel (three floor, two person), one alone in another.
  for (const float x : {0.05F, 0.15F, 0.25F, 0.35F, 0.45F, 1.25F}) points.points.emplace_back(x, 0.1F, 0.1F);
  points.labels = {msgs::SemanticLabel::kFloor, msgs::SemanticLabel::kFloor, msgs::SemanticLabel::kWall, msgs::SemanticLabel::kFloor,
                   msgs::SemanticLabel::kWall, msgs::SemanticLabel::kObstacle};
  points.classes = {0, 1, 0, 1, 0, msgs::kNoClass};
  points.class_probability = {0.9F, 0.8F, 0.7F, 0.8F, 0.8F, 0.0F};
  map.points = points;
  const msgs::FusionMap kept = redact_map(map, RedactionConfig{.drop_labels = false, .resolution = 0.5}).value();
  ASSERT_EQ(kept.points->points.size(), 2u);
  EXPECT_EQ(kept.semantic_classes, map.semantic_classes);
  EXPECT_EQ(kept.points->labels, (std::vector<msgs::SemanticLabel>{msgs::SemanticLabel::kFloor, msgs::SemanticLabel::kObstacle}));
  EXPECT_EQ(kept.points->classes, (std::vector<uint16_t>{0, msgs::kNoClass}));
  EXPECT_NEAR(kept.points->class_probability[0], 0.8F, 1e-6F);  // the floor points' mean
  EXPECT_EQ(kept.points->class_probability[1], 0.0F);
  const msgs::FusionMap dropped = redact_map(map, RedactionConfig{.drop_labels = true, .resolution = 0.5}).value();
  EXPECT_TRUE(dropped.points->labels.empty());
  EXPECT_TRUE(dropped.points->classes.empty());
  EXPECT_TRUE(dropped.points->class_probability.empty());
  EXPECT_TRUE(dropped.semantic_classes.empty());
}

}  // namespace
}  // namespace hanzo::fusion::maps
