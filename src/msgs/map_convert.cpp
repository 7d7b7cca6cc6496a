#include "hanzo/fusion/msgs/map_convert.hpp"

#include "hanzo/fusion/msgs/map_validation.hpp"
#include "wire_helpers.hpp"

namespace hanzo::fusion::msgs {
namespace {

using wire::write;

// ---- to the wire ------------------------------------------------------------------------

template <typename RepeatedPoints>
void write_points(const std::vector<Eigen::Vector3f>& points, RepeatedPoints* out) {
  out->Reserve(static_cast<int>(points.size()));
  for (const Eigen::Vector3f& point : points) {
    v1::Point3* p = out->Add();
    p->set_x(point.x());
    p->set_y(point.y());
    p->set_z(point.z());
  }
}

template <typename RepeatedLabels>
void write_labels(const std::vector<SemanticLabel>& labels, RepeatedLabels* out) {
  out->Reserve(static_cast<int>(labels.size()));
  for (SemanticLabel label : labels) out->Add(static_cast<int>(label));
}

void write(const PointLayer& layer, v1::PointLayer* out) {
  write_points(layer.points, out->mutable_points());
  out->mutable_position_std()->Add(layer.position_std.begin(), layer.position_std.end());
  write_labels(layer.labels, out->mutable_labels());
  out->mutable_intensities()->Add(layer.intensities.begin(), layer.intensities.end());
  out->set_voxel_size(layer.voxel_size);
  out->mutable_classes()->Add(layer.classes.begin(), layer.classes.end());
  out->mutable_class_probability()->Add(layer.class_probability.begin(), layer.class_probability.end());
}

void write(const OccupancyGridLayer& layer, v1::OccupancyGridLayer* out) {
  out->set_resolution(layer.resolution);
  out->set_size_x(layer.size_x);
  out->set_size_y(layer.size_y);
  out->set_size_z(layer.size_z);
  write(layer.origin, out->mutable_origin());
  out->mutable_occupancy()->Add(layer.occupancy.begin(), layer.occupancy.end());
  write_labels(layer.labels, out->mutable_labels());
  out->mutable_classes()->Add(layer.classes.begin(), layer.classes.end());
}

void write(const TsdfLayer& layer, v1::TsdfLayer* out) {
  out->set_voxel_size(layer.voxel_size);
  out->set_truncation_distance(layer.truncation_distance);
  out->set_block_size(layer.block_size);
  for (const TsdfBlock& block : layer.blocks) {
    v1::TsdfBlock* b = out->add_blocks();
    b->set_index_x(block.index.x());
    b->set_index_y(block.index.y());
    b->set_index_z(block.index.z());
    b->mutable_distances()->Add(block.distances.begin(), block.distances.end());
    b->mutable_weights()->Add(block.weights.begin(), block.weights.end());
  }
}

void write(const MeshLayer& layer, v1::MeshLayer* out) {
  write_points(layer.vertices, out->mutable_vertices());
  out->mutable_triangle_indices()->Add(layer.triangle_indices.begin(), layer.triangle_indices.end());
  write_labels(layer.vertex_labels, out->mutable_vertex_labels());
}

void write(const VisualLandmarkLayer& layer, v1::VisualLandmarkLayer* out) {
  out->set_camera(layer.camera);
  write_points(layer.positions, out->mutable_positions());
  out->mutable_descriptors()->Reserve(static_cast<int>(4 * layer.descriptors.size()));
  for (const std::array<uint8_t, 32>& descriptor : layer.descriptors) {
    for (int word = 0; word < 4; ++word) {
      uint64_t value = 0;
      for (int byte = 7; byte >= 0; --byte) value = (value << 8) | descriptor[static_cast<std::size_t>(8 * word + byte)];
      out->add_descriptors(value);
    }
  }
  if (layer.descriptor_type != "orb") {
    out->set_descriptor_type(layer.descriptor_type);
    out->set_float_descriptor_size(layer.float_descriptor_size);
    out->mutable_float_descriptors()->Add(layer.float_descriptors.begin(), layer.float_descriptors.end());
  }
  out->mutable_position_std()->Add(layer.position_std.begin(), layer.position_std.end());
  out->mutable_observations()->Add(layer.observations.begin(), layer.observations.end());
  for (const VisualKeyframe& keyframe : layer.keyframes) {
    v1::VisualKeyframe* k = out->add_keyframes();
    k->set_time_ns(wire::write_time(keyframe.time));
    write(keyframe.T_world_camera, k->mutable_pose());
    k->mutable_landmarks()->Add(keyframe.landmarks.begin(), keyframe.landmarks.end());
    k->set_source(keyframe.source);
  }
  out->set_scale_free(layer.scale_free);
  for (const std::string& source : layer.sources) out->add_sources(source);
}

// ---- from the wire (already validated) --------------------------------------------------

template <typename RepeatedPoints>
std::vector<Eigen::Vector3f> read_points(const RepeatedPoints& in) {
  std::vector<Eigen::Vector3f> points;
  points.reserve(in.size());
  for (const v1::Point3& p : in) points.emplace_back(p.x(), p.y(), p.z());
  return points;
}

template <typename RepeatedLabels>
std::vector<SemanticLabel> read_labels(const RepeatedLabels& in) {
  std::vector<SemanticLabel> labels;
  labels.reserve(in.size());
  for (int label : in) labels.push_back(static_cast<SemanticLabel>(label));
  return labels;
}

PointLayer read(const v1::PointLayer& in) {
  return {read_points(in.points()),
          {in.position_std().begin(), in.position_std().end()},
          read_labels(in.labels()),
          {in.intensities().begin(), in.intensities().end()},
          in.voxel_size(),
          {in.classes().begin(), in.classes().end()},
          {in.class_probability().begin(), in.class_probability().end()}};
}

OccupancyGridLayer read(const v1::OccupancyGridLayer& in) {
  OccupancyGridLayer layer;
  layer.resolution = in.resolution();
  layer.size_x = in.size_x();
  layer.size_y = in.size_y();
  layer.size_z = in.size_z();
  const v1::Pose& origin = in.origin();
  layer.origin.position = {origin.position().x(), origin.position().y(), origin.position().z()};
  layer.origin.orientation = in.origin().has_orientation()
                                 ? Eigen::Quaterniond(origin.orientation().w(), origin.orientation().x(), origin.orientation().y(),
                                                      origin.orientation().z())
                                 : Eigen::Quaterniond::Identity();
  layer.occupancy.assign(in.occupancy().begin(), in.occupancy().end());
  layer.labels = read_labels(in.labels());
  layer.classes.assign(in.classes().begin(), in.classes().end());
  return layer;
}

TsdfLayer read(const v1::TsdfLayer& in) {
  TsdfLayer layer;
  layer.voxel_size = in.voxel_size();
  layer.truncation_distance = in.truncation_distance();
  layer.block_size = in.block_size();
  layer.blocks.reserve(in.blocks_size());
  for (const v1::TsdfBlock& b : in.blocks()) {
    layer.blocks.push_back({Eigen::Vector3i(b.index_x(), b.index_y(), b.index_z()),
                            {b.distances().begin(), b.distances().end()},
                            {b.weights().begin(), b.weights().end()}});
  }
  return layer;
}

MeshLayer read(const v1::MeshLayer& in) {
  return {read_points(in.vertices()), {in.triangle_indices().begin(), in.triangle_indices().end()}, read_labels(in.vertex_labels())};
}

Result<VisualLandmarkLayer> read(const v1::VisualLandmarkLayer& in) {
  VisualLandmarkLayer layer;
  layer.camera = in.camera();
  layer.positions = read_points(in.positions());
  if (!in.descriptor_type().empty()) layer.descriptor_type = in.descriptor_type();
  layer.float_descriptor_size = in.float_descriptor_size();
  layer.float_descriptors.assign(in.float_descriptors().begin(), in.float_descriptors().end());
  layer.descriptors.resize(in.descriptors_size() > 0 ? static_cast<std::size_t>(in.positions_size()) : 0);
  for (std::size_t i = 0; i < layer.descriptors.size(); ++i) {
    for (int word = 0; word < 4; ++word) {
      uint64_t value = in.descriptors(static_cast<int>(4 * i) + word);
      for (int byte = 0; byte < 8; ++byte, value >>= 8) layer.descriptors[i][static_cast<std::size_t>(8 * word + byte)] = static_cast<uint8_t>(value & 0xff);
    }
  }
  layer.position_std.assign(in.position_std().begin(), in.position_std().end());
  layer.observations.assign(in.observations().begin(), in.observations().end());
  for (const v1::VisualKeyframe& k : in.keyframes()) {
    VisualKeyframe keyframe;
    HANZO_ASSIGN_OR_RETURN(keyframe.time, wire::read_time(k.time_ns(), "VisualKeyframe", "time_ns"));
    const v1::Pose& pose = k.pose();
    keyframe.T_world_camera.position = {pose.position().x(), pose.position().y(), pose.position().z()};
    keyframe.T_world_camera.orientation = Eigen::Quaterniond(pose.orientation().w(), pose.orientation().x(), pose.orientation().y(), pose.orientation().z()).normalized();
    keyframe.landmarks.assign(k.landmarks().begin(), k.landmarks().end());
    keyframe.source = k.source();
    layer.keyframes.push_back(std::move(keyframe));
  }
  layer.scale_free = in.scale_free();
  layer.sources.assign(in.sources().begin(), in.sources().end());
  return layer;
}

void write(const NeuralProvenance& provenance, v1::NeuralProvenance* out) {
  out->set_source(provenance.source);
  out->set_views(provenance.views);
  out->set_iterations(provenance.iterations);
  out->set_training_seconds(provenance.training_seconds);
  out->set_evaluated_views(provenance.evaluated_views);
  out->set_psnr_db(provenance.psnr_db);
  out->set_ssim(provenance.ssim);
}

NeuralProvenance read(const v1::NeuralProvenance& in) {
  return {in.source(), in.views(), in.iterations(), in.training_seconds(), in.evaluated_views(), in.psnr_db(), in.ssim()};
}

void write(const GaussianSplatLayer& layer, v1::GaussianSplatLayer* out) {
  out->set_sh_degree(layer.sh_degree);
  out->mutable_positions()->Add(layer.positions.begin(), layer.positions.end());
  out->mutable_log_scales()->Add(layer.log_scales.begin(), layer.log_scales.end());
  out->mutable_rotations()->Add(layer.rotations.begin(), layer.rotations.end());
  out->mutable_opacity_logits()->Add(layer.opacity_logits.begin(), layer.opacity_logits.end());
  out->mutable_sh()->Add(layer.sh.begin(), layer.sh.end());
  write(layer.provenance, out->mutable_provenance());
}

GaussianSplatLayer read(const v1::GaussianSplatLayer& in) {
  GaussianSplatLayer layer;
  layer.sh_degree = in.sh_degree();
  layer.positions.assign(in.positions().begin(), in.positions().end());
  layer.log_scales.assign(in.log_scales().begin(), in.log_scales().end());
  layer.rotations.assign(in.rotations().begin(), in.rotations().end());
  layer.opacity_logits.assign(in.opacity_logits().begin(), in.opacity_logits().end());
  layer.sh.assign(in.sh().begin(), in.sh().end());
  layer.provenance = read(in.provenance());
  return layer;
}

void write(const NeuralFieldLayer& layer, v1::NeuralFieldLayer* out) {
  out->set_encoding(layer.encoding);
  *out->add_model_parts() = layer.model;
  write(layer.provenance, out->mutable_provenance());
}

NeuralFieldLayer read(const v1::NeuralFieldLayer& in) {
  NeuralFieldLayer layer;
  layer.encoding = in.encoding();
  for (const std::string& part : in.model_parts()) layer.model += part;
  layer.provenance = read(in.provenance());
  return layer;
}

void write(const LidarKeyframeLayer& layer, v1::LidarKeyframeLayer* out) {
  for (const std::string& source : layer.sources) out->add_sources(source);
  for (const LidarKeyframe& keyframe : layer.keyframes) {
    v1::LidarKeyframe* k = out->add_keyframes();
    k->set_time_ns(wire::write_time(keyframe.time));
    write(keyframe.T_world_lidar, k->mutable_pose());
    write_points(keyframe.points, k->mutable_points());
    k->set_source(keyframe.source);
  }
}

Result<LidarKeyframeLayer> read(const v1::LidarKeyframeLayer& in) {
  LidarKeyframeLayer layer;
  layer.sources.assign(in.sources().begin(), in.sources().end());
  for (const v1::LidarKeyframe& k : in.keyframes()) {
    LidarKeyframe keyframe;
    HANZO_ASSIGN_OR_RETURN(keyframe.time, wire::read_time(k.time_ns(), "LidarKeyframe", "time_ns"));
    const v1::Pose& pose = k.pose();
    keyframe.T_world_lidar.position = {pose.position().x(), pose.position().y(), pose.position().z()};
    keyframe.T_world_lidar.orientation = Eigen::Quaterniond(pose.orientation().w(), pose.orientation().x(), pose.orientation().y(), pose.orientation().z()).normalized();
    keyframe.points = read_points(k.points());
    keyframe.source = k.source();
    layer.keyframes.push_back(std::move(keyframe));
  }
  return layer;
}

}  // namespace

v1::FusionMap to_proto(const FusionMap& map) {
  v1::FusionMap out;
  out.set_format_version(map.format_version);
  out.set_map_id(map.map_id);
  out.set_version(map.version);
  out.set_parent_version(map.parent_version);
  out.set_created_ns(wire::write_time(map.created));
  out.set_frame_id(map.frame_id);
  if (map.datum) {
    out.mutable_datum()->set_latitude(map.datum->latitude_deg);
    out.mutable_datum()->set_longitude(map.datum->longitude_deg);
    out.mutable_datum()->set_altitude(map.datum->altitude_m);
  }
  out.set_sensor_configuration(map.sensor_configuration);
  v1::Provenance* provenance = out.mutable_provenance();
  for (const InputLog& log : map.provenance.input_logs) {
    v1::InputLog* entry = provenance->add_input_logs();
    entry->set_uri(log.uri);
    entry->set_sha256(log.sha256);
  }
  provenance->set_algorithm(map.provenance.algorithm);
  provenance->set_parameters(map.provenance.parameters);
  provenance->set_software_version(map.provenance.software_version);
  if (map.points) write(*map.points, out.mutable_points());
  if (map.occupancy) write(*map.occupancy, out.mutable_occupancy());
  if (map.tsdf) write(*map.tsdf, out.mutable_tsdf());
  if (map.mesh) write(*map.mesh, out.mutable_mesh());
  if (map.visual_landmarks) write(*map.visual_landmarks, out.mutable_visual_landmarks());
  if (map.gaussian_splats) write(*map.gaussian_splats, out.mutable_gaussian_splats());
  if (map.neural_field) write(*map.neural_field, out.mutable_neural_field());
  if (map.lidar_keyframes) write(*map.lidar_keyframes, out.mutable_lidar_keyframes());
  for (const std::string& name : map.semantic_classes) out.add_semantic_classes(name);
  return out;
}

v1::MapUpdate to_proto(const MapUpdate& update) {
  v1::MapUpdate out;
  out.set_map_id(update.map_id);
  out.set_version(update.version);
  out.set_timestamp_ns(wire::write_time(update.timestamp));
  if (update.added_points) write(*update.added_points, out.mutable_added_points());
  if (update.occupancy_patch) write(*update.occupancy_patch, out.mutable_occupancy_patch());
  if (update.mesh) write(*update.mesh, out.mutable_mesh());
  out.set_full_replacement(update.full_replacement);
  return out;
}

Result<FusionMap> from_proto(const v1::FusionMap& in) {
  HANZO_RETURN_IF_ERROR(validate(in));
  FusionMap map;
  map.format_version = in.format_version();
  map.map_id = in.map_id();
  map.version = in.version();
  map.parent_version = in.parent_version();
  HANZO_ASSIGN_OR_RETURN(map.created, wire::read_time(in.created_ns(), "FusionMap", "created_ns"));
  map.frame_id = in.frame_id();
  if (in.has_datum()) map.datum = GeodeticPoint{in.datum().latitude(), in.datum().longitude(), in.datum().altitude()};
  map.sensor_configuration = in.sensor_configuration();
  for (const v1::InputLog& log : in.provenance().input_logs()) map.provenance.input_logs.push_back({log.uri(), log.sha256()});
  map.provenance.algorithm = in.provenance().algorithm();
  map.provenance.parameters = in.provenance().parameters();
  map.provenance.software_version = in.provenance().software_version();
  if (in.has_points()) map.points = read(in.points());
  if (in.has_occupancy()) map.occupancy = read(in.occupancy());
  if (in.has_tsdf()) map.tsdf = read(in.tsdf());
  if (in.has_mesh()) map.mesh = read(in.mesh());
  if (in.has_visual_landmarks()) HANZO_ASSIGN_OR_RETURN(map.visual_landmarks, read(in.visual_landmarks()));
  if (in.has_gaussian_splats()) map.gaussian_splats = read(in.gaussian_splats());
  if (in.has_neural_field()) map.neural_field = read(in.neural_field());
  if (in.has_lidar_keyframes()) HANZO_ASSIGN_OR_RETURN(map.lidar_keyframes, read(in.lidar_keyframes()));
  map.semantic_classes.assign(in.semantic_classes().begin(), in.semantic_classes().end());
  return map;
}

Result<MapUpdate> from_proto(const v1::MapUpdate& in) {
  HANZO_RETURN_IF_ERROR(validate(in));
  MapUpdate update;
  update.map_id = in.map_id();
  update.version = in.version();
  HANZO_ASSIGN_OR_RETURN(update.timestamp, wire::read_time(in.timestamp_ns(), "MapUpdate", "timestamp_ns"));
  if (in.has_added_points()) update.added_points = read(in.added_points());
  if (in.has_occupancy_patch()) update.occupancy_patch = read(in.occupancy_patch());
  if (in.has_mesh()) update.mesh = read(in.mesh());
  update.full_replacement = in.full_replacement();
  return update;
}

}  // namespace hanzo::fusion::msgs
