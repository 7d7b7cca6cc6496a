#include "hanzo/fusion/maps/redaction.hpp"

#include <array>
#include <cmath>
#include <unordered_map>

#include <fmt/format.h>

#include "class_votes.hpp"
#include "floor_divide.hpp"

#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/maps/map_export.hpp"
#include "hanzo/fusion/maps/occupancy_grid.hpp"

namespace hanzo::fusion::maps {
namespace {

// Points merged into voxels of `resolution`; each coarse point takes the most frequent geometric
// label and segmentation class of the points it merges (the class's probability: their mean).
msgs::PointLayer coarsen_points(const msgs::PointLayer& layer, double resolution) {
  const cloud::PointCloud coarse = cloud::voxel_downsample(to_point_cloud(layer), resolution);
  msgs::PointLayer out = to_point_layer(coarse, resolution);
  out.position_std.assign(out.points.size(), static_cast<float>(resolution / std::sqrt(12.0)));
  if (layer.labels.empty() && layer.classes.empty()) return out;
  // Each coarse point is its voxel's centroid, inside the voxel.
  const auto inverse = static_cast<float>(1.0 / resolution);
  std::unordered_map<uint64_t, std::size_t> coarse_of_voxel;
  for (std::size_t i = 0; i < out.points.size(); ++i) {
    uint64_t key = 0;
    if (cloud::pack_voxel_key(cloud::voxel_coordinates(out.points[i], inverse), &key)) coarse_of_voxel.emplace(key, i);
  }
  std::vector<ClassVotes> labels(layer.labels.empty() ? 0 : out.points.size()), classes(layer.classes.empty() ? 0 : out.points.size());
  std::vector<std::pair<double, uint32_t>> probability_of(classes.size());  // per coarse point: its class's probabilities, sum and count
  std::vector<std::size_t> coarse_of_point(layer.points.size(), out.points.size());
  for (std::size_t i = 0; i < layer.points.size(); ++i) {
    uint64_t key = 0;
    if (!cloud::pack_voxel_key(cloud::voxel_coordinates(layer.points[i], inverse), &key)) continue;
    const auto found = coarse_of_voxel.find(key);
    if (found == coarse_of_voxel.end()) continue;
    coarse_of_point[i] = found->second;
    if (!labels.empty()) labels[found->second].add(static_cast<uint16_t>(layer.labels[i]));
    if (!classes.empty() && layer.classes[i] != msgs::kNoClass) classes[found->second].add(layer.classes[i]);
  }
  if (!labels.empty()) {
    out.labels.resize(out.points.size());
    for (std::size_t c = 0; c < out.points.size(); ++c) out.labels[c] = static_cast<msgs::SemanticLabel>(labels[c].counts.empty() ? 0 : labels[c].most().first);
  }
  if (!classes.empty()) {
    out.classes.resize(out.points.size());
    for (std::size_t c = 0; c < out.points.size(); ++c) out.classes[c] = classes[c].most().first;
    for (std::size_t i = 0; i < layer.points.size(); ++i) {
      const std::size_t c = coarse_of_point[i];
      if (c == out.points.size() || layer.classes[i] != out.classes[c] || layer.class_probability.empty()) continue;
      probability_of[c].first += layer.class_probability[i];
      ++probability_of[c].second;
    }
    out.class_probability.resize(out.points.size());
    for (std::size_t c = 0; c < out.points.size(); ++c) {
      out.class_probability[c] = probability_of[c].second == 0 ? 0.0F : static_cast<float>(probability_of[c].first / probability_of[c].second);
    }
    if (layer.class_probability.empty()) out.class_probability.clear();
  }
  return out;
}

Result<msgs::OccupancyGridLayer> coarsen_occupancy(const msgs::OccupancyGridLayer& layer, int factor) {
  Eigen::Vector3i first;
  HANZO_ASSIGN_OR_RETURN(first, occupancy_layer_first_cell(layer));
  const bool planar = layer.size_z <= 1;
  const Eigen::Vector3i factors(factor, factor, planar ? 1 : factor);
  const Eigen::Vector3i size(static_cast<int>(layer.size_x), static_cast<int>(layer.size_y), static_cast<int>(layer.size_z));
  Eigen::Vector3i coarse_first;
  Eigen::Vector3i coarse_last;
  for (int axis = 0; axis < 3; ++axis) {
    coarse_first[axis] = floor_divide(first[axis], factors[axis]);
    coarse_last[axis] = floor_divide(first[axis] + std::max(size[axis], 1) - 1, factors[axis]);
  }
  const Eigen::Vector3i coarse_size = coarse_last - coarse_first + Eigen::Vector3i::Ones();

  msgs::OccupancyGridLayer out;
  out.resolution = layer.resolution * factor;
  out.size_x = static_cast<uint32_t>(coarse_size.x());
  out.size_y = static_cast<uint32_t>(coarse_size.y());
  out.size_z = planar ? 1 : static_cast<uint32_t>(coarse_size.z());
  out.origin.position = coarse_first.cast<double>().cwiseProduct(factors.cast<double>()) * layer.resolution;
  if (planar) out.origin.position.z() = layer.origin.position.z();
  out.occupancy.assign(static_cast<std::size_t>(out.size_x) * out.size_y * out.size_z, 0.5f);
  if (layer.size_x == 0 || layer.size_y == 0) {
    out.size_x = 0;
    out.size_y = 0;
    out.occupancy.clear();
    return out;
  }
  std::size_t linear = 0;
  for (int z = 0; z < size.z(); ++z) {
    for (int y = 0; y < size.y(); ++y) {
      for (int x = 0; x < size.x(); ++x, ++linear) {
        const float p = layer.occupancy[linear];
        if (p == 0.5f) continue;
        const Eigen::Vector3i cell = first + Eigen::Vector3i(x, y, z);
        Eigen::Vector3i coarse;
        for (int axis = 0; axis < 3; ++axis) coarse[axis] = floor_divide(cell[axis], factors[axis]) - coarse_first[axis];
        float& merged = out.occupancy[(static_cast<std::size_t>(coarse.z()) * out.size_y + static_cast<std::size_t>(coarse.y())) *
                                          out.size_x +
                                      static_cast<std::size_t>(coarse.x())];
        merged = merged == 0.5f ? p : std::max(merged, p);
      }
    }
  }
  return out;
}

msgs::MeshLayer cluster_mesh(const msgs::MeshLayer& mesh, double resolution) {
  const float inverse = static_cast<float>(1.0 / resolution);
  std::unordered_map<uint64_t, uint32_t> cluster_of_key;
  std::vector<Eigen::Vector3d> sums;
  std::vector<uint32_t> counts;
  std::vector<uint32_t> cluster_of_vertex(mesh.vertices.size(), 0);
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    uint64_t key = 0;
    if (!cloud::pack_voxel_key(cloud::voxel_coordinates(mesh.vertices[i], inverse), &key)) key = ~uint64_t{0} - i;
    const auto [entry, inserted] = cluster_of_key.emplace(key, static_cast<uint32_t>(sums.size()));
    if (inserted) {
      sums.emplace_back(Eigen::Vector3d::Zero());
      counts.push_back(0);
    }
    sums[entry->second] += mesh.vertices[i].cast<double>();
    ++counts[entry->second];
    cluster_of_vertex[i] = entry->second;
  }
  msgs::MeshLayer out;
  out.vertices.reserve(sums.size());
  for (std::size_t c = 0; c < sums.size(); ++c) out.vertices.push_back((sums[c] / counts[c]).cast<float>());
  for (std::size_t t = 0; t + 2 < mesh.triangle_indices.size(); t += 3) {
    const std::array<uint32_t, 3> corners{cluster_of_vertex[mesh.triangle_indices[t]], cluster_of_vertex[mesh.triangle_indices[t + 1]],
                                          cluster_of_vertex[mesh.triangle_indices[t + 2]]};
    if (corners[0] == corners[1] || corners[1] == corners[2] || corners[0] == corners[2]) continue;
    out.triangle_indices.insert(out.triangle_indices.end(), corners.begin(), corners.end());
  }
  return out;
}

}  // namespace

Result<msgs::FusionMap> redact_map(const msgs::FusionMap& map, const RedactionConfig& config, RedactionReport* report) {
  if (!(std::isfinite(config.resolution) && config.resolution >= 0.0)) {
    return Error{fmt::format("redaction: resolution must be >= 0 meters, got {}", config.resolution), "resolution"};
  }
  RedactionReport local_report;
  RedactionReport& out_report = report != nullptr ? *report : local_report;
  const auto note = [&](std::string line) {
    logger()->info("redaction: {}", line);
    out_report.actions.push_back(std::move(line));
  };
  msgs::FusionMap out = map;
  const double resolution = config.resolution;

  if (out.points && resolution > out.points->voxel_size) {
    const std::size_t before = out.points->points.size();
    out.points = coarsen_points(*out.points, resolution);
    note(fmt::format("points: {} -> {} at {} m voxels", before, out.points->points.size(), resolution));
  }
  if (out.occupancy) {
    const int factor = static_cast<int>(std::lround(resolution / out.occupancy->resolution));
    if (factor > 1) {
      HANZO_ASSIGN_OR_RETURN(out.occupancy, coarsen_occupancy(*out.occupancy, factor));
      note(fmt::format("occupancy: {:.6g} m -> {:.6g} m cells", map.occupancy->resolution, out.occupancy->resolution));
    }
  }
  if (out.mesh && resolution > 0.0) {
    const std::size_t before = out.mesh->triangle_indices.size() / 3;
    out.mesh = cluster_mesh(*out.mesh, resolution);
    note(fmt::format("mesh: {} -> {} triangles (vertex clustering at {} m)", before, out.mesh->triangle_indices.size() / 3,
                     resolution));
  }
  if (out.tsdf && resolution > out.tsdf->voxel_size) {
    out.tsdf.reset();
    note("tsdf: layer removed");
  }
  // Photorealistic layers render the facility from any viewpoint: removed at any resolution.
  if (out.gaussian_splats && resolution > 0.0) {
    out.gaussian_splats.reset();
    note("gaussian_splats: layer removed");
  }
  if (out.neural_field && resolution > 0.0) {
    out.neural_field.reset();
    note("neural_field: layer removed");
  }
  // The keyframes' sweeps hold the full-resolution geometry the coarsening removes.
  if (out.lidar_keyframes && resolution > 0.0) {
    out.lidar_keyframes.reset();
    note("lidar_keyframes: layer removed");
  }
  if (config.drop_labels) {
    std::size_t dropped = 0;
    if (out.points) {
      dropped += std::exchange(out.points->labels, {}).size() + std::exchange(out.points->classes, {}).size();
      out.points->class_probability.clear();
    }
    if (out.occupancy) dropped += std::exchange(out.occupancy->labels, {}).size() + std::exchange(out.occupancy->classes, {}).size();
    out.semantic_classes.clear();
    if (out.mesh) dropped += std::exchange(out.mesh->vertex_labels, {}).size();
    note(fmt::format("labels: {} removed", dropped));
  }
  if (config.drop_sensor_details) {
    out.sensor_configuration.clear();
    for (msgs::InputLog& input : out.provenance.input_logs) input.uri = "redacted";
    note("sensor configuration and input log paths removed");
  }
  out.provenance.parameters += fmt::format("{}redaction: {{drop_labels: {}, resolution: {}, drop_sensor_details: {}}}\n",
                                           out.provenance.parameters.empty() || out.provenance.parameters.ends_with('\n') ? "" : "\n",
                                           config.drop_labels, resolution, config.drop_sensor_details);
  return out;
}

}  // namespace hanzo::fusion::maps
