#pragma once
// Maps shared by the maps tests: a FusionMap with every layer and metadata field set, an
// exact comparison, and per-process temporary paths.

#include <filesystem>
#include <string>

#include <unistd.h>

#include <gtest/gtest.h>

#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps::testing_maps {

inline std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("hanzo_maps_" + std::to_string(::getpid()) + "_" + name)).string();
}

inline msgs::FusionMap full_map() {
  msgs::FusionMap map;
  map.map_id = "3f1c2d6e-9a4b-4c1d-8e2f-0123456789ab";
  map.version = 7;
  map.parent_version = 6;
  map.created = Timestamp::from_nanoseconds(1'700'000'000'123'456'789);
  map.frame_id = "map";
  map.datum = GeodeticPoint{47.3769, 8.5417, 408.25};
  map.sensor_configuration = "lidar:\n  topic: /velodyne\n";
  map.provenance.algorithm = "lidar_slam/gicp";
  map.provenance.parameters = "voxel_size: 0.1\n";
  map.provenance.software_version = "0.1.0";
  map.provenance.input_logs.push_back({"file:///data/run1.mcap", std::string(64, 'a')});

  msgs::PointLayer points;
  for (int i = 0; i < 500; ++i) {
    points.points.emplace_back(0.1f * static_cast<float>(i), -0.05f * static_cast<float>(i), 1.0f / static_cast<float>(i + 1));
    points.position_std.push_back(0.01f + 1e-4f * static_cast<float>(i));
    points.labels.push_back(static_cast<msgs::SemanticLabel>(i % 5));
    points.intensities.push_back(static_cast<float>(i % 100) / 100.0f);
    points.classes.push_back(i % 7 == 0 ? msgs::kNoClass : static_cast<uint16_t>(i % 3));
    points.class_probability.push_back(i % 7 == 0 ? 0.0f : 0.5f + 0.001f * static_cast<float>(i % 400));
  }
  points.voxel_size = 0.1;
  map.semantic_classes = {"floor", "wall", "person"};
  map.points = points;

  msgs::OccupancyGridLayer occupancy;
  occupancy.resolution = 0.05;
  occupancy.size_x = 40;
  occupancy.size_y = 30;
  occupancy.size_z = 2;
  occupancy.origin.position = {-1.0, 2.5, 0.0};
  for (uint32_t i = 0; i < 40 * 30 * 2; ++i) {
    occupancy.occupancy.push_back(static_cast<float>(i % 11) / 10.0f);
    occupancy.labels.push_back(static_cast<msgs::SemanticLabel>(i % 3));
    occupancy.classes.push_back(i % 4 == 0 ? msgs::kNoClass : static_cast<uint16_t>(i % 3));
  }
  map.occupancy = occupancy;

  msgs::TsdfLayer tsdf;
  tsdf.voxel_size = 0.05;
  tsdf.truncation_distance = 0.15;
  tsdf.block_size = 4;
  for (int b = 0; b < 20; ++b) {
    msgs::TsdfBlock block;
    block.index = {b, -b, b % 3};
    for (int v = 0; v < 64; ++v) {
      block.distances.push_back(0.15f * static_cast<float>((v + b) % 21 - 10) / 10.0f);
      block.weights.push_back(static_cast<float>(v % 7));
    }
    tsdf.blocks.push_back(block);
  }
  map.tsdf = tsdf;

  msgs::MeshLayer mesh;
  for (int i = 0; i < 300; ++i) {
    mesh.vertices.emplace_back(static_cast<float>(i), static_cast<float>(i % 17), 0.5f);
    mesh.vertex_labels.push_back(msgs::SemanticLabel::kWall);
  }
  for (uint32_t i = 0; i + 2 < 300; ++i) mesh.triangle_indices.insert(mesh.triangle_indices.end(), {i, i + 1, i + 2});
  map.mesh = mesh;

  msgs::GaussianSplatLayer splats;
  splats.sh_degree = 1;
  for (int i = 0; i < 200; ++i) {
    const auto f = static_cast<float>(i);
    splats.positions.insert(splats.positions.end(), {f, -f, 0.5f * f});
    splats.log_scales.insert(splats.log_scales.end(), {-3.0f, -2.5f, -2.0f - 0.001f * f});
    splats.rotations.insert(splats.rotations.end(), {1.0f, 0.0f, 0.01f * f, 0.0f});
    splats.opacity_logits.push_back(0.02f * f - 2.0f);
    for (int k = 0; k < 12; ++k) splats.sh.push_back(0.01f * static_cast<float>((i + k) % 50));
  }
  splats.provenance = {"{\"transforms\":\"scene.json\"}", 40, 3000, 120.5, 10, 24.5, 0.81};
  map.gaussian_splats = splats;

  msgs::NeuralFieldLayer field;
  for (int i = 0; i < 5000; ++i) field.model.push_back(static_cast<char>(i % 256));  // every byte value, zeros included
  field.provenance = {"{\"log\":\"drive.mcap\"}", 30, 500, 60.0, 0, 0.0, 0.0};
  map.neural_field = field;
  return map;
}

inline void expect_same(const msgs::FusionMap& a, const msgs::FusionMap& b) {
  EXPECT_EQ(a.format_version, b.format_version);
  EXPECT_EQ(a.map_id, b.map_id);
  EXPECT_EQ(a.semantic_classes, b.semantic_classes);
  EXPECT_EQ(a.version, b.version);
  EXPECT_EQ(a.parent_version, b.parent_version);
  EXPECT_EQ(a.created, b.created);
  EXPECT_EQ(a.frame_id, b.frame_id);
  ASSERT_EQ(a.datum.has_value(), b.datum.has_value());
  if (a.datum) {
    EXPECT_EQ(a.datum->latitude_deg, b.datum->latitude_deg);
    EXPECT_EQ(a.datum->longitude_deg, b.datum->longitude_deg);
    EXPECT_EQ(a.datum->altitude_m, b.datum->altitude_m);
  }
  EXPECT_EQ(a.sensor_configuration, b.sensor_configuration);
  EXPECT_EQ(a.provenance.algorithm, b.provenance.algorithm);
  EXPECT_EQ(a.provenance.parameters, b.provenance.parameters);
  EXPECT_EQ(a.provenance.software_version, b.provenance.software_version);
  ASSERT_EQ(a.provenance.input_logs.size(), b.provenance.input_logs.size());
  for (std::size_t i = 0; i < a.provenance.input_logs.size(); ++i) {
    EXPECT_EQ(a.provenance.input_logs[i].uri, b.provenance.input_logs[i].uri);
    EXPECT_EQ(a.provenance.input_logs[i].sha256, b.provenance.input_logs[i].sha256);
  }
  ASSERT_EQ(a.points.has_value(), b.points.has_value());
  if (a.points) {
    EXPECT_EQ(a.points->points, b.points->points);
    EXPECT_EQ(a.points->position_std, b.points->position_std);
    EXPECT_EQ(a.points->labels, b.points->labels);
    EXPECT_EQ(a.points->classes, b.points->classes);
    EXPECT_EQ(a.points->class_probability, b.points->class_probability);
    EXPECT_EQ(a.points->intensities, b.points->intensities);
    EXPECT_EQ(a.points->voxel_size, b.points->voxel_size);
  }
  ASSERT_EQ(a.occupancy.has_value(), b.occupancy.has_value());
  if (a.occupancy) {
    EXPECT_EQ(a.occupancy->resolution, b.occupancy->resolution);
    EXPECT_EQ(a.occupancy->size_x, b.occupancy->size_x);
    EXPECT_EQ(a.occupancy->size_y, b.occupancy->size_y);
    EXPECT_EQ(a.occupancy->size_z, b.occupancy->size_z);
    EXPECT_EQ(a.occupancy->origin.position, b.occupancy->origin.position);
    EXPECT_EQ(a.occupancy->origin.orientation.coeffs(), b.occupancy->origin.orientation.coeffs());
    EXPECT_EQ(a.occupancy->occupancy, b.occupancy->occupancy);
    EXPECT_EQ(a.occupancy->labels, b.occupancy->labels);
    EXPECT_EQ(a.occupancy->classes, b.occupancy->classes);
  }
  ASSERT_EQ(a.tsdf.has_value(), b.tsdf.has_value());
  if (a.tsdf) {
    EXPECT_EQ(a.tsdf->voxel_size, b.tsdf->voxel_size);
    EXPECT_EQ(a.tsdf->truncation_distance, b.tsdf->truncation_distance);
    EXPECT_EQ(a.tsdf->block_size, b.tsdf->block_size);
    ASSERT_EQ(a.tsdf->blocks.size(), b.tsdf->blocks.size());
    for (std::size_t i = 0; i < a.tsdf->blocks.size(); ++i) {
      EXPECT_EQ(a.tsdf->blocks[i].index, b.tsdf->blocks[i].index);
      EXPECT_EQ(a.tsdf->blocks[i].distances, b.tsdf->blocks[i].distances);
      EXPECT_EQ(a.tsdf->blocks[i].weights, b.tsdf->blocks[i].weights);
    }
  }
  ASSERT_EQ(a.mesh.has_value(), b.mesh.has_value());
  if (a.mesh) {
    EXPECT_EQ(a.mesh->vertices, b.mesh->vertices);
    EXPECT_EQ(a.mesh->triangle_indices, b.mesh->triangle_indices);
    EXPECT_EQ(a.mesh->vertex_labels, b.mesh->vertex_labels);
  }
  const auto expect_same_provenance = [](const msgs::NeuralProvenance& x, const msgs::NeuralProvenance& y) {
    EXPECT_EQ(x.source, y.source);
    EXPECT_EQ(x.views, y.views);
    EXPECT_EQ(x.iterations, y.iterations);
    EXPECT_EQ(x.training_seconds, y.training_seconds);
    EXPECT_EQ(x.evaluated_views, y.evaluated_views);
    EXPECT_EQ(x.psnr_db, y.psnr_db);
    EXPECT_EQ(x.ssim, y.ssim);
  };
  ASSERT_EQ(a.gaussian_splats.has_value(), b.gaussian_splats.has_value());
  if (a.gaussian_splats) {
    EXPECT_EQ(a.gaussian_splats->sh_degree, b.gaussian_splats->sh_degree);
    EXPECT_EQ(a.gaussian_splats->positions, b.gaussian_splats->positions);
    EXPECT_EQ(a.gaussian_splats->log_scales, b.gaussian_splats->log_scales);
    EXPECT_EQ(a.gaussian_splats->rotations, b.gaussian_splats->rotations);
    EXPECT_EQ(a.gaussian_splats->opacity_logits, b.gaussian_splats->opacity_logits);
    EXPECT_EQ(a.gaussian_splats->sh, b.gaussian_splats->sh);
    expect_same_provenance(a.gaussian_splats->provenance, b.gaussian_splats->provenance);
  }
  ASSERT_EQ(a.neural_field.has_value(), b.neural_field.has_value());
  if (a.neural_field) {
    EXPECT_EQ(a.neural_field->encoding, b.neural_field->encoding);
    EXPECT_EQ(a.neural_field->model, b.neural_field->model);
    expect_same_provenance(a.neural_field->provenance, b.neural_field->provenance);
  }
}

}  // namespace hanzo::fusion::maps::testing_maps
