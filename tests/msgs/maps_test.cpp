#include "hanzo/fusion/msgs/map_convert.hpp"
#include "hanzo/fusion/msgs/map_validation.hpp"

#include <limits>

#include <google/protobuf/util/message_differencer.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion::msgs {
namespace {

using ::testing::HasSubstr;

v1::Point3 point(float x, float y, float z) {
  v1::Point3 p;
  p.set_x(x);
  p.set_y(y);
  p.set_z(z);
  return p;
}

// A map with every layer and every metadata field set.
v1::FusionMap full_map() {
  v1::FusionMap map;
  map.set_format_version(kFusionMapFormatVersion);
  map.set_map_id("2f1c6a8e-7d3b-4c55-9a10-5e3a2b1f0c9d");
  map.set_version(3);
  map.set_parent_version(2);
  map.set_created_ns(1'771'842'930'000'000'000);
  map.set_frame_id("world");
  map.mutable_datum()->set_latitude(47.378177);
  map.mutable_datum()->set_longitude(8.540192);
  map.mutable_datum()->set_altitude(408.0);
  map.set_sensor_configuration("fusion:\n  sensors: {}\n");
  v1::InputLog* log = map.mutable_provenance()->add_input_logs();
  log->set_uri("logs/run1.mcap");
  log->set_sha256(std::string(64, 'a'));
  map.mutable_provenance()->set_algorithm("lidar_slam/gicp");
  map.mutable_provenance()->set_software_version("0.1.0");
  v1::PointLayer* points = map.mutable_points();
  for (int i = 0; i < 10; ++i) {
    *points->add_points() = point(0.1F * i, 1.0F, -0.5F);
    points->add_position_std(0.02F);
    points->add_labels(i % 2 == 0 ? v1::LABEL_FLOOR : v1::LABEL_WALL);
    points->add_intensities(0.5F);
    points->add_classes(i == 9 ? kNoClass : static_cast<uint32_t>(i % 3));
    points->add_class_probability(i == 9 ? 0.0F : 0.95F);
  }
  points->set_voxel_size(0.1);
  for (const char* name : {"floor", "shelf", "person"}) map.add_semantic_classes(name);
  v1::OccupancyGridLayer* grid = map.mutable_occupancy();
  grid->set_resolution(0.05);
  grid->set_size_x(4);
  grid->set_size_y(3);
  grid->set_size_z(1);
  grid->mutable_origin()->mutable_position()->set_x(-1.0);
  grid->mutable_origin()->mutable_orientation()->set_w(1.0);
  for (int i = 0; i < 12; ++i) {
    grid->add_occupancy(i % 3 == 0 ? 0.9F : 0.5F);
    grid->add_classes(i % 3 == 0 ? 1 : kNoClass);
  }
  v1::TsdfLayer* tsdf = map.mutable_tsdf();
  tsdf->set_voxel_size(0.05);
  tsdf->set_truncation_distance(0.15);
  tsdf->set_block_size(2);
  v1::TsdfBlock* block = tsdf->add_blocks();
  block->set_index_x(-1);
  for (int i = 0; i < 8; ++i) {
    block->add_distances(0.01F * i);
    block->add_weights(1.0F);
  }
  v1::MeshLayer* mesh = map.mutable_mesh();
  *mesh->add_vertices() = point(0, 0, 0);
  *mesh->add_vertices() = point(1, 0, 0);
  *mesh->add_vertices() = point(0, 1, 0);
  for (uint32_t index : {0U, 1U, 2U}) mesh->add_triangle_indices(index);
  v1::GaussianSplatLayer* splats = map.mutable_gaussian_splats();
  splats->set_sh_degree(0);
  for (int i = 0; i < 2; ++i) {
    for (float value : {0.1F * i, 0.0F, 1.0F}) splats->add_positions(value);
    for (float value : {-3.0F, -3.0F, -3.0F}) splats->add_log_scales(value);
    for (float value : {1.0F, 0.0F, 0.0F, 0.0F}) splats->add_rotations(value);
    splats->add_opacity_logits(0.5F);
    for (float value : {0.2F, 0.3F, 0.4F}) splats->add_sh(value);
  }
  splats->mutable_provenance()->set_views(12);
  v1::NeuralFieldLayer* field = map.mutable_neural_field();
  field->set_encoding("hznerf1");
  field->add_model_parts(std::string("HZNERF1\n\0\1", 10));
  field->mutable_provenance()->set_iterations(500);
  return map;
}

void expect_rejected(const v1::FusionMap& map, const std::string& field, const std::string& text) {
  const Status status = validate(map);
  ASSERT_FALSE(status.ok()) << "expected rejection of " << field;
  EXPECT_EQ(status.error().field, field) << status.error().message;
  EXPECT_THAT(status.error().message, HasSubstr(text));
}

TEST(MapValidation, FullMapIsValidAndRoundTripsExactly) {
  const v1::FusionMap map = full_map();
  const Status status = validate(map);
  ASSERT_TRUE(status.ok()) << status.error().message;
  v1::FusionMap parsed;
  ASSERT_TRUE(parsed.ParseFromString(map.SerializeAsString()));
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(map, parsed));
  EXPECT_TRUE(validate(parsed).ok());
}

TEST(MapValidation, UnknownFormatVersionIsRejected) {
  v1::FusionMap map = full_map();
  map.set_format_version(2);
  expect_rejected(map, "format_version", "unrecognized format version 2 (this build reads version 1)");
  map.set_format_version(0);  // a message that never set it
  expect_rejected(map, "format_version", "unrecognized format version 0");
}

TEST(MapValidation, BadLayersAreRejectedNamingTheField) {
  v1::FusionMap map = full_map();
  map.clear_map_id();
  expect_rejected(map, "map_id", "empty");
  map = full_map();
  map.mutable_datum()->set_latitude(95.0);
  expect_rejected(map, "datum", "outside [-90, 90]");
  map = full_map();
  map.mutable_points()->mutable_points(3)->set_y(std::numeric_limits<float>::quiet_NaN());
  expect_rejected(map, "points.points[3]", "non-finite");
  map = full_map();
  map.mutable_points()->mutable_labels()->RemoveLast();
  expect_rejected(map, "points.labels", "9 values for 10 points");
  map = full_map();
  map.mutable_points()->set_labels(0, static_cast<v1::SemanticLabel>(99));
  expect_rejected(map, "points.labels[0]", "unknown label 99");
  map = full_map();
  map.mutable_points()->set_classes(4, 3);
  expect_rejected(map, "points.classes[4]", "class 3 past the 3 semantic_classes");
  map = full_map();
  map.mutable_points()->mutable_class_probability()->RemoveLast();
  expect_rejected(map, "points.class_probability", "9 values for 10 points");
  map = full_map();
  map.mutable_points()->set_class_probability(2, 1.5F);
  expect_rejected(map, "points.class_probability[2]", "outside [0, 1]");
  map = full_map();
  map.mutable_occupancy()->set_classes(3, 7);
  expect_rejected(map, "occupancy.classes[3]", "class 7 past the 3 semantic_classes");
  map = full_map();
  map.set_semantic_classes(1, "");
  expect_rejected(map, "semantic_classes[1]", "empty");
  map = full_map();
  map.mutable_occupancy()->set_size_y(4);
  expect_rejected(map, "occupancy.occupancy", "12 cells, but 4x4x1 needs 16");
  map = full_map();
  map.mutable_occupancy()->set_occupancy(5, 1.5F);
  expect_rejected(map, "occupancy.occupancy[5]", "outside [0, 1]");
  map = full_map();
  map.mutable_occupancy()->set_resolution(0.0);
  expect_rejected(map, "occupancy.resolution", "expected > 0");
  map = full_map();
  map.mutable_tsdf()->mutable_blocks(0)->mutable_weights()->RemoveLast();
  expect_rejected(map, "tsdf.blocks[0]", "8 distances and 7 weights (expected 8 each)");
  map = full_map();
  map.mutable_tsdf()->mutable_blocks(0)->set_weights(2, -1.0F);
  expect_rejected(map, "tsdf.blocks[0].weights[2]", "expected >= 0");
  map = full_map();
  map.mutable_mesh()->add_triangle_indices(0);
  expect_rejected(map, "mesh.triangle_indices", "4 indices (expected three per triangle)");
  map = full_map();
  map.mutable_mesh()->set_triangle_indices(2, 3);
  expect_rejected(map, "mesh.triangle_indices[2]", "index 3 past the 3 vertices");
  map = full_map();
  map.mutable_gaussian_splats()->mutable_rotations()->RemoveLast();
  expect_rejected(map, "gaussian_splats.rotations", "7 floats for 2 Gaussians (expected 4 per Gaussian)");
  map = full_map();
  map.mutable_gaussian_splats()->set_sh_degree(1);  // 12 SH floats a Gaussian, 3 given
  expect_rejected(map, "gaussian_splats.sh", "6 floats for 2 Gaussians (expected 12 per Gaussian)");
  map = full_map();
  map.mutable_gaussian_splats()->set_sh_degree(4);
  expect_rejected(map, "gaussian_splats.sh_degree", "4 (expected 0 to 3)");
  map = full_map();
  map.mutable_gaussian_splats()->set_positions(4, std::numeric_limits<float>::infinity());
  expect_rejected(map, "gaussian_splats.positions[4]", "not finite");
  map = full_map();
  map.mutable_neural_field()->set_encoding("nerfstudio");
  expect_rejected(map, "neural_field.encoding", "this build reads \"hznerf1\"");
  map = full_map();
  map.mutable_neural_field()->clear_model_parts();
  expect_rejected(map, "neural_field.model_parts", "empty");
}

TEST(MapValidation, MapUpdate) {
  v1::MapUpdate update;
  update.set_map_id("m");
  update.set_version(4);
  update.set_timestamp_ns(1'771'842'930'000'000'000);
  *update.mutable_added_points() = full_map().points();
  EXPECT_TRUE(validate(update).ok());
  update.set_timestamp_ns(0);
  EXPECT_EQ(validate(update).error().field, "timestamp_ns");
  update.set_timestamp_ns(1);
  update.mutable_added_points()->mutable_intensities()->Add(0.1F);
  EXPECT_EQ(validate(update).error().field, "added_points.intensities");
}

TEST(MapConvert, FusionMapRoundTripsLosslessly) {
  const v1::FusionMap wire = full_map();
  const Result<FusionMap> map = from_proto(wire);
  ASSERT_TRUE(map.ok()) << map.error().message;
  EXPECT_EQ(map->map_id, wire.map_id());
  EXPECT_EQ(map->created.nanoseconds(), 1'771'842'930'000'000'000);
  ASSERT_TRUE(map->datum.has_value());
  EXPECT_EQ(map->datum->latitude_deg, 47.378177);
  ASSERT_TRUE(map->points && map->occupancy && map->tsdf && map->mesh);
  EXPECT_EQ(map->points->points.size(), 10U);
  EXPECT_EQ(map->points->labels[1], SemanticLabel::kWall);
  EXPECT_EQ(map->semantic_classes, (std::vector<std::string>{"floor", "shelf", "person"}));
  EXPECT_EQ(map->points->classes[2], 2U);
  EXPECT_EQ(map->points->classes[9], kNoClass);
  EXPECT_EQ(map->occupancy->classes[3], 1U);
  EXPECT_EQ(map->occupancy->occupancy.size(), 12U);
  EXPECT_EQ(map->tsdf->blocks[0].index, Eigen::Vector3i(-1, 0, 0));
  EXPECT_EQ(map->mesh->triangle_indices, (std::vector<uint32_t>{0, 1, 2}));
  EXPECT_EQ(map->provenance.input_logs[0].uri, "logs/run1.mcap");
  // struct -> proto gives back the same message, byte for byte.
  const v1::FusionMap again = to_proto(*map);
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(wire, again));
  EXPECT_EQ(again.SerializeAsString(), wire.SerializeAsString());
}

TEST(MapConvert, MapWithoutOptionalPartsKeepsThemAbsent) {
  FusionMap map;
  map.map_id = "empty";
  map.created = Timestamp::from_nanoseconds(5);
  const v1::FusionMap wire = to_proto(map);
  EXPECT_FALSE(wire.has_datum());
  EXPECT_FALSE(wire.has_points());
  const Result<FusionMap> back = from_proto(wire);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_FALSE(back->datum.has_value());
  EXPECT_FALSE(back->occupancy.has_value());
  EXPECT_EQ(back->format_version, kFusionMapFormatVersion);
}

TEST(MapConvert, FromProtoRefusesAFutureFormatVersion) {
  v1::FusionMap wire = full_map();
  wire.set_format_version(kFusionMapFormatVersion + 1);
  const Result<FusionMap> map = from_proto(wire);
  ASSERT_FALSE(map.ok());
  EXPECT_EQ(map.error().field, "format_version");
}

TEST(MapConvert, MapUpdateRoundTrip) {
  MapUpdate update;
  update.map_id = "m";
  update.version = 9;
  update.timestamp = Timestamp::from_nanoseconds(1'771'842'930'000'000'000);
  update.added_points = PointLayer{{{1.0F, 2.0F, 3.0F}}, {0.01F}, {SemanticLabel::kObstacle}, {}, 0.1, {}, {}};
  update.full_replacement = true;
  const v1::MapUpdate wire = to_proto(update);
  const Result<MapUpdate> back = from_proto(wire);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back->version, 9U);
  EXPECT_TRUE(back->full_replacement);
  EXPECT_EQ(back->added_points->points, update.added_points->points);
  EXPECT_EQ(back->added_points->labels, update.added_points->labels);
  EXPECT_EQ(to_proto(*back).SerializeAsString(), wire.SerializeAsString());
}

}  // namespace
}  // namespace hanzo::fusion::msgs
