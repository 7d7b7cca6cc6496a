// hanzo-fusion map build|info|export|import|diff|redact|save|versions|checkout: FusionMap files
// (maps/fusion_map_file.hpp) and the versioned map store (maps/map_store.hpp).

#include <algorithm>
#include <chrono>
#include <filesystem>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/crypto/file_encryption.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/maps/geometric_labels.hpp"
#include "hanzo/fusion/maps/map_diff.hpp"
#include "hanzo/fusion/maps/label_export.hpp"
#include "hanzo/fusion/maps/map_export.hpp"
#include "hanzo/fusion/maps/map_store.hpp"
#include "hanzo/fusion/maps/provenance.hpp"
#include "hanzo/fusion/maps/redaction.hpp"
#include "map_commands.hpp"

namespace hanzo::fusion::app {
namespace {

struct MapOptions {
  std::string input;
  std::string second;
  std::string out;
  std::string format;
  std::string layer;
  double pixel_size = 0.0;
  double voxel = 0.0;
  double resolution = 0.5;
  bool drop_labels = false;
  bool drop_sensor_details = false;
  std::string store;
  std::vector<std::string> key_files;
  std::string map_id;
  uint64_t version = 0;
  std::string at;
};

std::string extension_of(const std::string& path) {
  std::string extension = std::filesystem::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(), [](unsigned char c) { return std::tolower(c); });
  return extension;
}

// The map store of --store: versions saved encrypted with the first --key; every --key and the
// keys of $HANZO_ENCRYPTION_KEY decrypt.
Result<maps::MapStore> open_store(const MapOptions& options) {
  maps::MapStoreConfig config;
  for (const std::string& file : options.key_files) {
    Result<crypto::EncryptionKey> key = crypto::EncryptionKey::load(file);
    if (!key) return Error(fmt::format("--key: {}", key.error().message));
    if (!config.encryption_key) {
      config.encryption_key = *key;
    } else {
      config.decryption_keys.push_back(*key);
    }
  }
  std::vector<crypto::EncryptionKey> environment;
  HANZO_ASSIGN_OR_RETURN(environment, crypto::keys_from_environment());
  config.decryption_keys.insert(config.decryption_keys.end(), environment.begin(), environment.end());
  return maps::MapStore::open(options.store, std::move(config));
}

void add_store_options(CLI::App* app, MapOptions& options) {
  app->add_option("--store", options.store, "Map store: a folder, or s3://BUCKET/PREFIX (docs/security.md)")->required();
  app->add_option("--key", options.key_files, "Key file: the first encrypts saved versions; each decrypts (repeatable)");
}

Status export_map(const MapOptions& options, nlohmann::json& result) {
  msgs::FusionMap map;
  HANZO_ASSIGN_OR_RETURN(map, maps::read_fusion_map(options.input));
  std::string format = options.format.empty() ? extension_of(options.out).substr(std::min<std::size_t>(1, extension_of(options.out).size())) : options.format;
  if (format == "yaml") format = "pgm";
  result["format"] = format;
  const auto need_occupancy = [&]() -> Status {
    if (!map.occupancy) return Error{fmt::format("{}: the map has no occupancy layer to export as {}", options.input, format)};
    return ok_status();
  };
  const auto need_points = [&]() -> Status {
    if (!map.points) return Error{fmt::format("{}: the map has no point layer to export as {}", options.input, format)};
    return ok_status();
  };
  if (options.layer == "labels") {
    // Semantic labels: the points coloured by label (ply), or one ROS map per label of the grid (pgm).
    result["layer"] = "labels";
    if (format == "ply") {
      HANZO_RETURN_IF_ERROR(need_points());
      HANZO_RETURN_IF_ERROR(maps::write_labelled_points_ply(options.out, *map.points));
      result["files"] = {options.out};
      result["points"] = map.points->points.size();
      return ok_status();
    }
    if (format != "pgm") return Error{fmt::format("--layer labels: exports as ply (labelled points) or pgm (a map per label), not {}", format)};
    HANZO_RETURN_IF_ERROR(need_occupancy());
    const std::string extension = extension_of(options.out);
    const std::string stem = extension == ".yaml" || extension == ".yml" || extension == ".pgm"
                                 ? std::filesystem::path(options.out).replace_extension("").string()
                                 : options.out;
    std::vector<std::string> files;
    HANZO_ASSIGN_OR_RETURN(files, maps::write_label_maps(stem, *map.occupancy));
    result["files"] = files;
    return ok_status();
  }
  if (options.layer == "classes") {
    // Segmentation classes: the points coloured by class, with the class and its probability.
    result["layer"] = "classes";
    if (format != "ply") return Error{fmt::format("--layer classes: exports as ply (classified points), not {}", format)};
    HANZO_RETURN_IF_ERROR(need_points());
    HANZO_RETURN_IF_ERROR(maps::write_classified_points_ply(options.out, *map.points, map.semantic_classes));
    result["files"] = {options.out};
    result["points"] = map.points->points.size();
    result["semantic_classes"] = map.semantic_classes;
    return ok_status();
  }
  if (format == "pgm") {
    HANZO_RETURN_IF_ERROR(need_occupancy());
    // The names as given: --out map.pgm writes map.pgm (+ map.yaml), --out map.yaml map.yaml (+ map.pgm).
    const std::string extension = extension_of(options.out);
    const std::string yaml = extension == ".yaml" || extension == ".yml" ? options.out
                             : extension == ".pgm"                        ? std::filesystem::path(options.out).replace_extension(".yaml").string()
                                                                          : options.out + ".yaml";
    HANZO_RETURN_IF_ERROR(maps::write_ros_map(yaml, *map.occupancy));
    result["files"] = {yaml, std::filesystem::path(yaml).replace_extension(".pgm").string()};
    return ok_status();
  }
  if (!options.layer.empty() && options.layer != "occupancy" && options.layer != "points" && options.layer != "mesh") {
    return Error{fmt::format("--layer: expected occupancy, points, mesh, labels or classes, got '{}'", options.layer)};
  }
  if (format == "png") {
    const std::string layer = !options.layer.empty() ? options.layer : map.occupancy ? "occupancy" : map.points ? "points" : "mesh";
    if (layer == "occupancy") {
      HANZO_RETURN_IF_ERROR(need_occupancy());
      HANZO_RETURN_IF_ERROR(maps::write_occupancy_png(options.out, *map.occupancy));
    } else if (layer == "points") {
      HANZO_RETURN_IF_ERROR(need_points());
      HANZO_RETURN_IF_ERROR(maps::write_points_png(options.out, *map.points, options.pixel_size));
    } else {
      if (!map.mesh) return Error{fmt::format("{}: the map has no mesh layer to picture", options.input)};
      msgs::PointLayer vertices;
      vertices.points = map.mesh->vertices;
      HANZO_RETURN_IF_ERROR(maps::write_points_png(options.out, vertices, options.pixel_size));
    }
    result["layer"] = layer;
    result["files"] = {options.out};
    return ok_status();
  }
  const bool mesh_wanted = options.layer == "mesh" || format == "obj" || (format == "ply" && options.layer.empty() && !map.points && map.mesh);
  if (mesh_wanted) {
    if (!map.mesh) return Error{fmt::format("{}: the map has no mesh layer to export", options.input)};
    if (format != "ply" && format != "obj") return Error{fmt::format("--format: meshes export as ply or obj, not {}", format)};
    const std::string path = extension_of(options.out) == "." + format ? options.out : options.out + "." + format;
    HANZO_RETURN_IF_ERROR(maps::write_mesh(path, *map.mesh));
    result["layer"] = "mesh";
    result["files"] = {path};
    result["triangles"] = map.mesh->triangle_indices.size() / 3;
    return ok_status();
  }
  if (format == "pcd" || format == "ply" || format == "bin") {
    HANZO_RETURN_IF_ERROR(need_points());
    const std::string path = extension_of(options.out) == "." + format ? options.out : options.out + "." + format;
    HANZO_RETURN_IF_ERROR(cloud::write_cloud(path, maps::to_point_cloud(*map.points)));
    result["files"] = {path};
    result["points"] = map.points->points.size();
    return ok_status();
  }
  return Error{fmt::format("--format: expected png, pgm, pcd, ply, bin or obj, got '{}'", format)};
}

Result<msgs::FusionMap> import_map(const MapOptions& options) {
  msgs::FusionMap map;
  map.map_id = options.map_id.empty() ? maps::generate_map_id() : options.map_id;
  HANZO_RETURN_IF_ERROR(maps::validate_map_id(map.map_id));
  map.version = 1;
  map.created = Timestamp::wall_clock_now();
  const std::string extension = extension_of(options.input);
  if (extension == ".yaml" || extension == ".yml") {
    HANZO_ASSIGN_OR_RETURN(map.occupancy, maps::read_ros_map(options.input));
    map.provenance.algorithm = "import/ros_map";
  } else {
    cloud::PointCloud cloud;
    HANZO_ASSIGN_OR_RETURN(cloud, cloud::read_cloud(options.input));
    if (options.voxel > 0.0) cloud = cloud::voxel_downsample(cloud, options.voxel);
    map.points = maps::to_point_layer(cloud, options.voxel);
    map.provenance.algorithm = "import/point_cloud";
  }
  msgs::InputLog input;
  HANZO_ASSIGN_OR_RETURN(input, maps::describe_input_file(options.input));
  map.provenance.input_logs.push_back(input);
  map.provenance.software_version = HANZO_FUSION_VERSION;
  return map;
}

nlohmann::json diff_json(const maps::MapDiff& diff) {
  nlohmann::json result = nlohmann::json::object();
  if (diff.occupancy) {
    const maps::OccupancyDiff& o = *diff.occupancy;
    result["occupancy"] = {{"resolution", o.resolution},         {"cells_compared", o.cells_compared},
                           {"became_occupied", o.became_occupied}, {"became_free", o.became_free},
                           {"newly_observed", o.newly_observed},   {"no_longer_observed", o.no_longer_observed}};
  }
  if (diff.points) {
    const maps::PointDiff& p = *diff.points;
    result["points"] = {{"voxel_size", p.voxel_size},   {"voxels_before", p.voxels_before}, {"voxels_after", p.voxels_after},
                        {"added", p.added.size()}, {"removed", p.removed.size()}};
  }
  return result;
}

std::string diff_text(const nlohmann::json& diff) {
  std::string text;
  if (diff.contains("occupancy")) {
    const auto& o = diff["occupancy"];
    text += fmt::format("occupancy ({} m cells, {} compared): {} became occupied, {} became free, {} newly observed, {} no longer observed\n",
                        o["resolution"].get<double>(), o["cells_compared"].get<std::size_t>(), o["became_occupied"].get<std::size_t>(),
                        o["became_free"].get<std::size_t>(), o["newly_observed"].get<std::size_t>(),
                        o["no_longer_observed"].get<std::size_t>());
  }
  if (diff.contains("points")) {
    const auto& p = diff["points"];
    text += fmt::format("points ({} m voxels, {} -> {}): {} voxels added, {} removed\n", p["voxel_size"].get<double>(),
                        p["voxels_before"].get<std::size_t>(), p["voxels_after"].get<std::size_t>(), p["added"].get<std::size_t>(),
                        p["removed"].get<std::size_t>());
  }
  return text;
}

nlohmann::json version_json(const maps::MapVersionInfo& info) {
  return {{"map_id", info.map_id},           {"version", info.version},   {"parent_version", info.parent_version},
          {"created", io::format_seconds(info.created)}, {"file_bytes", info.file_bytes}, {"location", info.location}, {"encrypted", !info.key_id.empty()}};
}

template <typename Function>
int run_reporting(const Output& output, nlohmann::json result, Function&& body) {
  std::string text;
  if (Status status = body(result, text); !status) return report_failure(output, result, status.error().message);
  result["ok"] = true;
  return report_success(output, result, text);
}

// Points, cells or vertices per geometric label name.
nlohmann::json label_counts(const std::vector<msgs::SemanticLabel>& labels) {
  nlohmann::json counts = nlohmann::json::object();
  for (const msgs::SemanticLabel label : labels) {
    const char* name = maps::semantic_label_name(label);
    counts[name] = counts.value(name, 0) + 1;
  }
  return counts;
}

// "floor 12, wall 40" of a label_counts / class_counts object.
std::string counts_text(const nlohmann::json& counts) {
  std::string text;
  for (const auto& [name, count] : counts.items()) text += fmt::format("{}{} {}", text.empty() ? "" : ", ", name, count.get<std::size_t>());
  return text;
}

}  // namespace

nlohmann::json describe_map(const msgs::FusionMap& map) {
  nlohmann::json result = {{"map_id", map.map_id},
                           {"format_version", map.format_version},
                           {"version", map.version},
                           {"parent_version", map.parent_version},
                           {"created", io::format_seconds(map.created)},
                           {"created_iso8601", map.created.to_iso8601()},
                           {"frame_id", map.frame_id},
                           {"algorithm", map.provenance.algorithm},
                           {"software_version", map.provenance.software_version}};
  if (map.datum) result["datum"] = {map.datum->latitude_deg, map.datum->longitude_deg, map.datum->altitude_m};
  nlohmann::json inputs = nlohmann::json::array();
  for (const msgs::InputLog& input : map.provenance.input_logs) inputs.push_back({{"uri", input.uri}, {"sha256", input.sha256}});
  result["inputs"] = inputs;
  result["semantic_classes"] = map.semantic_classes;
  nlohmann::json layers = nlohmann::json::object();
  if (map.points) {
    Eigen::Vector3f low = Eigen::Vector3f::Zero();
    Eigen::Vector3f high = Eigen::Vector3f::Zero();
    if (!map.points->points.empty()) {
      low = high = map.points->points.front();
      for (const Eigen::Vector3f& p : map.points->points) {
        low = low.cwiseMin(p);
        high = high.cwiseMax(p);
      }
    }
    layers["points"] = {{"count", map.points->points.size()},
                        {"voxel_size", map.points->voxel_size},
                        {"min", {low.x(), low.y(), low.z()}},
                        {"max", {high.x(), high.y(), high.z()}},
                        {"labels", !map.points->labels.empty()},
                        {"uncertainty", !map.points->position_std.empty()}};
    if (!map.points->labels.empty()) layers["points"]["label_counts"] = label_counts(map.points->labels);
    if (!map.points->classes.empty()) {
      // Segmentation classes (the label table's names) with their points.
      nlohmann::json counts = nlohmann::json::object();
      for (const uint16_t index : map.points->classes) {
        if (index == msgs::kNoClass) continue;
        const std::string& name = map.semantic_classes.at(index);  // validated on reading
        counts[name] = counts.value(name, 0) + 1;
      }
      layers["points"]["class_counts"] = std::move(counts);
    }
  }
  if (map.occupancy) {
    const auto& grid = *map.occupancy;
    std::size_t occupied = 0;
    std::size_t free = 0;
    for (float p : grid.occupancy) {
      occupied += p > 0.65f ? 1 : 0;
      free += p < 0.196f ? 1 : 0;
    }
    layers["occupancy"] = {{"resolution", grid.resolution},
                           {"size", {grid.size_x, grid.size_y, grid.size_z}},
                           {"origin", {grid.origin.position.x(), grid.origin.position.y(), grid.origin.position.z()}},
                           {"extent_m", {grid.size_x * grid.resolution, grid.size_y * grid.resolution, grid.size_z * grid.resolution}},
                           {"occupied_cells", occupied},
                           {"free_cells", free},
                           {"unknown_cells", grid.occupancy.size() - occupied - free},
                           {"labels", !grid.labels.empty()},
                           {"classes", !grid.classes.empty()}};
    if (!grid.labels.empty()) layers["occupancy"]["label_counts"] = label_counts(grid.labels);
  }
  if (map.tsdf) {
    layers["tsdf"] = {{"voxel_size", map.tsdf->voxel_size}, {"blocks", map.tsdf->blocks.size()}, {"block_size", map.tsdf->block_size}};
  }
  if (map.mesh) {
    layers["mesh"] = {{"vertices", map.mesh->vertices.size()}, {"triangles", map.mesh->triangle_indices.size() / 3}};
    if (!map.mesh->vertex_labels.empty()) layers["mesh"]["label_counts"] = label_counts(map.mesh->vertex_labels);
  }
  if (map.visual_landmarks) {
    layers["visual_landmarks"] = {{"camera", map.visual_landmarks->camera},        {"landmarks", map.visual_landmarks->positions.size()},
                                  {"keyframes", map.visual_landmarks->keyframes.size()}, {"descriptor_type", map.visual_landmarks->descriptor_type},
                                  {"scale_free", map.visual_landmarks->scale_free},      {"sources", map.visual_landmarks->sources}};
  }
  const auto trained = [](const msgs::NeuralProvenance& provenance) {
    return nlohmann::json{{"views", provenance.views},
                          {"iterations", provenance.iterations},
                          {"training_seconds", provenance.training_seconds},
                          {"evaluated_views", provenance.evaluated_views},
                          {"psnr_db", provenance.psnr_db},
                          {"ssim", provenance.ssim}};
  };
  if (map.gaussian_splats) {
    layers["gaussian_splats"] = {{"gaussians", map.gaussian_splats->size()}, {"sh_degree", map.gaussian_splats->sh_degree},
                                 {"trained", trained(map.gaussian_splats->provenance)}};
  }
  if (map.neural_field) {
    layers["neural_field"] = {{"encoding", map.neural_field->encoding}, {"bytes", map.neural_field->model.size()},
                              {"trained", trained(map.neural_field->provenance)}};
  }
  if (map.lidar_keyframes) {
    std::size_t points = 0;
    for (const msgs::LidarKeyframe& keyframe : map.lidar_keyframes->keyframes) points += keyframe.points.size();
    layers["lidar_keyframes"] = {{"keyframes", map.lidar_keyframes->keyframes.size()}, {"points", points},
                                 {"sources", map.lidar_keyframes->sources}};
  }
  result["layers"] = layers;
  return result;
}

std::string describe_map_text(const nlohmann::json& description) {
  std::string text;
  const auto& layers = description["layers"];
  if (layers.contains("points")) {
    const auto& p = layers["points"];
    text += fmt::format("  points: {} ({} m voxels)\n", p["count"].get<std::size_t>(), p["voxel_size"].get<double>());
    for (const char* key : {"label_counts", "class_counts"}) {
      if (!p.contains(key)) continue;
      text += fmt::format("    {}: {}\n", std::string_view(key) == "label_counts" ? "geometric labels" : "segmentation classes", counts_text(p[key]));
    }
  }
  if (layers.contains("occupancy")) {
    const auto& o = layers["occupancy"];
    text += fmt::format("  occupancy: {} x {} x {} cells of {} m ({} occupied, {} free, {} unknown)\n", o["size"][0].get<uint32_t>(),
                        o["size"][1].get<uint32_t>(), o["size"][2].get<uint32_t>(), o["resolution"].get<double>(),
                        o["occupied_cells"].get<std::size_t>(), o["free_cells"].get<std::size_t>(), o["unknown_cells"].get<std::size_t>());
    if (o.contains("label_counts")) text += fmt::format("    labels: {}\n", counts_text(o["label_counts"]));
  }
  if (layers.contains("tsdf")) text += fmt::format("  tsdf: {} blocks\n", layers["tsdf"]["blocks"].get<std::size_t>());
  if (layers.contains("mesh")) {
    text += fmt::format("  mesh: {} triangles\n", layers["mesh"]["triangles"].get<std::size_t>());
    if (layers["mesh"].contains("label_counts")) text += fmt::format("    vertex labels: {}\n", counts_text(layers["mesh"]["label_counts"]));
  }
  if (layers.contains("visual_landmarks")) {
    const auto& v = layers["visual_landmarks"];
    text += fmt::format("  visual landmarks: {} seen by {} keyframes of camera {} ({}{}){}\n", v["landmarks"].get<std::size_t>(),
                        v["keyframes"].get<std::size_t>(), v["camera"].get<std::string>(), v["descriptor_type"].get<std::string>(),
                        v["scale_free"].get<bool>() ? ", monocular scale" : "",
                        v["sources"].empty() ? "" : fmt::format(" from {}", fmt::join(v["sources"].get<std::vector<std::string>>(), ", ")));
  }
  const auto trained_text = [](const nlohmann::json& trained) {
    std::string line = fmt::format("trained on {} views, {} steps", trained["views"].get<uint32_t>(), trained["iterations"].get<uint64_t>());
    if (trained["evaluated_views"].get<uint32_t>() > 0) {
      line += fmt::format(", {:.2f} dB PSNR on {} held-back views", trained["psnr_db"].get<double>(), trained["evaluated_views"].get<uint32_t>());
    }
    return line;
  };
  if (layers.contains("gaussian_splats")) {
    const auto& g = layers["gaussian_splats"];
    text += fmt::format("  gaussian splats: {} (SH degree {}), {}\n", g["gaussians"].get<std::size_t>(), g["sh_degree"].get<uint32_t>(), trained_text(g["trained"]));
  }
  if (layers.contains("neural_field")) {
    const auto& n = layers["neural_field"];
    text += fmt::format("  neural field: {} ({:.1f} MB), {}\n", n["encoding"].get<std::string>(), static_cast<double>(n["bytes"].get<std::size_t>()) / 1e6,
                        trained_text(n["trained"]));
  }
  if (layers.contains("lidar_keyframes")) {
    const auto& k = layers["lidar_keyframes"];
    text += fmt::format("  lidar keyframes: {} ({} points){}\n", k["keyframes"].get<std::size_t>(), k["points"].get<std::size_t>(),
                        k["sources"].empty() ? "" : fmt::format(" from {}", fmt::join(k["sources"].get<std::vector<std::string>>(), ", ")));
  }
  return text;
}

void add_map_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* map_app = app.add_subcommand("map", "FusionMap files: build, inspect, export, compare, redact, version, localize a scan");
  map_app->require_subcommand(1);

  auto build = std::make_shared<MapBuildOptions>();
  CLI::App* build_app = map_app->add_subcommand("build", "Build a map from a log's point clouds and a trajectory (known poses)");
  build_app->add_option("--log", build->log, "Sensor log (MCAP)")->required();
  build_app->add_option("--trajectory", build->trajectory, "T_world_body poses (TUM by default)")->required();
  build_app->add_option("--trajectory-format", build->trajectory_format, "tum, kitti or euroc")->capture_default_str();
  build_app->add_option("--calibration,--calib", build->calibration, "Calibration YAML with the sensor's extrinsics (default: identity)");
  build_app->add_option("--topic", build->topic, "Point-cloud topic")->capture_default_str();
  build_app->add_option("--sensor", build->sensor, "Calibration entry of the sensor (default: the topic's last component)");
  build_app->add_option("--occupancy", build->occupancy, "2d, 3d or none")->capture_default_str();
  build_app->add_option("--resolution", build->resolution, "Occupancy cell size (m); spec: 0.05 indoor, 0.2 outdoor")->capture_default_str();
  build_app->add_option("--height-band", build->height_band, "2D grid: returns between min,max m relative to the sensor")->delimiter(',');
  build_app->add_option("--points-voxel", build->points_voxel, "Point layer voxel size (m, 0: no point layer)")->capture_default_str();
  build_app->add_flag("--keep-moving-points", build->keep_moving_points,
                      "Keep the points of objects that moved away (by default, points later or earlier scans saw through leave the point layer)");
  build_app->add_option("--max-range", build->max_range, "Returns farther than this only clear space (m, 0: no limit)");
  build_app->add_option("--tsdf-voxel", build->tsdf_voxel, "TSDF voxel size (m) for a TSDF layer and its mesh (0: none)");
  build_app->add_option("--map-id", build->map_id, "Map id (default: a new UUID)");
  build_app->add_option("--frame", build->frame, "World frame name")->capture_default_str();
  build_app->add_option("--out", build->out, "Output FusionMap file (.fmap)")->required();
  build_app->callback([&output, &run, build] { run = [&output, build] { return run_map_build(output, *build); }; });

  auto options = std::make_shared<MapOptions>();
  CLI::App* info_app = map_app->add_subcommand("info", "Metadata and layers of a FusionMap file");
  info_app->add_option("MAP", options->input, "FusionMap file")->required();
  info_app->callback([&output, &run, options] {
    run = [&output, options] {
      return run_reporting(output, {{"map", options->input}}, [&](nlohmann::json& result, std::string& text) -> Status {
        msgs::FusionMap map;
        HANZO_ASSIGN_OR_RETURN(map, maps::read_fusion_map(options->input));
        result.update(describe_map(map));
        const std::string datum =
            map.datum ? fmt::format(", datum {:.8f} {:.8f} {:.3f} m", map.datum->latitude_deg, map.datum->longitude_deg, map.datum->altitude_m)
                      : "";
        text = fmt::format("{}: map {} version {} (parent {}), frame {}{}, created {}, by {}\n{}", options->input, map.map_id, map.version,
                           map.parent_version, map.frame_id, datum, map.created.to_iso8601(), map.provenance.algorithm,
                           describe_map_text(result));
        return ok_status();
      });
    };
  });

  CLI::App* export_app = map_app->add_subcommand("export", "Export a layer: png (picture), pgm (ROS map_server), pcd/ply/bin (points), ply/obj (mesh)");
  export_app->add_option("MAP", options->input, "FusionMap file")->required();
  export_app->add_option("--out", options->out, "Output file (pgm: map.pgm or map.yaml; both files are written side by side)")->required();
  export_app->add_option("--format", options->format, "png, pgm, pcd, ply, bin or obj (default: from --out's extension)");
  export_app->add_option("--layer", options->layer,
                         "occupancy, points, mesh, labels or classes (png default: occupancy, then points; ply: points, then mesh; labels: ply "
                         "of the points coloured by label, or pgm: one map per label of the grid; classes: ply of the points coloured by "
                         "segmentation class)");
  export_app->add_option("--pixel-size", options->pixel_size, "png of points: meters per pixel (default: 1600 px wide)");
  export_app->callback([&output, &run, options] {
    run = [&output, options] {
      return run_reporting(output, {{"map", options->input}, {"out", options->out}}, [&](nlohmann::json& result, std::string& text) {
        Status status = export_map(*options, result);
        if (status) text = fmt::format("wrote {}\n", result["files"].dump());
        return status;
      });
    };
  });

  CLI::App* import_app = map_app->add_subcommand("import", "Make a FusionMap from a PCD/PLY/.bin cloud or a ROS map YAML");
  import_app->add_option("IN", options->input, "Point cloud or map_server YAML")->required();
  import_app->add_option("--out", options->out, "Output FusionMap file")->required();
  import_app->add_option("--voxel", options->voxel, "Downsample the cloud first (m)");
  import_app->add_option("--map-id", options->map_id, "Map id (default: a new UUID)");
  import_app->callback([&output, &run, options] {
    run = [&output, options] {
      return run_reporting(output, {{"in", options->input}, {"out", options->out}}, [&](nlohmann::json& result, std::string& text) -> Status {
        msgs::FusionMap map;
        HANZO_ASSIGN_OR_RETURN(map, import_map(*options));
        HANZO_RETURN_IF_ERROR(maps::write_fusion_map(options->out, map));
        result.update(describe_map(map));
        text = fmt::format("{} -> {} (map {})\n{}", options->input, options->out, map.map_id, describe_map_text(result));
        return ok_status();
      });
    };
  });

  CLI::App* diff_app = map_app->add_subcommand("diff", "What changed between two maps (occupancy cells, point voxels)");
  diff_app->add_option("BEFORE", options->input, "FusionMap file")->required();
  diff_app->add_option("AFTER", options->second, "FusionMap file")->required();
  diff_app->add_option("--png", options->out, "Picture of the occupancy changes (red appeared, green vanished)");
  diff_app->add_option("--voxel", options->voxel, "Voxel size for comparing points (m)");
  diff_app->callback([&output, &run, options] {
    run = [&output, options] {
      return run_reporting(output, {{"before", options->input}, {"after", options->second}}, [&](nlohmann::json& result, std::string& text) -> Status {
        msgs::FusionMap before;
        msgs::FusionMap after;
        HANZO_ASSIGN_OR_RETURN(before, maps::read_fusion_map(options->input));
        HANZO_ASSIGN_OR_RETURN(after, maps::read_fusion_map(options->second));
        maps::MapDiff diff;
        HANZO_ASSIGN_OR_RETURN(diff, maps::diff_maps(before, after, maps::MapDiffConfig{.point_voxel_size = options->voxel}));
        result.update(diff_json(diff));
        text = diff_text(result);
        if (!options->out.empty()) {
          if (!diff.occupancy) return Error{"--png: the maps have no occupancy layers to picture"};
          HANZO_RETURN_IF_ERROR(maps::write_diff_png(options->out, *after.occupancy, *diff.occupancy));
          result["png"] = options->out;
          text += fmt::format("wrote {}\n", options->out);
        }
        return ok_status();
      });
    };
  });

  CLI::App* redact_app = map_app->add_subcommand("redact", "Remove labels and coarsen geometry before sharing a map");
  redact_app->add_option("IN", options->input, "FusionMap file")->required();
  redact_app->add_option("--out", options->out, "Redacted FusionMap file")->required();
  redact_app->add_flag("--drop-labels", options->drop_labels, "Remove semantic labels from every layer");
  redact_app->add_option("--resolution", options->resolution, "Coarsest geometry kept (m)")->capture_default_str();
  redact_app->add_flag("--drop-sensor-details", options->drop_sensor_details, "Also remove the sensor configuration and input paths");
  redact_app->callback([&output, &run, options] {
    run = [&output, options] {
      return run_reporting(output, {{"in", options->input}, {"out", options->out}}, [&](nlohmann::json& result, std::string& text) -> Status {
        msgs::FusionMap map;
        HANZO_ASSIGN_OR_RETURN(map, maps::read_fusion_map(options->input));
        maps::RedactionReport report;
        msgs::FusionMap redacted;
        HANZO_ASSIGN_OR_RETURN(redacted, maps::redact_map(map, {options->drop_labels, options->resolution, options->drop_sensor_details}, &report));
        HANZO_RETURN_IF_ERROR(maps::write_fusion_map(options->out, redacted));
        result["actions"] = report.actions;
        result["layers"] = describe_map(redacted)["layers"];
        for (const std::string& action : report.actions) text += action + "\n";
        text += fmt::format("wrote {}\n", options->out);
        return ok_status();
      });
    };
  });

  CLI::App* save_app = map_app->add_subcommand("save", "Store a map file as the next version of its map in a map store");
  save_app->add_option("MAP", options->input, "FusionMap file")->required();
  add_store_options(save_app, *options);
  save_app->callback([&output, &run, options] {
    run = [&output, options] {
      return run_reporting(output, {{"map", options->input}, {"store", options->store}}, [&](nlohmann::json& result, std::string& text) -> Status {
        msgs::FusionMap map;
        HANZO_ASSIGN_OR_RETURN(map, maps::read_fusion_map(options->input));
        auto store = open_store(*options);
        if (!store) return store.error();
        maps::MapVersionInfo info;
        HANZO_ASSIGN_OR_RETURN(info, store->save(map));
        result.update(version_json(info));
        text = fmt::format("stored map {} version {} (parent {}) at {}\n", info.map_id, info.version, info.parent_version, info.location);
        return ok_status();
      });
    };
  });

  CLI::App* versions_app = map_app->add_subcommand("versions", "List the maps of a store, or the versions of one map");
  add_store_options(versions_app, *options);
  versions_app->add_option("MAP_ID", options->map_id, "List this map's versions (default: every map)");
  versions_app->callback([&output, &run, options] {
    run = [&output, options] {
      return run_reporting(output, {{"store", options->store}}, [&](nlohmann::json& result, std::string& text) -> Status {
        auto store = open_store(*options);
        if (!store) return store.error();
        std::vector<std::string> ids{options->map_id};
        if (options->map_id.empty()) HANZO_ASSIGN_OR_RETURN(ids, store->map_ids());
        nlohmann::json maps_json = nlohmann::json::array();
        for (const std::string& id : ids) {
          std::vector<maps::MapVersionInfo> versions;
          HANZO_ASSIGN_OR_RETURN(versions, store->versions(id));
          nlohmann::json list = nlohmann::json::array();
          text += fmt::format("{}: {} versions\n", id, versions.size());
          for (const maps::MapVersionInfo& info : versions) {
            list.push_back(version_json(info));
            text += fmt::format("  v{} (parent {}) created {} s, {} bytes\n", info.version, info.parent_version,
                                io::format_seconds(info.created), info.file_bytes);
          }
          maps_json.push_back({{"map_id", id}, {"versions", list}});
        }
        result["maps"] = maps_json;
        return ok_status();
      });
    };
  });

  CLI::App* checkout_app = map_app->add_subcommand("checkout", "Copy a version of a stored map to a file (latest, --version or --at)");
  checkout_app->add_option("MAP_ID", options->map_id, "Map id")->required();
  add_store_options(checkout_app, *options);
  checkout_app->add_option("--version", options->version, "Version number");
  checkout_app->add_option("--at", options->at, "The version current at this time (seconds since the epoch)");
  checkout_app->add_option("--out", options->out, "Output FusionMap file")->required();
  checkout_app->callback([&output, &run, options] {
    run = [&output, options] {
      return run_reporting(output, {{"store", options->store}, {"map_id", options->map_id}}, [&](nlohmann::json& result, std::string& text) -> Status {
        auto store = open_store(*options);
        if (!store) return store.error();
        msgs::FusionMap map;
        if (!options->at.empty()) {
          Timestamp at;
          HANZO_ASSIGN_OR_RETURN(at, with_context(io::parse_seconds(options->at), "--at"));
          HANZO_ASSIGN_OR_RETURN(map, store->load_at(options->map_id, at));
        } else {
          HANZO_ASSIGN_OR_RETURN(map, store->load(options->map_id, options->version > 0 ? std::optional<uint64_t>(options->version) : std::nullopt));
        }
        HANZO_RETURN_IF_ERROR(maps::write_fusion_map(options->out, map));
        result.update(describe_map(map));
        result["out"] = options->out;
        text = fmt::format("map {} version {} -> {}\n{}", map.map_id, map.version, options->out, describe_map_text(result));
        return ok_status();
      });
    };
  });
  add_map_localize_command(*map_app, output, run);
  add_map_merge_command(*map_app, output, run);
}

}  // namespace hanzo::fusion::app
