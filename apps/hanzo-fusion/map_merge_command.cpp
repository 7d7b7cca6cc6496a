// hanzo-fusion map merge A.fmap B.fmap [C.fmap ...] --out M.fmap: the maps of sessions that saw
// the same places joined in A's frame without an initial guess. Maps with LiDAR keyframes
// (Sessions write them) are joined by inter-session loops in one optimized keyframe graph
// (pipeline/session_merge.hpp); other maps by localizing views of each in the merge so far
// (pipeline/map_merge.hpp). Prints where each map went and the checks' numbers (--json: one
// object); exits 1 with the reason when a map shares no place with the others for certain
// (nothing is written then).

#include <algorithm>
#include <memory>
#include <optional>
#include <numbers>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/pipeline/map_merge.hpp"
#include "hanzo/fusion/pipeline/session_merge.hpp"

namespace hanzo::fusion::app {
namespace {

struct MergeOptions {
  std::vector<std::string> maps;
  std::string out;
  std::string map_id = "merged";
  bool indoor = false;
};

double yaw_degrees(const SE3& pose) {
  const Eigen::Matrix3d R = pose.rotation().matrix();
  return std::atan2(R(1, 0), R(0, 0)) * 180.0 / std::numbers::pi;
}

void indoor_registration(lidar::LidarOdometryConfig& odometry) {
  odometry.map.voxel_size = 0.5;
  odometry.source_voxel_size = 0.25;
}

/// Every map has LiDAR or visual keyframes: one keyframe graph.
int run_session_merge(const Output& output, const MergeOptions& options, std::vector<msgs::FusionMap> inputs, nlohmann::json& result) {
  pipeline::SessionMergeConfig config;
  if (options.indoor) indoor_registration(config.odometry);
  Result<pipeline::SessionMergeResult> done = pipeline::merge_sessions(inputs, config);
  if (!done) return report_failure(output, result, done.error().message);
  msgs::FusionMap& merged = done->merged;
  merged.map_id = options.map_id;
  if (Status written = maps::write_fusion_map(options.out, merged); !written) return report_failure(output, result, written.error().message);
  nlohmann::json joined = nlohmann::json::array();
  std::string text;
  for (const pipeline::SessionJoin& join : done->joins) {
    const Eigen::Vector3d t = join.T_joined_map.translation();
    joined.push_back({{"map", options.maps[join.map]}, {"joined_to", options.maps[join.joined_to]}, {"translation", {t.x(), t.y(), t.z()}},
                      {"yaw_deg", yaw_degrees(join.T_joined_map)}, {"scale", join.scale}, {"loops", join.loops}});
    text += fmt::format("{}: at {:.3f} {:.3f} {:.3f}, yaw {:.2f} deg{} in {} ({} agreeing loops)\n", options.maps[join.map], t.x(), t.y(), t.z(),
                        yaw_degrees(join.T_joined_map), join.scale == 1.0 ? "" : fmt::format(", scale {:.4f}", join.scale), options.maps[join.joined_to],
                        join.loops);
  }
  result["method"] = "keyframe_graph";
  result["joined"] = joined;
  result["keyframes"] = done->keyframes;
  result["queries"] = done->queries;
  result["candidates"] = done->candidates;
  result["verified"] = done->verified;
  result["visual_queries"] = done->visual_queries;
  result["visual_verified"] = done->visual_verified;
  result["inter_session_loops"] = done->inter_session_loops;
  result["chi2"] = {done->initial_chi2, done->final_chi2};
  result["dropped_layers"] = done->dropped_layers;
  result["points"] = merged.points ? merged.points->points.size() : 0;
  result["landmarks"] = merged.visual_landmarks ? merged.visual_landmarks->positions.size() : 0;
  text += fmt::format("{} keyframes joined by {} inter-session loops ({} Scan Context candidates, {} verified; {} of {} visual keyframes aligned); "
                      "{} points, {} landmarks in {}",
                      done->keyframes, done->inter_session_loops, done->candidates, done->verified, done->visual_verified, done->visual_queries,
                      result["points"].get<std::size_t>(), result["landmarks"].get<std::size_t>(), options.out);
  return report_success(output, result, text);
}

int run_merge(const Output& output, const MergeOptions& options) {
  nlohmann::json result = {{"maps", options.maps}, {"out", options.out}};
  const auto fail = [&](const std::string& reason) { return report_failure(output, result, reason); };
  if (options.maps.size() < 2) return fail("give two or more maps: the first is the frame the others join");
  std::vector<msgs::FusionMap> inputs;
  for (const std::string& path : options.maps) {
    Result<msgs::FusionMap> map = maps::read_fusion_map(path);
    if (!map) return fail(map.error().message);
    inputs.push_back(std::move(map).value());
  }
  // Maps with the same id (every `run` writes "run") are named by their files.
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    const auto same = [&](const msgs::FusionMap& map) { return map.map_id == inputs[i].map_id; };
    if (std::count_if(inputs.begin(), inputs.end(), same) > 1) {
      for (std::size_t j = 0; j < inputs.size(); ++j) {
        if (j != i && same(inputs[j])) inputs[j].map_id = options.maps[j];
      }
      inputs[i].map_id = options.maps[i];
    }
  }
  // The keyframe graph rebuilds a map's points from its LiDAR keyframes; a map with points and
  // visual keyframes alone joins by its points (views).
  const auto has_keyframes = [](const msgs::FusionMap& map) {
    const bool points = map.points && !map.points->points.empty();
    return (map.lidar_keyframes && !map.lidar_keyframes->keyframes.empty()) || (!points && map.visual_landmarks && !map.visual_landmarks->keyframes.empty());
  };
  if (std::all_of(inputs.begin(), inputs.end(), has_keyframes)) {
    return run_session_merge(output, options, std::move(inputs), result);
  }
  std::optional<msgs::FusionMap> merged = std::move(inputs.front());
  pipeline::MapMergeConfig config;
  if (options.indoor) indoor_registration(config.odometry);
  nlohmann::json joined = nlohmann::json::array();
  std::string text;
  for (std::size_t i = 1; i < options.maps.size(); ++i) {
    Result<pipeline::MapMergeResult> done = pipeline::merge_maps(*merged, inputs[i], config);
    if (!done) return fail(fmt::format("{}: {}", options.maps[i], done.error().message));
    const Eigen::Vector3d t = done->T_a_b.translation();
    const double yaw_deg = yaw_degrees(done->T_a_b);
    joined.push_back({{"map", options.maps[i]}, {"translation", {t.x(), t.y(), t.z()}}, {"yaw_deg", yaw_deg}, {"views", done->views},
                      {"localized", done->localized}, {"agreeing", done->agreeing}, {"points_added", done->points_from_b},
                      {"dropped_layers", done->dropped_layers}});
    text += fmt::format("{}: at {:.3f} {:.3f} {:.3f} m, yaw {:.2f} deg in {} ({} of {} views localized, {} agree); {} points added{}\n",
                        options.maps[i], t.x(), t.y(), t.z(), yaw_deg, options.maps.front(), done->localized, done->views, done->agreeing,
                        done->points_from_b, done->dropped_layers.empty() ? "" : fmt::format(" (its {} not moved)", fmt::join(done->dropped_layers, ", ")));
    merged = std::move(done->merged);
  }
  merged->map_id = options.map_id;
  merged->parent_version = 0;
  merged->provenance.algorithm = "pipeline/map_merge";
  if (Status written = maps::write_fusion_map(options.out, *merged); !written) return fail(written.error().message);
  result["method"] = "views";
  result["joined"] = joined;
  result["points"] = merged->points->points.size();
  text += fmt::format("{} points in {}", merged->points->points.size(), options.out);
  return report_success(output, result, text);
}

}  // namespace

void add_map_merge_command(CLI::App& map_app, const Output& output, Command& run) {
  auto options = std::make_shared<MergeOptions>();
  CLI::App* command = map_app.add_subcommand("merge", "Join maps of the same place without an initial guess (the first map's frame)");
  command->add_option("MAPS", options->maps, "FusionMap files (z up): with LiDAR keyframes, or else with point layers; the first is the frame the others join")->required()->check(CLI::ExistingFile);
  command->add_option("--out", options->out, "The merged FusionMap file")->required();
  command->add_option("--map-id", options->map_id, "The merged map's id")->capture_default_str();
  command->add_flag("--indoor", options->indoor, "Indoor registration settings (0.25 m points, 0.5 m map voxels)");
  command->callback([&output, &run, options] { run = [&output, options] { return run_merge(output, *options); }; });
}

}  // namespace hanzo::fusion::app
