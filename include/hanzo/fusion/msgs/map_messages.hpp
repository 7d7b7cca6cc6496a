#pragma once
// FusionMap and MapUpdate as plain C++ structs mirroring proto/hanzo/fusion/v1/maps.proto:
// the canonical map container's layers and metadata. The maps module builds its occupancy
// grids, TSDFs and point maps on top of these; conversion to and from the wire is in
// msgs/map_convert.hpp, checks in msgs/map_validation.hpp.

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/geodesy.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"

namespace hanzo::fusion::msgs {

enum class SemanticLabel : uint8_t { kUnknown, kFloor, kWall, kObstacle, kTraversable };

/// A point or cell no segmentation class was projected onto (PointLayer::classes,
/// OccupancyGridLayer::classes).
inline constexpr uint16_t kNoClass = 0xFFFF;

struct PointLayer {
  std::vector<Eigen::Vector3f> points;  // world frame, meters
  std::vector<float> position_std;      // 1-sigma per point (m); empty or one per point
  std::vector<SemanticLabel> labels;    // empty or one per point
  std::vector<float> intensities;       // empty or one per point
  double voxel_size = 0.0;              // meters, 0 if not voxelized
  /// Projected segmentation classes: empty or one per point, an index into
  /// FusionMap::semantic_classes, kNoClass where no camera's segmentation saw the point.
  std::vector<uint16_t> classes;
  std::vector<float> class_probability;  // empty or one per point: the class's posterior, (0, 1]; 0 for kNoClass
};

struct OccupancyGridLayer {
  double resolution = 0.05;  // meters per cell
  uint32_t size_x = 0;
  uint32_t size_y = 0;
  uint32_t size_z = 1;       // 1 for a 2D grid
  Pose origin;               // world pose of the corner of cell (0, 0, 0)
  std::vector<float> occupancy;        // probability per cell, x fastest, then y, then z; 0.5 = unknown
  std::vector<SemanticLabel> labels;   // empty or one per cell
  std::vector<uint16_t> classes;       // empty or one per cell: FusionMap::semantic_classes index or kNoClass
};

struct TsdfBlock {
  Eigen::Vector3i index = Eigen::Vector3i::Zero();  // block coordinates
  std::vector<float> distances;                     // block_size^3, x fastest
  std::vector<float> weights;                       // same size, >= 0
};

struct TsdfLayer {
  double voxel_size = 0.05;
  double truncation_distance = 0.15;
  uint32_t block_size = 8;
  std::vector<TsdfBlock> blocks;
};

struct MeshLayer {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<uint32_t> triangle_indices;    // three per triangle
  std::vector<SemanticLabel> vertex_labels;  // empty or one per vertex
};

struct VisualKeyframe {
  Timestamp time;
  Pose T_world_camera;              // optical frame (x right, y down, z forward)
  std::vector<uint32_t> landmarks;  // indices into the layer's landmarks
  uint32_t source = 0;              // index into VisualLandmarkLayer::sources (0 when it is empty)
};

// Sparse visual landmarks with ORB descriptors and the keyframes that saw them (relocalization).
struct VisualLandmarkLayer {
  std::string camera;                                    // sensor name
  std::vector<Eigen::Vector3f> positions;                // world frame, meters
  std::vector<std::array<uint8_t, 32>> descriptors;      // one ORB descriptor per landmark (descriptor_type "orb")
  std::string descriptor_type = "orb";                   // the extractor's name; a learned one ("aliked-t16") fills float_descriptors
  uint32_t float_descriptor_size = 0;                    // floats per landmark in float_descriptors
  std::vector<float> float_descriptors;                  // row-major, one unit-length row per landmark
  std::vector<float> position_std;                       // 1-sigma (m); empty or one per landmark
  std::vector<uint32_t> observations;                    // empty or one per landmark
  std::vector<VisualKeyframe> keyframes;
  bool scale_free = false;               // monocular: lengths in units of the first baseline, not metres
  std::vector<std::string> sources;      // the map each keyframe came from (map_id); empty: all are this map's own
};

/// A deskewed LiDAR sweep the map was built from (sensor frame) at the pose the map has it: what
/// re-optimizing the map or joining it with other sessions' maps (pipeline/map_merge.hpp) needs.
struct LidarKeyframe {
  Timestamp time;
  Pose T_world_lidar;
  std::vector<Eigen::Vector3f> points;  // sensor frame, meters
  uint32_t source = 0;                  // index into LidarKeyframeLayer::sources (0 when it is empty)
};

struct LidarKeyframeLayer {
  std::vector<std::string> sources;  // the map each keyframe came from (map_id); empty: all are this map's own
  std::vector<LidarKeyframe> keyframes;
};

/// How a neural layer was trained (views, steps, metrics on held-back views).
struct NeuralProvenance {
  std::string source;             // the views' origin: a transforms.json, or a sensor log + trajectory
  uint32_t views = 0;             // training views
  uint64_t iterations = 0;        // optimizer steps
  double training_seconds = 0.0;
  uint32_t evaluated_views = 0;   // held-back views scored (0: no metrics)
  double psnr_db = 0.0;
  double ssim = 0.0;
};

/// 3D Gaussian splats, world frame, laid out as neural::GaussianCloud (structure of arrays):
/// per Gaussian 3 positions, 3 log_scales, 4 rotations (w, x, y, z), 1 opacity_logits and
/// 3 (sh_degree + 1)^2 sh coefficients (coefficient-major, RGB).
struct GaussianSplatLayer {
  uint32_t sh_degree = 3;
  std::vector<float> positions;
  std::vector<float> log_scales;
  std::vector<float> rotations;
  std::vector<float> opacity_logits;
  std::vector<float> sh;
  NeuralProvenance provenance;
  std::size_t size() const { return opacity_logits.size(); }
};

/// A neural radiance field as its model file's bytes (`encoding` "hznerf1": neural/nerf_field.hpp).
struct NeuralFieldLayer {
  std::string encoding = "hznerf1";
  std::string model;
  NeuralProvenance provenance;
};

struct InputLog {
  std::string uri;
  std::string sha256;  // hex digest
};

struct Provenance {
  std::vector<InputLog> input_logs;
  std::string algorithm;
  std::string parameters;        // the configuration used, YAML text
  std::string software_version;
};

struct FusionMap {
  uint32_t format_version = 1;
  std::string map_id;
  uint64_t version = 0;
  uint64_t parent_version = 0;  // 0 for none
  Timestamp created;
  std::string frame_id = "world";
  std::optional<GeodeticPoint> datum;  // WGS84 of the ENU origin when known
  std::string sensor_configuration;    // fusion configuration + calibration, YAML text
  Provenance provenance;
  std::optional<PointLayer> points;
  std::optional<OccupancyGridLayer> occupancy;
  std::optional<TsdfLayer> tsdf;
  std::optional<MeshLayer> mesh;
  std::optional<VisualLandmarkLayer> visual_landmarks;
  std::optional<GaussianSplatLayer> gaussian_splats;
  std::optional<NeuralFieldLayer> neural_field;
  std::optional<LidarKeyframeLayer> lidar_keyframes;
  /// The label table of the layers' segmentation classes (PointLayer::classes,
  /// OccupancyGridLayer::classes): the name of each class index.
  std::vector<std::string> semantic_classes;
};

struct MapUpdate {
  std::string map_id;
  uint64_t version = 0;
  Timestamp timestamp;
  std::optional<PointLayer> added_points;
  std::optional<OccupancyGridLayer> occupancy_patch;
  std::optional<MeshLayer> mesh;
  bool full_replacement = false;
};

}  // namespace hanzo::fusion::msgs
